//! Axial (yaw) law (45) of `PHYSICS.md` §3 [I9]: τ̃ψ = −a_ψ1 ψ̇ − a_ψ2 (ψ − ψ_d).
//!
//! ψ is the rotation about z_B (the thrust axis) driven by the differential ailerons [I2]. The
//! error is wrapped into (−π, π] so the vehicle turns the short way round; with ψ_d = 0 and |ψ| < π
//! this is exactly the paper's law. The pilot modes add a rate setpoint ψ̇_d (yaw stick).

use crate::model::frames::wrap_pi;

/// τ̃ψ = −a_ψ1 (ψ̇ − ψ̇_d) − a_ψ2 wrap(ψ − ψ_d), rad/s². ψ̇ is the Euler rate (from W_n⁻¹ Ω).
#[must_use]
pub fn yaw_tau(
    kd: f64,
    kp: f64,
    psi_rad: f64,
    psi_dot_rad_s: f64,
    psi_setpoint_rad: f64,
    psi_dot_setpoint_rad_s: f64,
) -> f64 {
    -kd * (psi_dot_rad_s - psi_dot_setpoint_rad_s) - kp * wrap_pi(psi_rad - psi_setpoint_rad)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn paper_initial_value() {
        // Section IV: ψ0 = 1 rad, ψ̇0 = 0, a_ψ1 = a_ψ2 = 5 → τ̃ψ(0) = −5.
        assert!((yaw_tau(5.0, 5.0, 1.0, 0.0, 0.0, 0.0) + 5.0).abs() < 1e-15);
    }

    #[test]
    fn wraps_the_short_way() {
        // ψ = 3.0, ψ_d = −3.0: the short way is +0.283 rad forward, so the error is −0.283.
        let tau = yaw_tau(5.0, 5.0, 3.0, 0.0, -3.0, 0.0);
        let err = 6.0 - 2.0 * std::f64::consts::PI;
        assert!((tau + 5.0 * err).abs() < 1e-12, "{tau}");
        assert!(tau > 0.0);
    }

    /// Closed form: ψ̈ = τ̃ψ from ψ0 with ψ̇0 = 0 has roots −1.382 and −3.618 for
    /// a_ψ1 = a_ψ2 = 5: ψ(t) = ψ0 (r2 e^{r1 t} − r1 e^{r2 t})/(r2 − r1).
    #[test]
    fn closed_loop_matches_closed_form() {
        let (kd, kp, psi0) = (5.0_f64, 5.0_f64, 1.0_f64);
        let disc = (kd * kd - 4.0 * kp).sqrt();
        let (r1, r2) = ((-kd + disc) / 2.0, (-kd - disc) / 2.0);
        assert!((r1 + 1.382).abs() < 1e-3 && (r2 + 3.618).abs() < 1e-3);
        let (mut psi, mut rate, h) = (psi0, 0.0, 1e-4);
        for _ in 0..20_000 {
            // Semi-implicit Euler is enough at this step for 1e-4 agreement over 2 s.
            rate += h * yaw_tau(kd, kp, psi, rate, 0.0, 0.0);
            psi += h * rate;
        }
        let t = 2.0_f64;
        let exact = psi0 * (r2 * (r1 * t).exp() - r1 * (r2 * t).exp()) / (r2 - r1);
        assert!((psi - exact).abs() < 1e-3, "{psi} vs {exact}");
    }

    #[test]
    fn rate_setpoint_is_tracked() {
        // At the heading setpoint turning at the commanded rate: no torque.
        assert!(yaw_tau(5.0, 5.0, 0.2, 0.4, 0.2, 0.4).abs() < 1e-15);
    }
}
