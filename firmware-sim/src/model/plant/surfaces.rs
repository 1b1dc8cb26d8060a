//! Control surfaces in the prop-wash (body frame B): the elevator below the CG and the two
//! ailerons behind the rotors (`PHYSICS.md` §2 eqs. 19–24, §5 steps 3–5, [I14], [I15]).
//!
//! Flat plates at zero incidence in the slipstream: lift = k ½ρS · C_L · υ² · δ, no drag (C_D ≈ 0).
//! The elevator spans both slipstreams (υ_e² = (υ1² + υ2²)/2); aileron R sits behind rotor 1
//! (y = +l_a), aileron L behind rotor 2 (y = −l_a). Lifts are signed: positive δ gives lift
//! along +x_B for the ailerons and along −x_B for the elevator.

use nalgebra::Vector3;

use crate::model::airframe::Airframe;
use crate::model::signals::ActuatorCommand;

/// Signed lifts of the three surfaces, N.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct SurfaceLifts {
    /// Elevator lift L_e; acts along −x_B ([I15]).
    pub elevator_n: f64,
    /// Left aileron lift L_aL (behind rotor 2); acts along +x_B.
    pub aileron_left_n: f64,
    /// Right aileron lift L_aR (behind rotor 1); acts along +x_B.
    pub aileron_right_n: f64,
}

/// Signed surface lifts from the rotor speeds (prop-wash υ_i = k_υ ω_i, (24)) and deflections.
#[must_use]
pub fn lifts(af: &Airframe, act: &ActuatorCommand) -> SurfaceLifts {
    let v1 = af.k_wash_m_per_rad * act.rotor_speed_rad_s[0];
    let v2 = af.k_wash_m_per_rad * act.rotor_speed_rad_s[1];
    let (v1_sq, v2_sq) = (v1 * v1, v2 * v2);
    let ve_sq = 0.5 * (v1_sq + v2_sq);
    lifts_in(af, act, [ve_sq, v2_sq, v1_sq])
}

/// Signed surface lifts with the squared air speed over the elevator, the left and the right
/// aileron, m²/s²: L = k C_L υ² δ for each.
#[must_use]
pub fn lifts_in(af: &Airframe, act: &ActuatorCommand, speed_sq: [f64; 3]) -> SurfaceLifts {
    let cl = af.lift_slope_per_rad;
    let [elevator_sq, left_sq, right_sq] = speed_sq;
    SurfaceLifts {
        elevator_n: af.k_elevator_kg_m * cl * elevator_sq * act.elevator_rad,
        aileron_left_n: af.k_aileron_kg_m * cl * left_sq * act.aileron_left_rad,
        aileron_right_n: af.k_aileron_kg_m * cl * right_sq * act.aileron_right_rad,
    }
}

/// Surface force in B: f_x,surf = L_aL + L_aR − L_e ([I14], [I15]); f_y = f_z = 0 (C_D ≈ 0).
#[must_use]
pub fn force_body_n(l: &SurfaceLifts) -> Vector3<f64> {
    Vector3::new(
        l.aileron_left_n + l.aileron_right_n - l.elevator_n,
        0.0,
        0.0,
    )
}

/// Surface torque in B: (0, l_e L_e, l_a (L_aL − L_aR)) (10), [I14], [I15].
///
/// The elevator sits at z_B = −l_e and pushes along −x_B: r × F = (0, 0, −l_e) × (−L_e, 0, 0)
/// = (0, +l_e L_e, 0). The left aileron sits at y = −l_a: (0, −l_a, 0) × (L_aL, 0, 0)
/// = (0, 0, +l_a L_aL); the right one gives −l_a L_aR.
#[must_use]
pub fn torque_body_nm(af: &Airframe, l: &SurfaceLifts) -> Vector3<f64> {
    Vector3::new(
        0.0,
        af.elevator_arm_m * l.elevator_n,
        af.aileron_arm_m * (l.aileron_left_n - l.aileron_right_n),
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    fn hover(af: &Airframe) -> ActuatorCommand {
        let w = af.hover_rotor_speed_rad_s();
        ActuatorCommand {
            rotor_speed_rad_s: [w, w],
            ..Default::default()
        }
    }

    #[test]
    fn elevator_pitches_positive_and_pushes_minus_x() {
        let af = Airframe::default();
        let l = lifts(
            &af,
            &ActuatorCommand {
                elevator_rad: 0.1,
                ..hover(&af)
            },
        );
        assert!(torque_body_nm(&af, &l).y > 0.0);
        assert!(force_body_n(&l).x < 0.0);
        // Authority at hover, §5: about 0.76 N·m/rad.
        let per_rad = torque_body_nm(&af, &l).y / 0.1;
        assert!((per_rad - 0.76).abs() < 0.02, "{per_rad}");
    }

    #[test]
    fn differential_ailerons_are_a_pure_yaw_couple() {
        let af = Airframe::default();
        let act = ActuatorCommand {
            aileron_left_rad: 0.1,
            aileron_right_rad: -0.1,
            ..hover(&af)
        };
        let l = lifts(&af, &act);
        assert!(torque_body_nm(&af, &l).z > 0.0);
        assert!(force_body_n(&l).x.abs() < 1e-12);
        let per_rad = torque_body_nm(&af, &l).z / 0.1;
        assert!((per_rad - 0.86).abs() < 0.02, "{per_rad}");
    }

    #[test]
    fn no_wash_no_lift() {
        let af = Airframe::default();
        let act = ActuatorCommand {
            elevator_rad: 0.3,
            aileron_left_rad: 0.3,
            ..Default::default()
        };
        assert_eq!(lifts(&af, &act), SurfaceLifts::default());
    }
}
