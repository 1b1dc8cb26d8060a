//! The navigator's fixed-wing legs (`docs/forward-flight.md`): what the vehicle needs to know to
//! fly a waypoint, an approach or a loiter on the wing, and the guidance for each (L1 for the
//! bank, the height and the trim airspeed for the energy controller). Frames: local NED.

use mavlink::dialects::ardupilotmega::MavCmd;
use nalgebra::{Vector2, Vector3};

use crate::model::mode::{ForwardGuidance, Guidance, VtolState};
use crate::nav::globe::{GeoPoint, Origin, horizontal_distance_m};
use crate::nav::l1::{self, L1Params};
use crate::nav::mission::{Mission, MissionItem};

/// A fixed-wing approach to a VTOL landing starts the back transition this far from the
/// landing point, m: the slowing stage and the pull-up take about 50 m from the trim airspeed;
/// the hover flies the rest.
pub const APPROACH_DISTANCE_M: f64 = 50.0;

/// What the fixed-wing legs need of the vehicle and its settings.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FixedWingInput {
    /// Hover, forward flight or a transition.
    pub vtol: VtolState,
    /// Ground velocity (local NED), m/s.
    pub vel_ned_m_s: Vector3<f64>,
    /// Airspeed of the legs (`TRIM_ARSPD_CM`), m/s.
    pub airspeed_m_s: f64,
    /// `NAVL1_PERIOD`, `NAVL1_DAMPING`.
    pub l1: L1Params,
    /// The radius of this mode's circles, m: `WP_LOITER_RAD`, in RTL `RTL_RADIUS` when set.
    pub loiter_radius_m: f64,
    /// `WP_RADIUS`, m: the most a waypoint on the wing is reached short of its point.
    pub wp_radius_m: f64,
    /// Gravity, m/s².
    pub gravity_m_s2: f64,
    /// `Q_RTL_MODE` 1 or 2: RTL on the wing lands vertically at home (QRTL on arrival); 0: it
    /// circles home (3, QRTL always, never gets here).
    pub rtl_vtol_land: bool,
    /// `Q_TRANS_DECEL`, m/s²: the deceleration the VTOL landing distances assume.
    pub trans_decel_m_s2: f64,
    /// `Q_GUIDED_MODE` 0: a GUIDED target in the air is flown to on the wing and circled at
    /// `WP_LOITER_RAD`; 1: flown to and held in a hover.
    pub guided_on_the_wing: bool,
    /// `RTL_ALTITUDE`, m above home; `None` (a negative value): RTL keeps its altitude.
    pub rtl_altitude_m: Option<f64>,
    /// `Q_ENABLE` 2 (VTOL AUTO): AUTO starts in VTOL mode, its position items flown in a hover.
    pub vtol_auto: bool,
}

impl Default for FixedWingInput {
    fn default() -> Self {
        Self {
            vtol: VtolState::Mc,
            vel_ned_m_s: Vector3::zeros(),
            airspeed_m_s: 12.0,
            l1: L1Params {
                period_s: 10.0,
                damping: 0.75,
            },
            loiter_radius_m: 60.0,
            wp_radius_m: 90.0,
            gravity_m_s2: crate::model::airframe::GRAVITY_M_S2,
            rtl_vtol_land: false,
            trans_decel_m_s2: 6.0,
            guided_on_the_wing: true,
            rtl_altitude_m: Some(100.0),
            vtol_auto: false,
        }
    }
}

/// ArduPlane's `QuadPlane::stopping_distance`: v² / (2 `Q_TRANS_DECEL`), m.
#[must_use]
pub fn stopping_distance_m(speed_m_s: f64, decel_m_s2: f64) -> f64 {
    speed_m_s * speed_m_s / (2.0 * decel_m_s2)
}

/// ArduPlane's pre-arm mission check (`AP_Arming_Plane::mission_checks`): a VTOL landing
/// (NAV_LAND, NAV_VTOL_LAND) right after a NAV_WAYPOINT must be at least 0.75 stopping
/// distances at the landing airspeed (here the cruise airspeed) from it. Returns the text
/// ArduPlane sends (without "PreArm: ") for the first leg too short.
#[must_use]
pub fn vtol_land_too_short(
    mission: &Mission,
    origin: &Origin,
    airspeed_m_s: f64,
    decel_m_s2: f64,
) -> Option<String> {
    let min_m = 0.75 * stopping_distance_m(airspeed_m_s, decel_m_s2);
    let items = mission.items();
    items
        .iter()
        .skip(1)
        .zip(items.iter().skip(2))
        .find_map(|(prev, it)| {
            let land = matches!(
                it.cmd(),
                Some(MavCmd::MAV_CMD_NAV_LAND | MavCmd::MAV_CMD_NAV_VTOL_LAND)
            );
            // A point of latitude and longitude 0 is "here": ArduPilot's distance to it is the
            // distance to 0°, 0°, never short.
            let placed = |i: &MissionItem| i.x != 0 || i.y != 0;
            if !(land
                && prev.command == MavCmd::MAV_CMD_NAV_WAYPOINT as u16
                && placed(prev)
                && placed(it))
            {
                return None;
            }
            let at = |i: &MissionItem| {
                origin.to_local_ned(&GeoPoint {
                    lat_e7: i.x,
                    lon_e7: i.y,
                    alt_amsl_m: 0.0,
                })
            };
            let dist = horizontal_distance_m(&at(prev), &at(it));
            (dist < min_m).then(|| format!("VTOL land too short, min {min_m:.0}m"))
        })
}

impl FixedWingInput {
    /// ArduPlane's `QuadPlane::transition_threshold`: a VTOL landing point farther than 1.5
    /// stopping distances at the cruise airspeed is approached on the wing, m.
    #[must_use]
    pub fn transition_threshold_m(&self) -> f64 {
        1.5 * stopping_distance_m(self.airspeed_m_s, self.trans_decel_m_s2)
    }

    /// Whether the vehicle flies (or is going) on the wing.
    #[must_use]
    pub fn on_the_wing(&self) -> bool {
        matches!(self.vtol, VtolState::Fw | VtolState::TransitionToFw)
    }
}

/// Whether `here` is past the line through `to` square to the leg `from` → `to` (ArduPlane's
/// "passed the waypoint").
#[must_use]
pub fn passed(from: &Vector2<f64>, to: &Vector2<f64>, here: &Vector2<f64>) -> bool {
    let leg = to - from;
    leg.norm() > 1e-6 && (here - to).dot(&leg) >= 0.0
}

fn forward(fw: &FixedWingInput, z_ned_m: f64, accel: f64) -> Guidance {
    Guidance::Forward(ForwardGuidance {
        height_m: -z_ned_m,
        airspeed_m_s: fw.airspeed_m_s,
        bank_rad: (accel / fw.gravity_m_s2).atan(),
    })
}

/// Fly the line `from` → `to` at `z_ned_m`.
#[must_use]
pub fn track(
    fw: &FixedWingInput,
    here: &Vector3<f64>,
    from: &Vector2<f64>,
    to: &Vector2<f64>,
    z_ned_m: f64,
) -> Guidance {
    let a = l1::track_accel(&fw.l1, &here.xy(), &fw.vel_ned_m_s.xy(), from, to);
    forward(fw, z_ned_m, a)
}

/// Circle `centre` at `WP_LOITER_RAD` and `z_ned_m`.
#[must_use]
pub fn loiter(
    fw: &FixedWingInput,
    here: &Vector3<f64>,
    centre: &Vector2<f64>,
    z_ned_m: f64,
) -> Guidance {
    let a = l1::loiter_accel(
        &fw.l1,
        &here.xy(),
        &fw.vel_ned_m_s.xy(),
        centre,
        fw.loiter_radius_m,
    );
    forward(fw, z_ned_m, a)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_waypoint_is_passed_at_the_square_through_it() {
        let (a, b) = (Vector2::zeros(), Vector2::new(100.0, 0.0));
        assert!(!passed(&a, &b, &Vector2::new(99.0, 20.0)));
        assert!(passed(&a, &b, &Vector2::new(100.5, -20.0)));
    }

    #[test]
    fn the_legs_ask_for_the_height_up_and_the_trim_airspeed() {
        let fw = FixedWingInput {
            vel_ned_m_s: Vector3::new(12.0, 0.0, 0.0),
            ..FixedWingInput::default()
        };
        let g = track(
            &fw,
            &Vector3::new(10.0, 0.0, -20.0),
            &Vector2::zeros(),
            &Vector2::new(100.0, 0.0),
            -20.0,
        );
        let Guidance::Forward(f) = g else {
            panic!("{g:?}")
        };
        assert!(
            (f.height_m - 20.0).abs() < 1e-12 && f.bank_rad.abs() < 1e-9,
            "{f:?}"
        );
        assert!((f.airspeed_m_s - 12.0).abs() < 1e-12);
    }
}

#[cfg(test)]
mod mission_check_tests {
    use super::*;
    use crate::nav::mission::test_items::{item, limits};
    use mavlink::dialects::ardupilotmega::MavFrame;

    fn at(command: u16, north_m: f64) -> MissionItem {
        let p = limits().origin.to_global(&Vector3::new(north_m, 0.0, 0.0));
        item(command, [0.0; 4], p.lat_e7, p.lon_e7, 20.0)
    }

    /// ArduPlane's rule: 0.75 v² / (2 Q_TRANS_DECEL), 27 m at 12 m/s and 2 m/s², between a
    /// NAV_WAYPOINT and the VTOL landing right after it.
    #[test]
    fn a_vtol_landing_too_close_after_its_waypoint_is_refused_with_ardupilots_text() {
        let o = limits().origin;
        let mission = |leg_m: f64| {
            Mission::new(vec![
                at(MavCmd::MAV_CMD_NAV_WAYPOINT as u16, 0.0),
                at(MavCmd::MAV_CMD_NAV_VTOL_TAKEOFF as u16, 0.0),
                at(MavCmd::MAV_CMD_NAV_WAYPOINT as u16, 100.0),
                at(MavCmd::MAV_CMD_NAV_VTOL_LAND as u16, 100.0 - leg_m),
            ])
        };
        assert_eq!(
            vtol_land_too_short(&mission(20.0), &o, 12.0, 2.0).as_deref(),
            Some("VTOL land too short, min 27m")
        );
        assert_eq!(vtol_land_too_short(&mission(30.0), &o, 12.0, 2.0), None);
        // What ArduPlane SITL's tailsitter answers for a 29 m leg (AIRSPEED_CRUISE 22,
        // Q_TRANS_DECEL 6), and the twin's defaults (12 m/s, 6 m/s²).
        assert_eq!(
            vtol_land_too_short(&mission(29.0), &o, 22.0, 6.0).as_deref(),
            Some("VTOL land too short, min 30m")
        );
        assert_eq!(
            vtol_land_too_short(&mission(5.0), &o, 12.0, 6.0).as_deref(),
            Some("VTOL land too short, min 9m")
        );
        // NAV_LAND counts too; a DO item between them, or a landing "here", does not.
        let mut m = mission(20.0).items().to_vec();
        m[3].command = MavCmd::MAV_CMD_NAV_LAND as u16;
        assert!(vtol_land_too_short(&Mission::new(m.clone()), &o, 12.0, 2.0).is_some());
        let mut with_do = m.clone();
        let mut tr = at(MavCmd::MAV_CMD_DO_VTOL_TRANSITION as u16, 0.0);
        (tr.x, tr.y, tr.frame, tr.params[0]) = (0, 0, MavFrame::MAV_FRAME_MISSION as u8, 3.0);
        with_do.insert(3, tr);
        assert_eq!(
            vtol_land_too_short(&Mission::new(with_do), &o, 12.0, 2.0),
            None
        );
        (m[3].x, m[3].y) = (0, 0);
        assert_eq!(vtol_land_too_short(&Mission::new(m), &o, 12.0, 2.0), None);
    }
}
