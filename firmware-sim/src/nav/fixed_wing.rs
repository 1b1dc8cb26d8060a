//! The navigator's fixed-wing legs (`docs/forward-flight.md`): what the vehicle needs to know to
//! fly a waypoint, an approach or a loiter on the wing, and the guidance for each (L1 for the
//! bank, the height and the trim airspeed for the energy controller). Frames: local NED.

use nalgebra::{Vector2, Vector3};

use crate::model::mode::{ForwardGuidance, Guidance, VtolState};
use crate::nav::l1::{self, L1Params};

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
    /// `WP_LOITER_RAD`, m.
    pub loiter_radius_m: f64,
    /// Gravity, m/s².
    pub gravity_m_s2: f64,
    /// `Q_RTL_MODE` = 1: RTL on the wing lands vertically at home (QRTL on arrival); 0: it
    /// circles home at `WP_LOITER_RAD`.
    pub rtl_vtol_land: bool,
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
            loiter_radius_m: 30.0,
            gravity_m_s2: crate::model::airframe::GRAVITY_M_S2,
            rtl_vtol_land: true,
        }
    }
}

impl FixedWingInput {
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
