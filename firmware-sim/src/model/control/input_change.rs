//! The input change (33) of `PHYSICS.md` §3 and its algebraic loop [I19].
//!
//! Euler's equation (2) with Ω̇ = Ẇ_n η̇ + W_n η̈ (4) gives
//! I W_n η̈ = Γc + Γg + Γq − I Ẇ_n η̇ − Ω × IΩ, so choosing
//! Γc = I W_n Γ̃ + I Ẇ_n η̇ + Ω × IΩ − Γg − Γq
//! makes η̈ = Γ̃ exactly, with Γ̃ stacked as (τ̃ψ, τ̃θ, τ̃φ) like η [I5].
//!
//! Body frame (§1). Γg = I_r (q(ω2 − ω1), p(ω1 − ω2), 0) (11) with I_r [I11]. Γq is
//! (0, 0, l_r kD (ω1² − ω2²)) in `paper` mode (the paper's sign, [I12]) and its negative in
//! `physical` mode (rotor 1 spins about +z_B, so its reaction torque is −Q1).
//!
//! Γg and Γq depend on the rotor speeds, which depend on Γc,x through the mixer: the loop is
//! solved by fixed-point iteration from the measured speeds [I19]. The map's gain is about
//! 2 I_r |q| · ∂ω/∂Γx ≈ 0.036·|q| per iteration at hover. PHYSICS.md's six iterations reach
//! rounding at the paper's rates; at the gyros' full scale they do not, and near hover two or
//! three suffice, so the loop runs (bounded, no allocation) until the speeds stop moving.

use nalgebra::{Matrix3, Vector3};

use super::mixer::rotor_speeds_rad_s;
use crate::model::airframe::{Airframe, ModelMode};
use crate::model::frames::Euler;

/// Upper bound on the fixed-point iterations of [I19]. The loop stops as soon as the speeds
/// move by no more than [`INPUT_CHANGE_TOLERANCE_RAD_S`]: the contraction factor is
/// ≈ 0.036 |q| (q in rad/s), so near hover two or three passes reach it, PHYSICS.md's six are
/// at rounding for the paper's rates (|q| ≲ 0.5 rad/s), and the gyros' 2.6 rad/s needs about
/// ten. Iterating to a tolerance instead of a fixed count is as exact and cheaper in hover.
pub const INPUT_CHANGE_MAX_ITERATIONS: usize = 16;

/// Speed change below which the fixed point is considered reached, rad/s.
pub const INPUT_CHANGE_TOLERANCE_RAD_S: f64 = 1e-10;

/// Gyroscopic torque Γg of (11) with I_r [I11], N·m.
#[must_use]
pub fn gyroscopic_torque_nm(
    rotor_inertia_kg_m2: f64,
    omega_body_rad_s: &Vector3<f64>,
    rotor_speed_rad_s: [f64; 2],
) -> Vector3<f64> {
    let [w1, w2] = rotor_speed_rad_s;
    let (p, q) = (omega_body_rad_s.x, omega_body_rad_s.y);
    rotor_inertia_kg_m2 * Vector3::new(q * (w2 - w1), p * (w1 - w2), 0.0)
}

/// Rotor reaction torque Γq of (12), N·m: paper sign in `paper` mode, the physically consistent
/// sign in `physical` mode [I12].
#[must_use]
pub fn rotor_drag_torque_nm(
    airframe: &Airframe,
    model: ModelMode,
    rotor_speed_rad_s: [f64; 2],
) -> Vector3<f64> {
    let [w1, w2] = rotor_speed_rad_s;
    let paper = airframe.rotor_arm_m * airframe.k_drag_n_per_rad2_s2 * (w1 * w1 - w2 * w2);
    let z = match model {
        ModelMode::Paper => paper,
        ModelMode::Physical => -paper,
    };
    Vector3::new(0.0, 0.0, z)
}

/// The diagonal inertia matrix I of (6).
#[must_use]
pub fn inertia_matrix(airframe: &Airframe) -> Matrix3<f64> {
    Matrix3::from_diagonal(&Vector3::from(airframe.inertia_kg_m2))
}

/// (33) for given disturbance torques: Γc = I W_n Γ̃ + I Ẇ_n η̇ + Ω × IΩ − Γg − Γq.
#[must_use]
pub fn input_change_nm(
    inertia: &Matrix3<f64>,
    euler: &Euler,
    omega_body_rad_s: &Vector3<f64>,
    eta_dot: &Vector3<f64>,
    tau_tilde: &Vector3<f64>,
    disturbance_nm: &Vector3<f64>,
) -> Vector3<f64> {
    let w = euler.w_n();
    let w_dot = euler.w_n_dot(eta_dot);
    inertia * (w * tau_tilde + w_dot * eta_dot)
        + omega_body_rad_s.cross(&(inertia * omega_body_rad_s))
        - disturbance_nm
}

/// Solves (33) together with the mixer's rotor speeds [I19]: returns Γc and the rotor speeds
/// Γg and Γq were last evaluated at (which the mixer reproduces from Γc once converged).
/// Iterates to [`INPUT_CHANGE_TOLERANCE_RAD_S`], at most [`INPUT_CHANGE_MAX_ITERATIONS`] times.
///
/// `rotor_speed_start_rad_s` is the first guess (the measured speeds).
#[allow(clippy::too_many_arguments)]
#[must_use]
pub fn solve_input_change(
    airframe: &Airframe,
    model: ModelMode,
    euler: &Euler,
    omega_body_rad_s: &Vector3<f64>,
    eta_dot: &Vector3<f64>,
    tau_tilde: &Vector3<f64>,
    fz_n: f64,
    rotor_speed_start_rad_s: [f64; 2],
) -> (Vector3<f64>, [f64; 2]) {
    let inertia = inertia_matrix(airframe);
    // Everything but Γg + Γq is independent of the speeds: compute it once.
    let base = input_change_nm(
        &inertia,
        euler,
        omega_body_rad_s,
        eta_dot,
        tau_tilde,
        &Vector3::zeros(),
    );
    let torque_at = |w: [f64; 2]| {
        base - gyroscopic_torque_nm(airframe.rotor_inertia_kg_m2, omega_body_rad_s, w)
            - rotor_drag_torque_nm(airframe, model, w)
    };
    let mut w = rotor_speed_start_rad_s;
    let mut torque = torque_at(w);
    for _ in 0..INPUT_CHANGE_MAX_ITERATIONS {
        let next = rotor_speeds_rad_s(airframe, model, fz_n, torque.x);
        let moved = (next[0] - w[0]).abs().max((next[1] - w[1]).abs());
        w = next;
        torque = torque_at(w);
        if moved <= INPUT_CHANGE_TOLERANCE_RAD_S {
            break;
        }
    }
    (torque, w)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// η̈ from Euler's equation (13)/(14) with the corrected signs, through the frames helpers:
    /// Ω̇ = I⁻¹(Γc + Γg + Γq − Ω × IΩ), η̈ = W_n⁻¹ (Ω̇ − Ẇ_n η̇).
    pub(crate) fn eta_ddot(
        airframe: &Airframe,
        model: ModelMode,
        euler: &Euler,
        omega: &Vector3<f64>,
        torque_c: &Vector3<f64>,
        rotor_speed_rad_s: [f64; 2],
    ) -> Vector3<f64> {
        let i = inertia_matrix(airframe);
        let total = torque_c
            + gyroscopic_torque_nm(airframe.rotor_inertia_kg_m2, omega, rotor_speed_rad_s)
            + rotor_drag_torque_nm(airframe, model, rotor_speed_rad_s)
            - omega.cross(&(i * omega));
        let omega_dot = i.try_inverse().expect("diagonal, positive") * total;
        let eta_dot = euler.rates_from_body(omega);
        euler.w_n_inverse() * (omega_dot - euler.w_n_dot(&eta_dot) * eta_dot)
    }

    #[test]
    fn gamma_g_and_gamma_q_components() {
        let a = Airframe::default();
        let g = gyroscopic_torque_nm(2.0, &Vector3::new(3.0, 5.0, 7.0), [10.0, 4.0]);
        assert_eq!(
            g,
            Vector3::new(5.0 * 2.0 * (4.0 - 10.0), 3.0 * 2.0 * 6.0, 0.0)
        );
        let qp = rotor_drag_torque_nm(&a, ModelMode::Paper, [400.0, 300.0]);
        let qf = rotor_drag_torque_nm(&a, ModelMode::Physical, [400.0, 300.0]);
        assert!(qp.z > 0.0 && (qp + qf).norm() == 0.0);
        assert!((qp.z - 0.15 * 1.25e-6 * (160_000.0 - 90_000.0)).abs() < 1e-15);
    }

    #[test]
    fn input_change_gives_eta_ddot_equal_tau_tilde() {
        let a = Airframe::default();
        let euler = Euler::new(0.7, -0.25, 0.3);
        let omega = Vector3::new(0.8, -0.6, 0.4);
        let eta_dot = euler.rates_from_body(&omega);
        let tau = Vector3::new(-1.1, 0.4, 0.9);
        for m in [ModelMode::Paper, ModelMode::Physical] {
            let (tc, w) =
                solve_input_change(&a, m, &euler, &omega, &eta_dot, &tau, 5.2, [420.0, 450.0]);
            // The speeds returned are what the mixer makes of Γc: the loop is closed.
            let w_mixer = rotor_speeds_rad_s(&a, m, 5.2, tc.x);
            assert!((w_mixer[0] - w[0]).abs() < 1e-9 && (w_mixer[1] - w[1]).abs() < 1e-9);
            let edd = eta_ddot(&a, m, &euler, &omega, &tc, w);
            assert!((edd - tau).norm() < 1e-9, "{m:?}: {edd} vs {tau}");
        }
    }

    #[test]
    fn without_iteration_the_measured_speeds_would_be_wrong() {
        // A guard that the test above can fail: evaluating Γg at stale speeds misses η̈ = Γ̃ by
        // far more than 1e-9 when the body rates are large.
        let a = Airframe::default();
        let euler = Euler::new(0.0, 0.1, -0.2);
        let omega = Vector3::new(1.5, -2.0, 0.5);
        let eta_dot = euler.rates_from_body(&omega);
        let tau = Vector3::new(0.3, -0.4, 1.5);
        let i = inertia_matrix(&a);
        let stale = [300.0, 500.0];
        let d = gyroscopic_torque_nm(a.rotor_inertia_kg_m2, &omega, stale)
            + rotor_drag_torque_nm(&a, ModelMode::Paper, stale);
        let tc = input_change_nm(&i, &euler, &omega, &eta_dot, &tau, &d);
        let w_real = rotor_speeds_rad_s(&a, ModelMode::Paper, 4.9, tc.x);
        let edd = eta_ddot(&a, ModelMode::Paper, &euler, &omega, &tc, w_real);
        assert!((edd - tau).norm() > 1e-4, "{edd}");
    }
}
