//! The free stream over the control surfaces (`physical` mode). The paper's surfaces see only
//! the prop-wash (`surfaces`, (24)): exact in hover, but in forward flight the air arriving
//! along the nose blows over the elevator and the ailerons too, and their lift is
//! k C_L (υ² + V_s²) δ, the wash and the free stream's dynamic pressures added (the design in
//! `docs/forward-flight.md`). This module gives the free-stream part; the wash part stays in
//! [`super::surfaces`], so a hover in still air is the paper's model exactly.

use nalgebra::Vector3;

use super::Loads;
use super::surfaces::{self, SurfaceLifts};
use crate::model::airframe::Airframe;
use crate::model::signals::ActuatorCommand;

/// The free stream's squared speed along the nose, m²/s²: the air-relative velocity's component
/// along +z_B (flow from the nose back over the trailing-edge surfaces). Reversed flow (the
/// vehicle sinking tail first) gives none: the surfaces then sit in the wing's wake.
#[inline]
#[must_use]
pub fn axial_speed_sq(v_air_body_m_s: &Vector3<f64>) -> f64 {
    let w = v_air_body_m_s.z.max(0.0);
    w * w
}

/// Signed surface lifts from the free stream alone, N (same signs as [`surfaces::lifts`]).
#[must_use]
pub fn free_stream_lifts(
    af: &Airframe,
    v_air_body_m_s: &Vector3<f64>,
    act: &ActuatorCommand,
) -> SurfaceLifts {
    let vs_sq = axial_speed_sq(v_air_body_m_s);
    surfaces::lifts_in(af, act, [vs_sq; 3])
}

/// Force and torque of the free stream over the surfaces, in B.
#[must_use]
pub fn free_stream_loads(
    af: &Airframe,
    v_air_body_m_s: &Vector3<f64>,
    act: &ActuatorCommand,
) -> Loads {
    let l = free_stream_lifts(af, v_air_body_m_s, act);
    Loads {
        force_body_n: surfaces::force_body_n(&l),
        torque_body_nm: surfaces::torque_body_nm(af, &l),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn no_axial_flow_no_free_stream_lift() {
        let af = Airframe::default();
        let act = ActuatorCommand {
            elevator_rad: 0.2,
            aileron_left_rad: 0.1,
            aileron_right_rad: -0.1,
            ..ActuatorCommand::default()
        };
        for v in [
            Vector3::zeros(),
            Vector3::new(3.0, 1.0, 0.0),
            Vector3::new(0.0, 0.0, -5.0),
        ] {
            assert_eq!(free_stream_loads(&af, &v, &act), Loads::default());
        }
    }

    #[test]
    fn elevator_authority_grows_with_the_square_of_the_airspeed() {
        let af = Airframe::default();
        let act = ActuatorCommand {
            elevator_rad: 0.1,
            ..ActuatorCommand::default()
        };
        let at = |v: f64| {
            free_stream_loads(&af, &Vector3::new(0.0, 0.0, v), &act)
                .torque_body_nm
                .y
        };
        assert!(at(10.0) > 0.0);
        assert!((at(12.0) / at(6.0) - 4.0).abs() < 1e-12);
    }
}
