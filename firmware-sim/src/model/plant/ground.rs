//! Ground contact as a kinematic constraint (inertial frame I, z up; the ground is z = 0).
//!
//! The twin is a tail-sitter standing on its landing gear: on the ground it is held level at
//! z = 0 with zero velocity and rates (heading kept), and it lifts off when the vertical
//! acceleration the loads would give is upward. In the air, crossing z = 0 is a touchdown; the
//! sink rate and the tilt at that moment tell the vehicle whether it landed or crashed.

use nalgebra::Vector3;

use crate::model::frames::Euler;

use super::PlantState;

/// The state of a vehicle resting on the ground: z = 0, level, still, heading kept.
#[must_use]
pub fn resting(s: &PlantState) -> PlantState {
    PlantState {
        pos_m: Vector3::new(s.pos_m.x, s.pos_m.y, 0.0),
        vel_body_m_s: Vector3::zeros(),
        euler: Euler::new(s.euler.psi, 0.0, 0.0),
        omega_body_rad_s: Vector3::zeros(),
    }
}

/// Whether a resting vehicle leaves the ground: the vertical component of the
/// non-gravitational force (in I) exceeds the weight.
#[must_use]
pub fn lifts_off(vertical_force_n: f64, weight_n: f64) -> bool {
    vertical_force_n > weight_n
}

/// What happened when a flying vehicle reached the ground.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Touchdown {
    /// Downward speed at contact, m/s (≥ 0).
    pub sink_rate_m_s: f64,
    /// Tilt of z_B from the vertical at contact, rad.
    pub tilt_rad: f64,
}

/// Checks a flying state for contact with the ground; on contact returns the impact and the
/// state is replaced by the resting one.
pub fn touchdown(s: &mut PlantState) -> Option<Touchdown> {
    if s.pos_m.z > 0.0 {
        return None;
    }
    let vz = s.vel_inertial_m_s().z;
    let tilt = (s.euler.theta.cos() * s.euler.phi.cos())
        .clamp(-1.0, 1.0)
        .acos();
    *s = resting(s);
    Some(Touchdown {
        sink_rate_m_s: (-vz).max(0.0),
        tilt_rad: tilt,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn touchdown_reports_sink_rate_and_settles() {
        let mut s = PlantState {
            pos_m: Vector3::new(1.0, 2.0, -0.001),
            vel_body_m_s: Vector3::new(0.0, 0.0, -0.8),
            euler: Euler::new(0.5, 0.0, 0.0),
            omega_body_rad_s: Vector3::new(0.1, 0.0, 0.0),
        };
        let t = touchdown(&mut s).expect("contact");
        assert!((t.sink_rate_m_s - 0.8).abs() < 1e-12 && t.tilt_rad.abs() < 1e-12);
        assert_eq!(s.pos_m, Vector3::new(1.0, 2.0, 0.0));
        assert_eq!(s.euler, Euler::new(0.5, 0.0, 0.0));
        assert_eq!(s.omega_body_rad_s, Vector3::zeros());
        let mut up = PlantState {
            pos_m: Vector3::new(0.0, 0.0, 0.01),
            ..s
        };
        assert!(touchdown(&mut up).is_none());
        assert!(lifts_off(5.0, 4.9) && !lifts_off(4.9, 4.9));
    }
}
