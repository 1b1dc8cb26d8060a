//! What is refused before an upload, each problem named with where its item came from.

use num_traits::FromPrimitive;
use vtol_link::dialect::{MavCmd, MavFrame};

use super::{Kind, Located, command_name};

/// MAV_CMD_NAV_VTOL_LAND.
pub const NAV_VTOL_LAND: u16 = vtol_link::dialect::MavCmd::MAV_CMD_NAV_VTOL_LAND as u16;
/// ArduPlane's shortest last leg into a NAV_VTOL_LAND, m (its refusal:
/// `VTOL land too short, min 30m`).
pub const VTOL_LAND_MIN_LEG_M: f64 = 30.0;
/// Metres per degree of latitude (ArduPilot's LOCATION_SCALING_FACTOR × 1e7).
const M_PER_DEG: f64 = 111_318.844_502_145_03;

/// Ground distance between two global positions in degrees (ArduPilot's flat-earth scaling).
#[must_use]
pub fn distance_m(a: (f64, f64), b: (f64, f64)) -> f64 {
    let mid = ((a.0 + b.0) / 2.0).to_radians();
    let dn = (b.0 - a.0) * M_PER_DEG;
    let de = (b.1 - a.1) * M_PER_DEG * mid.cos();
    dn.hypot(de)
}

/// Every problem of `items` as a list of `kind`, each one line naming its item's origin.
#[must_use]
pub fn problems(items: &[Located], kind: Kind) -> Vec<String> {
    let mut out = Vec::new();
    let mut last_position: Option<(f64, f64)> = None;
    for (seq, l) in items.iter().enumerate() {
        let i = &l.item;
        let at = |what: String| format!("{} (item {seq}): {what}", l.origin);
        if MavCmd::from_u16(i.command).is_none() {
            out.push(at(format!("unknown command {}", i.command)));
        }
        if MavFrame::from_u8(i.frame).is_none() {
            out.push(at(format!("unknown frame {}", i.frame)));
        }
        if i.x.is_nan() || i.y.is_nan() || i.z.is_nan() {
            out.push(at(format!(
                "{} position or altitude is NaN",
                command_name(i.command)
            )));
        }
        if i.params.iter().any(|p| p.is_infinite())
            || i.x.is_infinite()
            || i.y.is_infinite()
            || i.z.is_infinite()
        {
            out.push(at("a value is infinite".into()));
        }
        if super::is_global(i.frame) {
            if i.x.abs() > 90.0 {
                out.push(at(format!("latitude {} is out of -90..90", i.x)));
            }
            if i.y.abs() > 180.0 {
                out.push(at(format!("longitude {} is out of -180..180", i.y)));
            }
        }
        let fine = |v: f64, limit: f64| v.is_finite() && v.abs() <= limit;
        let position =
            (i.has_position() && fine(i.x, 90.0) && fine(i.y, 180.0)).then_some((i.x, i.y));
        if kind == Kind::Mission
            && i.command == NAV_VTOL_LAND
            && let (Some(from), Some(to)) = (last_position, position)
        {
            let leg = distance_m(from, to);
            if leg < VTOL_LAND_MIN_LEG_M {
                out.push(at(format!(
                    "VTOL land too short, min 30m (the approach from the item before is {leg:.1} m)"
                )));
            }
        }
        if position.is_some() {
            last_position = position;
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::super::{Item, Origin};
    use super::*;

    fn at(line: usize, command: u16, x: f64, y: f64, z: f32) -> Located {
        Located {
            item: Item {
                frame: if line == 1 { 0 } else { 3 },
                command,
                current: false,
                autocontinue: true,
                params: [0.0; 4],
                x,
                y,
                z,
            },
            origin: Origin::Line(line),
        }
    }

    const LAT: f64 = -35.363_261;
    const LON: f64 = 149.165_230;
    const M: f64 = 1.0 / M_PER_DEG;

    #[test]
    fn a_good_mission_has_no_problem() {
        let items = [
            at(1, 16, LAT, LON, 584.0),
            at(2, 84, 0.0, 0.0, 20.0),
            at(3, 16, LAT + 200.0 * M, LON, 30.0),
            at(4, 85, LAT + 150.0 * M, LON, 0.0),
        ];
        assert_eq!(problems(&items, Kind::Mission), Vec::<String>::new());
    }

    #[test]
    fn each_problem_names_its_line() {
        let items = [
            at(1, 16, LAT, LON, 584.0),
            at(2, 9999, LAT, LON, 20.0),
            at(3, 16, f64::NAN, LON, 30.0),
            at(4, 16, 91.0, LON, 30.0),
            at(5, 16, LAT, -181.0, 30.0),
            at(6, 16, LAT + 100.0 * M, LON, 30.0),
            at(7, 85, LAT + 120.0 * M, LON, 0.0),
        ];
        let p = problems(&items, Kind::Mission);
        assert_eq!(p.len(), 5, "{p:#?}");
        assert!(
            p[0].starts_with("line 2 (item 1): unknown command 9999"),
            "{}",
            p[0]
        );
        assert!(
            p[1].starts_with("line 3 (item 2): NAV_WAYPOINT position or altitude is NaN"),
            "{}",
            p[1]
        );
        assert!(
            p[2].contains("line 4") && p[2].contains("latitude 91"),
            "{}",
            p[2]
        );
        assert!(
            p[3].contains("line 5") && p[3].contains("longitude -181"),
            "{}",
            p[3]
        );
        assert!(
            p[4].starts_with("line 7 (item 6): VTOL land too short, min 30m")
                && p[4].contains("20.0 m"),
            "{}",
            p[4]
        );
    }

    #[test]
    fn a_vtol_land_here_or_after_no_position_is_not_measured() {
        let items = [
            at(1, 16, 0.0, 0.0, 0.0),
            at(2, 85, LAT, LON, 0.0),
            at(3, 85, 0.0, 0.0, 0.0),
        ];
        assert!(problems(&items, Kind::Mission).is_empty());
    }

    #[test]
    fn distance_matches_the_flat_earth_scaling() {
        let d = distance_m((LAT, LON), (LAT + 100.0 * M, LON));
        assert!((d - 100.0).abs() < 1e-6, "{d}");
    }
}
