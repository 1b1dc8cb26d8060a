//! The two rotors (body frame B, thrust along +z_B): thrust T = kT ω², drag D = kD ω²
//! (`PHYSICS.md` §2 eqs. 16–18), the roll torque of their thrust difference (10), the
//! gyroscopic torque Γg of their spinning inertia (11, [I11]) and the reaction (drag) torque Γq
//! (12, [I12]).
//!
//! Rotor 1 sits at y = +l_r and spins about +z_B; rotor 2 sits at y = −l_r and spins about −z_B.

use nalgebra::Vector3;

use crate::model::airframe::{Airframe, ModelMode};

/// Rotor thrusts (T1, T2), N: T = kT ω² (16).
#[must_use]
pub fn thrusts_n(af: &Airframe, rotor_speed_rad_s: &[f64; 2]) -> [f64; 2] {
    let k = af.k_thrust_n_per_rad2_s2;
    [
        k * rotor_speed_rad_s[0] * rotor_speed_rad_s[0],
        k * rotor_speed_rad_s[1] * rotor_speed_rad_s[1],
    ]
}

/// Rotor drags (D1, D2), N: D = kD ω² (17).
#[must_use]
pub fn drags_n(af: &Airframe, rotor_speed_rad_s: &[f64; 2]) -> [f64; 2] {
    let k = af.k_drag_n_per_rad2_s2;
    [
        k * rotor_speed_rad_s[0] * rotor_speed_rad_s[0],
        k * rotor_speed_rad_s[1] * rotor_speed_rad_s[1],
    ]
}

/// Thrust force in B: (0, 0, T1 + T2) (8).
#[must_use]
pub fn thrust_force_body_n(thrusts_n: &[f64; 2]) -> Vector3<f64> {
    Vector3::new(0.0, 0.0, thrusts_n[0] + thrusts_n[1])
}

/// Roll torque of the thrust difference: (l_r (T1 − T2), 0, 0) (10), [I2].
#[must_use]
pub fn thrust_torque_body_nm(af: &Airframe, thrusts_n: &[f64; 2]) -> Vector3<f64> {
    Vector3::new(af.rotor_arm_m * (thrusts_n[0] - thrusts_n[1]), 0.0, 0.0)
}

/// Gyroscopic torque Γg = −Σ I_r Ω × ω_ri = I_r (q(ω2 − ω1), p(ω1 − ω2), 0) (11) with I_r
/// restored ([I11]). The rotors' net angular momentum is I_r (ω1 − ω2) along +z_B.
#[must_use]
pub fn gyroscopic_torque_body_nm(
    af: &Airframe,
    omega_body_rad_s: &Vector3<f64>,
    rotor_speed_rad_s: &[f64; 2],
) -> Vector3<f64> {
    let h = af.rotor_inertia_kg_m2 * (rotor_speed_rad_s[0] - rotor_speed_rad_s[1]);
    Vector3::new(-omega_body_rad_s[1] * h, omega_body_rad_s[0] * h, 0.0)
}

/// Propeller reaction torque Γq about z_B.
///
/// `paper` keeps the paper's sign, +l_r (D1 − D2) (12). `physical` uses the sign consistent
/// with the spin directions behind (11): rotor 1 spins about +z_B, so its drag torque pushes the
/// body about −z_B: −l_r kD ω1² + l_r kD ω2² ([I12]).
#[must_use]
pub fn drag_torque_body_nm(af: &Airframe, model: ModelMode, drags_n: &[f64; 2]) -> Vector3<f64> {
    let paper = af.rotor_arm_m * (drags_n[0] - drags_n[1]);
    let tz = match model {
        ModelMode::Paper => paper,
        ModelMode::Physical => -paper,
    };
    Vector3::new(0.0, 0.0, tz)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn hover_speed_carries_weight() {
        let af = Airframe::default();
        let w = af.hover_rotor_speed_rad_s();
        let t = thrusts_n(&af, &[w, w]);
        assert!((t[0] + t[1] - af.weight_n()).abs() < 1e-12);
    }

    #[test]
    fn faster_rotor_one_rolls_positive() {
        // [I2]: rotor 1 at y = +l_r; more thrust there gives a positive torque about x_B.
        let af = Airframe::default();
        let tau = thrust_torque_body_nm(&af, &thrusts_n(&af, &[450.0, 430.0]));
        assert!(tau.x > 0.0 && tau.y == 0.0 && tau.z == 0.0);
    }

    #[test]
    fn gyroscopic_signs_follow_eq_11() {
        // Γg = I_r (q(ω2 − ω1), p(ω1 − ω2), 0).
        let af = Airframe::default();
        let w = [500.0, 400.0];
        let g = gyroscopic_torque_body_nm(&af, &Vector3::new(0.0, 1.0, 0.0), &w);
        assert!((g.x - af.rotor_inertia_kg_m2 * (400.0 - 500.0)).abs() < 1e-15);
        assert_eq!((g.y, g.z), (0.0, 0.0));
        let g = gyroscopic_torque_body_nm(&af, &Vector3::new(1.0, 0.0, 0.0), &w);
        assert!((g.y - af.rotor_inertia_kg_m2 * (500.0 - 400.0)).abs() < 1e-15);
        assert_eq!((g.x, g.z), (0.0, 0.0));
        // Equal and opposite rotors cancel.
        let g = gyroscopic_torque_body_nm(&af, &Vector3::new(1.0, 2.0, 3.0), &[450.0, 450.0]);
        assert_eq!(g, Vector3::zeros());
    }

    #[test]
    fn drag_torque_signs_per_model() {
        let af = Airframe::default();
        let d = drags_n(&af, &[500.0, 400.0]);
        let paper = drag_torque_body_nm(&af, ModelMode::Paper, &d);
        let phys = drag_torque_body_nm(&af, ModelMode::Physical, &d);
        assert!(paper.z > 0.0, "paper: +l_r(D1 − D2)");
        assert!(
            phys.z < 0.0,
            "physical: rotor 1 (about +z_B) reacts about −z_B"
        );
        assert!((paper.z + phys.z).abs() < 1e-15);
    }
}
