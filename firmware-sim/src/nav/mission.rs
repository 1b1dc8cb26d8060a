//! The stored mission: its items, which of them the twin can fly, where each one goes, and the
//! mission file beside the parameter file.
//!
//! Items are kept exactly as a ground station sent them in MISSION_ITEM_INT (every field but
//! the sequence number, the target and the mission type), so a download returns the bytes of
//! the upload. As on ArduPilot, item 0 is the home slot: it is stored and returned but never
//! flown, and AUTO starts at item 1.
//!
//! The twin flies NAV_VTOL_TAKEOFF, NAV_WAYPOINT, NAV_LOITER_TIME, NAV_VTOL_LAND and
//! NAV_RETURN_TO_LAUNCH, and NAV_TAKEOFF/NAV_LAND as their VTOL forms (it cannot fly as a
//! plane), in the global frames (altitude above mean sea level or above home). Anything else is
//! refused at upload ([`check_item`]) with the `MAV_MISSION_RESULT` a ground station shows and a
//! sentence saying why; the stored mission is then left as it was.
//!
//! # Mission file
//!
//! The QGroundControl `QGC WPL 110` text format that MAVProxy's `wp load`/`wp save` use: a header
//! line, then one tab-separated line per item: `seq current frame command p1 p2 p3 p4 x y z
//! autocontinue`. Latitudes and longitudes are written with exactly seven decimals from their
//! 1e-7 degree integers and the floats in their shortest exact form, so a mission survives a
//! restart bit for bit. The file is rewritten atomically (temporary file, then rename); a file
//! that cannot be read is an error at start, never silently replaced.

use std::fmt::Write as _;
use std::path::{Path, PathBuf};

use mavlink::dialects::ardupilotmega::{MavCmd, MavMissionResult, MavVtolState};
use nalgebra::{Vector2, Vector3};
use num_traits::FromPrimitive as _;

use crate::nav::globe::{GeoPoint, Origin, valid_lat_lon};

/// Most items a mission may hold (ArduPilot's limit on boards with little storage is of the same
/// order); an upload announcing more is refused with `MAV_MISSION_NO_SPACE`.
pub const MAX_ITEMS: u16 = 1000;

/// The `MAV_FRAME` classes the twin tells apart, by the dialect's [`MavFrame`]. Items keep the
/// frame number as sent (a number the dialect lacks is stored and returned too).
// The `_INT` frames and the BODY_*NED ones are deprecated in common.xml but still sent.
#[allow(deprecated)]
pub mod frame {
    use mavlink::dialects::ardupilotmega::MavFrame as F;
    use num_traits::FromPrimitive as _;

    /// Latitude/longitude frames.
    #[must_use]
    pub fn is_global(f: u8) -> bool {
        matches!(
            F::from_u8(f),
            Some(
                F::MAV_FRAME_GLOBAL
                    | F::MAV_FRAME_GLOBAL_RELATIVE_ALT
                    | F::MAV_FRAME_GLOBAL_INT
                    | F::MAV_FRAME_GLOBAL_RELATIVE_ALT_INT
            )
        )
    }

    /// Frames whose altitude is relative to home.
    #[must_use]
    pub fn is_relative(f: u8) -> bool {
        matches!(
            F::from_u8(f),
            Some(F::MAV_FRAME_GLOBAL_RELATIVE_ALT | F::MAV_FRAME_GLOBAL_RELATIVE_ALT_INT)
        )
    }

    /// Local metric frames (x, y travel as metres × 1e4 in the integer messages). Frame 22, past
    /// the dialect's last, is counted local as it always was.
    #[must_use]
    pub fn is_local(f: u8) -> bool {
        matches!(
            F::from_u8(f),
            Some(
                F::MAV_FRAME_LOCAL_NED
                    | F::MAV_FRAME_LOCAL_ENU
                    | F::MAV_FRAME_LOCAL_OFFSET_NED
                    | F::MAV_FRAME_BODY_NED
                    | F::MAV_FRAME_BODY_OFFSET_NED
                    | F::MAV_FRAME_LOCAL_FRD
                    | F::MAV_FRAME_LOCAL_FLU
            )
        ) || f == 22
    }
}

/// One mission item as MISSION_ITEM_INT carries it.
#[derive(Debug, Clone, Copy, Default)]
pub struct MissionItem {
    /// param1..param4.
    pub params: [f32; 4],
    /// Latitude (1e-7 degree) in global frames, metres × 1e4 in local ones.
    pub x: i32,
    /// Longitude (1e-7 degree) in global frames, metres × 1e4 in local ones.
    pub y: i32,
    /// Altitude, m (meaning set by `frame`).
    pub z: f32,
    /// `MAV_CMD`.
    pub command: u16,
    /// `MAV_FRAME`.
    pub frame: u8,
    /// The `current` flag as sent.
    pub current: u8,
    /// The `autocontinue` flag as sent.
    pub autocontinue: u8,
}

impl PartialEq for MissionItem {
    /// Bit equality: a NaN parameter equals the same NaN (what a round trip must preserve).
    fn eq(&self, o: &Self) -> bool {
        self.params.map(f32::to_bits) == o.params.map(f32::to_bits)
            && (self.x, self.y, self.z.to_bits()) == (o.x, o.y, o.z.to_bits())
            && (self.command, self.frame, self.current, self.autocontinue)
                == (o.command, o.frame, o.current, o.autocontinue)
    }
}

/// Decimal places of x and y in MISSION_ITEM (floats) and in the mission file, by frame.
fn xy_decimals(frame: u8) -> u32 {
    if frame::is_global(frame) {
        7
    } else if frame::is_local(frame) {
        4
    } else {
        0
    }
}

/// x or y as MISSION_ITEM's float (degrees or metres) from the integer form.
#[must_use]
pub fn xy_to_float(frame: u8, v: i32) -> f64 {
    f64::from(v) / 10f64.powi(xy_decimals(frame) as i32)
}

/// x or y in the integer form from MISSION_ITEM's float (rounded; NaN → 0, clamped).
#[must_use]
pub fn xy_from_float(frame: u8, v: f64) -> i32 {
    let scaled = (v * 10f64.powi(xy_decimals(frame) as i32)).round();
    if scaled.is_nan() {
        0
    } else {
        scaled.clamp(f64::from(i32::MIN), f64::from(i32::MAX)) as i32
    }
}

/// An integer with `decimals` implied decimal places, written exactly (`-353632610`, 7 →
/// `-35.3632610`).
fn fixed_point(v: i32, decimals: u32) -> String {
    if decimals == 0 {
        return v.to_string();
    }
    let scale = 10i64.pow(decimals);
    let a = i64::from(v).abs();
    let sign = if v < 0 { "-" } else { "" };
    format!(
        "{sign}{}.{:0width$}",
        a / scale,
        a % scale,
        width = decimals as usize
    )
}

/// Parses what [`fixed_point`] writes, and any other decimal number (rounded).
fn parse_fixed_point(s: &str, decimals: u32) -> Option<i32> {
    let v: f64 = s.parse().ok()?;
    if !v.is_finite() {
        return None;
    }
    let scaled = (v * 10f64.powi(decimals as i32)).round();
    (f64::from(i32::MIN)..=f64::from(i32::MAX))
        .contains(&scaled)
        .then_some(scaled as i32)
}

/// Why an item (or a whole upload) is refused: the code MISSION_ACK carries and a sentence for
/// STATUSTEXT.
#[derive(Debug, Clone, PartialEq)]
pub struct Refusal {
    /// `MAV_MISSION_RESULT`.
    pub result: MavMissionResult,
    /// What is wrong, for the operator.
    pub reason: String,
}

impl Refusal {
    fn new(result: MavMissionResult, reason: String) -> Self {
        Self { result, reason }
    }
}

/// The flight envelope items and guided targets must stay in.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Limits {
    /// The motion-capture frame's place on the globe.
    pub origin: Origin,
    /// Home, local NED, m (altitudes "relative" are above it).
    pub home_ned_m: Vector3<f64>,
    /// Largest horizontal distance from home, m (`NAV_RADIUS_MAX`).
    pub radius_max_m: f64,
    /// Highest altitude above home, m (`NAV_ALT_MAX`).
    pub alt_max_m: f64,
}

impl Limits {
    /// Local NED of a global point in an item's altitude frame (z: altitude → down).
    #[must_use]
    pub fn local_ned(&self, frame_no: u8, lat_e7: i32, lon_e7: i32, alt_m: f64) -> Vector3<f64> {
        let alt_amsl_m = if frame::is_relative(frame_no) {
            self.origin.ground_amsl_m() - self.home_ned_m.z + alt_m
        } else {
            alt_m
        };
        self.origin.to_local_ned(&GeoPoint {
            lat_e7,
            lon_e7,
            alt_amsl_m,
        })
    }

    /// Checks a target (local NED) against the envelope; the reason names the limit.
    ///
    /// # Errors
    /// Which bound the target breaks, with the parameter that sets it: the horizontal distance
    /// ([`MavMissionResult::MAV_MISSION_INVALID_PARAM5_X`]) or the altitude
    /// ([`MavMissionResult::MAV_MISSION_INVALID_PARAM7`]).
    pub fn check(&self, what: &str, ned_m: &Vector3<f64>) -> Result<(), Refusal> {
        let dist = crate::nav::globe::horizontal_distance_m(ned_m, &self.home_ned_m);
        // NaN (a target that is not a number) fails too.
        if dist.is_nan() || dist > self.radius_max_m {
            return Err(Refusal::new(
                MavMissionResult::MAV_MISSION_INVALID_PARAM5_X,
                format!(
                    "{what} is {dist:.1} m from home, beyond NAV_RADIUS_MAX {} m",
                    self.radius_max_m
                ),
            ));
        }
        let alt = self.home_ned_m.z - ned_m.z;
        if !(0.0..=self.alt_max_m).contains(&alt) {
            return Err(Refusal::new(
                MavMissionResult::MAV_MISSION_INVALID_PARAM7,
                format!(
                    "{what} altitude {alt:.1} m is outside 0..NAV_ALT_MAX {} m above home",
                    self.alt_max_m
                ),
            ));
        }
        Ok(())
    }
}

/// Where an item sends the vehicle.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ItemTarget {
    /// Horizontal target (local NED north, east), m; `None` = where the vehicle is when the item
    /// starts (latitude and longitude both 0, ArduPilot's convention).
    pub xy_ned_m: Option<Vector2<f64>>,
    /// Altitude as local NED z (down), m.
    pub z_ned_m: f64,
}

/// The name a ground station shows for a command, for refusal sentences.
fn command_name(c: u16) -> String {
    MavCmd::from_u16(c).map_or_else(
        || format!("command {c}"),
        |m| format!("{m:?}").trim_start_matches("MAV_CMD_").to_owned(),
    )
}

impl MissionItem {
    /// The item's command as the dialect names it; `None` for a number the dialect lacks.
    #[must_use]
    pub fn cmd(&self) -> Option<MavCmd> {
        MavCmd::from_u16(self.command)
    }

    /// Whether the item moves the vehicle to a position it names.
    #[must_use]
    pub fn has_position(&self) -> bool {
        matches!(
            self.cmd(),
            Some(
                MavCmd::MAV_CMD_NAV_WAYPOINT
                    | MavCmd::MAV_CMD_NAV_LOITER_TIME
                    | MavCmd::MAV_CMD_NAV_LAND
                    | MavCmd::MAV_CMD_NAV_VTOL_LAND
                    | MavCmd::MAV_CMD_NAV_TAKEOFF
                    | MavCmd::MAV_CMD_NAV_VTOL_TAKEOFF
            )
        )
    }

    /// Where the item goes, in the local frame (global frames only; [`check_item`] refuses the
    /// rest).
    #[must_use]
    pub fn target(&self, limits: &Limits) -> ItemTarget {
        let ned = limits.local_ned(self.frame, self.x, self.y, f64::from(self.z));
        ItemTarget {
            xy_ned_m: (self.x != 0 || self.y != 0).then(|| ned.xy()),
            z_ned_m: ned.z,
        }
    }
}

/// Checks that the twin can fly an item (`seq` ≥ 1; the home slot is not checked).
///
/// # Errors
/// A [`Refusal`]: `MAV_MISSION_UNSUPPORTED` for a command the twin cannot fly,
/// `MAV_MISSION_UNSUPPORTED_FRAME`, `MAV_MISSION_INVALID_PARAM*` for a bad value or a point
/// outside the envelope.
pub fn check_item(seq: u16, item: &MissionItem, limits: &Limits) -> Result<(), Refusal> {
    use MavCmd as C;
    use MavMissionResult as R;
    let c = item.command;
    let Some(
        command @ (C::MAV_CMD_NAV_WAYPOINT
        | C::MAV_CMD_NAV_LOITER_TIME
        | C::MAV_CMD_NAV_RETURN_TO_LAUNCH
        | C::MAV_CMD_NAV_LAND
        | C::MAV_CMD_NAV_TAKEOFF
        | C::MAV_CMD_NAV_VTOL_TAKEOFF
        | C::MAV_CMD_NAV_VTOL_LAND
        | C::MAV_CMD_DO_VTOL_TRANSITION),
    ) = item.cmd()
    else {
        return Err(Refusal::new(
            R::MAV_MISSION_UNSUPPORTED,
            format!("Mission item {seq}: {} is not supported", command_name(c)),
        ));
    };
    let to = item.params[0];
    if command == C::MAV_CMD_DO_VTOL_TRANSITION
        && to != f32::from(MavVtolState::MAV_VTOL_STATE_MC as u8)
        && to != f32::from(MavVtolState::MAV_VTOL_STATE_FW as u8)
    {
        return Err(Refusal::new(
            R::MAV_MISSION_INVALID_PARAM1,
            format!("Mission item {seq}: transition to state {to}, not 3 (MC) or 4 (FW)"),
        ));
    }
    if !item.has_position() {
        return Ok(());
    }
    if !frame::is_global(item.frame) {
        return Err(Refusal::new(
            R::MAV_MISSION_UNSUPPORTED_FRAME,
            format!("Mission item {seq}: frame {} is not supported", item.frame),
        ));
    }
    let hold = item.params[0];
    if matches!(
        command,
        C::MAV_CMD_NAV_WAYPOINT | C::MAV_CMD_NAV_LOITER_TIME
    ) && !(0.0..=3600.0).contains(&hold)
    {
        return Err(Refusal::new(
            R::MAV_MISSION_INVALID_PARAM1,
            format!("Mission item {seq}: hold time {hold} s outside 0..3600"),
        ));
    }
    if command == C::MAV_CMD_NAV_WAYPOINT && item.params[1] < 0.0 {
        return Err(Refusal::new(
            R::MAV_MISSION_INVALID_PARAM2,
            format!("Mission item {seq}: negative acceptance radius"),
        ));
    }
    if !valid_lat_lon(item.x, item.y) {
        return Err(Refusal::new(
            R::MAV_MISSION_INVALID_PARAM5_X,
            format!("Mission item {seq}: latitude/longitude out of range"),
        ));
    }
    if !item.z.is_finite() {
        return Err(Refusal::new(
            R::MAV_MISSION_INVALID_PARAM7,
            format!("Mission item {seq}: altitude is not a number"),
        ));
    }
    let t = item.target(limits);
    let ned = Vector3::new(
        t.xy_ned_m.map_or(limits.home_ned_m.x, |v| v.x),
        t.xy_ned_m.map_or(limits.home_ned_m.y, |v| v.y),
        t.z_ned_m,
    );
    let takeoff = matches!(
        command,
        C::MAV_CMD_NAV_TAKEOFF | C::MAV_CMD_NAV_VTOL_TAKEOFF
    );
    let land = matches!(command, C::MAV_CMD_NAV_LAND | C::MAV_CMD_NAV_VTOL_LAND);
    // A landing's altitude is not flown (it descends to the ground); check only its position.
    let checked = if land {
        Vector3::new(ned.x, ned.y, limits.home_ned_m.z)
    } else {
        ned
    };
    limits
        .check(&format!("Mission item {seq}"), &checked)
        .map_err(|mut r| {
            if r.result == R::MAV_MISSION_INVALID_PARAM5_X && t.xy_ned_m.is_none() {
                r.result = R::MAV_MISSION_INVALID_PARAM7;
            }
            r
        })?;
    if takeoff && limits.home_ned_m.z - ned.z <= 0.0 {
        return Err(Refusal::new(
            R::MAV_MISSION_INVALID_PARAM7,
            format!("Mission item {seq}: take-off altitude must be above home"),
        ));
    }
    Ok(())
}

/// A mission file that cannot be used: unreadable, or a line that is not a mission item.
pub type MissionFileError = vtol_link::text_file::TextFileError;

/// The header of the `QGC WPL 110` format.
pub const WPL_HEADER: &str = "QGC WPL 110";

/// The stored mission (item 0 is the home slot).
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Mission {
    items: Vec<MissionItem>,
}

impl Mission {
    /// A mission of these items (item 0 first).
    #[must_use]
    pub fn new(items: Vec<MissionItem>) -> Self {
        Self { items }
    }

    /// Number of items, the home slot included (what MISSION_COUNT says).
    #[must_use]
    pub fn count(&self) -> u16 {
        self.items.len() as u16
    }

    /// Whether no item is stored.
    #[must_use]
    pub fn is_empty(&self) -> bool {
        self.items.is_empty()
    }

    /// Item `seq`.
    #[must_use]
    pub fn get(&self, seq: u16) -> Option<&MissionItem> {
        self.items.get(usize::from(seq))
    }

    /// Every item.
    #[must_use]
    pub fn items(&self) -> &[MissionItem] {
        &self.items
    }

    /// The mission as `QGC WPL 110` text.
    #[must_use]
    pub fn to_wpl_string(&self) -> String {
        let mut out = format!("{WPL_HEADER}\n");
        for (seq, it) in self.items.iter().enumerate() {
            let d = xy_decimals(it.frame);
            let [p1, p2, p3, p4] = it.params;
            // Writing into a String cannot fail.
            let _ = writeln!(
                out,
                "{seq}\t{}\t{}\t{}\t{p1:?}\t{p2:?}\t{p3:?}\t{p4:?}\t{}\t{}\t{:?}\t{}",
                it.current,
                it.frame,
                it.command,
                fixed_point(it.x, d),
                fixed_point(it.y, d),
                it.z,
                it.autocontinue,
            );
        }
        out
    }

    /// Parses `QGC WPL 110` text (what MAVProxy and QGroundControl write too). Items must be
    /// numbered 0, 1, 2… in order.
    ///
    /// # Errors
    /// [`TextFileError::Line`](vtol_link::text_file::TextFileError::Line) naming the first bad line.
    pub fn from_wpl_str(text: &str, path: &Path) -> Result<Self, MissionFileError> {
        let err = |line: usize, reason: String| MissionFileError::line(path, line, reason);
        let mut lines = text.lines().enumerate();
        match lines.next() {
            Some((_, h)) if h.trim().starts_with("QGC WPL") => {}
            _ => return Err(err(1, format!("expected a '{WPL_HEADER}' header"))),
        }
        let mut items = Vec::new();
        for (n, raw) in lines {
            let line_no = n + 1;
            if raw.trim().is_empty() {
                continue;
            }
            let f: Vec<&str> = raw.split_whitespace().collect();
            let [
                seq,
                current,
                frame_s,
                command,
                p1,
                p2,
                p3,
                p4,
                x,
                y,
                z,
                auto,
            ] = f[..]
            else {
                return Err(err(line_no, format!("expected 12 fields, got {}", f.len())));
            };
            let int = |s: &str, what: &str| -> Result<u64, MissionFileError> {
                s.parse::<u64>()
                    .map_err(|_| err(line_no, format!("bad {what} {s:?}")))
            };
            let small = |s: &str, what: &str, max: u64| -> Result<u64, MissionFileError> {
                let v = int(s, what)?;
                if v > max {
                    return Err(err(line_no, format!("{what} {v} out of range")));
                }
                Ok(v)
            };
            if int(seq, "sequence number")? != items.len() as u64 {
                return Err(err(
                    line_no,
                    format!("item {seq} out of order (expected {})", items.len()),
                ));
            }
            if items.len() >= usize::from(MAX_ITEMS) {
                return Err(err(line_no, format!("more than {MAX_ITEMS} items")));
            }
            let float = |s: &str, what: &str| -> Result<f32, MissionFileError> {
                s.parse::<f32>()
                    .map_err(|_| err(line_no, format!("bad {what} {s:?}")))
            };
            let frame_no = small(frame_s, "frame", 255)? as u8;
            let d = xy_decimals(frame_no);
            let coord = |s: &str, what: &str| {
                parse_fixed_point(s, d).ok_or_else(|| err(line_no, format!("bad {what} {s:?}")))
            };
            items.push(MissionItem {
                params: [
                    float(p1, "param1")?,
                    float(p2, "param2")?,
                    float(p3, "param3")?,
                    float(p4, "param4")?,
                ],
                x: coord(x, "x")?,
                y: coord(y, "y")?,
                z: float(z, "z")?,
                command: small(command, "command", u64::from(u16::MAX))? as u16,
                frame: frame_no,
                current: small(current, "current", 255)? as u8,
                autocontinue: small(auto, "autocontinue", 255)? as u8,
            });
        }
        Ok(Self { items })
    }

    /// Loads a mission file.
    ///
    /// # Errors
    /// I/O errors and everything [`Mission::from_wpl_str`] refuses.
    pub fn load(path: &Path) -> Result<Self, MissionFileError> {
        let text = vtol_link::text_file::read_text(path)?;
        Self::from_wpl_str(&text, path)
    }

    /// Writes the mission atomically (a temporary file in the same directory, flushed, renamed).
    ///
    /// # Errors
    /// [`TextFileError::Io`](vtol_link::text_file::TextFileError::Io).
    pub fn save(&self, path: &Path) -> Result<(), MissionFileError> {
        vtol_link::text_file::write_text(path, &self.to_wpl_string())
    }
}

/// Where the mission is kept beside a parameter file: the same name with the `.waypoints`
/// extension (`twin.parm` → `twin.waypoints`).
#[must_use]
pub fn file_beside(param_file: &Path) -> PathBuf {
    let p = param_file.with_extension("waypoints");
    if p == param_file {
        let mut s = param_file.as_os_str().to_owned();
        s.push(".mission.waypoints");
        PathBuf::from(s)
    } else {
        p
    }
}

/// What the mission's and the navigator's tests build missions from.
#[cfg(test)]
#[allow(deprecated)]
pub(crate) mod test_items {
    use super::*;
    use mavlink::dialects::ardupilotmega::MavFrame;

    /// A 100 m radius and 50 m ceiling around home at the origin, near Canberra.
    pub fn limits() -> Limits {
        Limits {
            origin: Origin::from_degrees(-35.363_261, 149.165_230, 584.0),
            home_ned_m: Vector3::zeros(),
            radius_max_m: 100.0,
            alt_max_m: 50.0,
        }
    }

    /// An item `command` at (`x`, `y`, `alt`) relative to home, auto-continuing.
    pub fn item(command: u16, params: [f32; 4], x: i32, y: i32, alt: f32) -> MissionItem {
        MissionItem {
            params,
            x,
            y,
            z: alt,
            command,
            frame: MavFrame::MAV_FRAME_GLOBAL_RELATIVE_ALT_INT as u8,
            current: 0,
            autocontinue: 1,
        }
    }
}

#[cfg(test)]
#[allow(deprecated)]
mod tests {
    use super::test_items::limits;
    use super::*;
    use mavlink::dialects::ardupilotmega::MavFrame;

    fn wp(command: u16, lat_e7: i32, lon_e7: i32, alt: f32) -> MissionItem {
        test_items::item(command, [0.0, 0.0, 0.0, f32::NAN], lat_e7, lon_e7, alt)
    }

    #[test]
    fn supported_items_pass_and_others_are_refused() {
        let l = limits();
        let (lat, lon) = (-353_632_610 + 450, 1_491_652_300);
        for c in [
            MavCmd::MAV_CMD_NAV_WAYPOINT as u16,
            MavCmd::MAV_CMD_NAV_LOITER_TIME as u16,
            MavCmd::MAV_CMD_NAV_VTOL_TAKEOFF as u16,
            MavCmd::MAV_CMD_NAV_VTOL_LAND as u16,
            MavCmd::MAV_CMD_NAV_TAKEOFF as u16,
            MavCmd::MAV_CMD_NAV_LAND as u16,
        ] {
            check_item(1, &wp(c, lat, lon, 3.0), &l).unwrap();
        }
        let rtl = MissionItem {
            command: MavCmd::MAV_CMD_NAV_RETURN_TO_LAUNCH as u16,
            frame: MavFrame::MAV_FRAME_MISSION as u8,
            ..wp(0, 0, 0, 0.0)
        };
        check_item(4, &rtl, &l).unwrap();
        // DO_SET_SERVO and an id the dialect does not know.
        let e = check_item(2, &wp(183, lat, lon, 3.0), &l).unwrap_err();
        assert_eq!(e.result, MavMissionResult::MAV_MISSION_UNSUPPORTED);
        assert_eq!(e.reason, "Mission item 2: DO_SET_SERVO is not supported");
        let e = check_item(2, &wp(65000, lat, lon, 3.0), &l).unwrap_err();
        assert_eq!(e.reason, "Mission item 2: command 65000 is not supported");
        let local = MissionItem {
            frame: MavFrame::MAV_FRAME_LOCAL_NED as u8,
            ..wp(MavCmd::MAV_CMD_NAV_WAYPOINT as u16, 10, 10, 3.0)
        };
        assert_eq!(
            check_item(1, &local, &l).unwrap_err().result,
            MavMissionResult::MAV_MISSION_UNSUPPORTED_FRAME
        );
    }

    #[test]
    fn envelope_and_values() {
        let l = limits();
        // 0.001 degree of latitude is 111 m: beyond the 100 m radius.
        let far = wp(
            MavCmd::MAV_CMD_NAV_WAYPOINT as u16,
            -353_632_610 + 10_000,
            1_491_652_300,
            3.0,
        );
        let e = check_item(1, &far, &l).unwrap_err();
        assert_eq!(e.result, MavMissionResult::MAV_MISSION_INVALID_PARAM5_X);
        assert!(e.reason.contains("NAV_RADIUS_MAX"), "{}", e.reason);
        let high = wp(MavCmd::MAV_CMD_NAV_WAYPOINT as u16, 0, 0, 60.0);
        let e = check_item(1, &high, &l).unwrap_err();
        assert_eq!(e.result, MavMissionResult::MAV_MISSION_INVALID_PARAM7);
        let nan = wp(MavCmd::MAV_CMD_NAV_WAYPOINT as u16, 0, 0, f32::NAN);
        assert!(check_item(1, &nan, &l).is_err());
        let ground_takeoff = wp(MavCmd::MAV_CMD_NAV_VTOL_TAKEOFF as u16, 0, 0, 0.0);
        assert!(check_item(1, &ground_takeoff, &l).is_err());
        let mut neg_hold = wp(MavCmd::MAV_CMD_NAV_LOITER_TIME as u16, 0, 0, 2.0);
        neg_hold.params[0] = -1.0;
        assert_eq!(
            check_item(1, &neg_hold, &l).unwrap_err().result,
            MavMissionResult::MAV_MISSION_INVALID_PARAM1
        );
        // AMSL altitude: 587 m is 3 m above the 584 m ground.
        let amsl = MissionItem {
            frame: MavFrame::MAV_FRAME_GLOBAL_INT as u8,
            ..wp(MavCmd::MAV_CMD_NAV_WAYPOINT as u16, 0, 0, 587.0)
        };
        check_item(1, &amsl, &l).unwrap();
        assert!((amsl.target(&l).z_ned_m + 3.0).abs() < 1e-9);
        assert_eq!(amsl.target(&l).xy_ned_m, None);
    }

    #[test]
    fn wpl_round_trip_is_exact() {
        let mut items = vec![
            MissionItem {
                frame: MavFrame::MAV_FRAME_GLOBAL as u8,
                ..wp(
                    MavCmd::MAV_CMD_NAV_WAYPOINT as u16,
                    -353_632_610,
                    1_491_652_300,
                    584.0,
                )
            },
            wp(MavCmd::MAV_CMD_NAV_VTOL_TAKEOFF as u16, 0, 0, 2.5),
            wp(
                MavCmd::MAV_CMD_NAV_WAYPOINT as u16,
                -353_632_161,
                1_491_651_234,
                3.333_333_3,
            ),
            wp(MavCmd::MAV_CMD_NAV_LOITER_TIME as u16, 5, -7, 0.1),
        ];
        items[2].params = [1.5, 0.25, f32::MIN_POSITIVE, -0.0];
        items[3].current = 1;
        let m = Mission::new(items);
        let text = m.to_wpl_string();
        assert!(text.starts_with("QGC WPL 110\n0\t0\t0\t16\t"), "{text}");
        assert!(text.contains("\t-35.3632161\t149.1651234\t"), "{text}");
        let back = Mission::from_wpl_str(&text, Path::new("m.waypoints")).unwrap();
        assert_eq!(back, m);
        // MAVProxy's spelling (spaces, fewer decimals) reads too.
        let mp = "QGC WPL 110\n0 1 0 16 0 0 0 0 -35.363261 149.165230 584.000000 1\n";
        let m2 = Mission::from_wpl_str(mp, Path::new("x")).unwrap();
        assert_eq!(m2.get(0).unwrap().x, -353_632_610);
    }

    #[test]
    fn bad_files_are_errors() {
        let p = Path::new("bad.waypoints");
        for (text, needle) in [
            ("", "header"),
            ("hello\n", "header"),
            ("QGC WPL 110\n0 0 0 16 0 0 0 0 1 2 3\n", "12 fields"),
            ("QGC WPL 110\n1 0 0 16 0 0 0 0 1 2 3 1\n", "out of order"),
            ("QGC WPL 110\n0 0 0 16 x 0 0 0 1 2 3 1\n", "param1"),
            ("QGC WPL 110\n0 0 0 70000 0 0 0 0 1 2 3 1\n", "command"),
            ("QGC WPL 110\n0 0 0 16 0 0 0 0 1e30 2 3 1\n", "bad x"),
        ] {
            let e = Mission::from_wpl_str(text, p).unwrap_err();
            assert!(e.to_string().contains(needle), "{text:?}: {e}");
            assert!(e.to_string().starts_with("bad.waypoints:"), "{e}");
        }
    }

    #[test]
    fn save_and_load_beside_the_param_file() {
        let dir = tempfile::tempdir().unwrap();
        let parm = dir.path().join("twin.parm");
        let path = file_beside(&parm);
        assert_eq!(path, dir.path().join("twin.waypoints"));
        let m = Mission::new(vec![wp(MavCmd::MAV_CMD_NAV_WAYPOINT as u16, 1, 2, 3.0)]);
        m.save(&path).unwrap();
        assert_eq!(Mission::load(&path).unwrap(), m);
        assert_eq!(std::fs::read_dir(dir.path()).unwrap().count(), 1);
        let odd = dir.path().join("a.waypoints");
        assert_eq!(
            file_beside(&odd),
            dir.path().join("a.waypoints.mission.waypoints")
        );
    }

    #[test]
    fn float_xy_conversions() {
        assert_eq!(
            xy_from_float(MavFrame::MAV_FRAME_GLOBAL as u8, -35.363_261),
            -353_632_610
        );
        assert_eq!(
            xy_from_float(MavFrame::MAV_FRAME_LOCAL_NED as u8, 1.5),
            15_000
        );
        assert_eq!(xy_from_float(MavFrame::MAV_FRAME_MISSION as u8, 3.0), 3);
        assert_eq!(xy_from_float(MavFrame::MAV_FRAME_GLOBAL as u8, f64::NAN), 0);
        assert!(
            (xy_to_float(MavFrame::MAV_FRAME_GLOBAL as u8, -353_632_610) + 35.363_261).abs()
                < 1e-12
        );
    }
}
