//! Hover position hold of `physical` mode (`docs/model.md`, "Hover position hold"): a cascade
//! as ArduPilot's position controller flies it, in place of the paper's position chains.
//!
//! * position → velocity: v_d = k_p (ξ_d − ξ), |v_d| ≤ `Q_WP_SPEED`;
//! * velocity → acceleration, PI: a_d = k_v (v_d − v) + I, İ = k_i (v_d − v). I is the wind
//!   estimate: the acceleration the air imposes at rest, held in the inertial frame so a turn
//!   does not smear it. Anti-windup: I stops integrating while the tilt is at its limit and is
//!   clamped to `Q_P_VELXY_IMAX`;
//! * acceleration → tilt: in the heading frame ẍ_h = g tan θ, ÿ_h = −g tan φ / cos θ (altitude
//!   law (37) holding f_z = m g / (cos φ cos θ)), with |a_d| ≤ g tan(`Q_ANGLE_MAX`);
//! * tilt → τ̃: angle → rate → angular acceleration, ω_d = clip(−λ e / 2, ±2 rad/s),
//!   τ̃ = clip(2λ (ω_d − ė), ±`HOV_ATT_ACC`), i.e. (s + λ)² with λ = `HOV_ATT_BW` in the linear
//!   region and a bounded slew outside it, plus an integral J̇ = −κ λ² e that carries
//!   the aerodynamic moment of the wind the input change (33) cannot cancel (the controller
//!   knows its ground velocity, not its air velocity).
//!
//! Pure: the state is the two integrators; no clock, no I/O.

use nalgebra::Vector2;

use super::chains::to_heading_frame;

/// Largest angle rate the attitude law asks for, rad/s. A nested law −σa(λ ė) − σb(λ ė + λ² e)
/// with the budget split between a and b slews at only b/λ (0.5 rad/s at λ = 8 rad/s and
/// b = 4 rad/s²): a tilt demand of 0.5 rad then lags by a second and the position loop limit
/// cycles. The rate limit keeps the slew at 2 rad/s.
const ATTITUDE_RATE_MAX_RAD_S: f64 = 2.0;

/// Integral rate κ of the attitude integrator, 1/s: J̇ = −κ λ² e. The loop
/// s³ + 2λ s² + λ² s + κ λ² is stable for κ < 2λ; κ = 1 /s leaves the inner poles near −λ and
/// adds one near −κ.
const ATTITUDE_INTEGRAL_RATE_PER_S: f64 = 1.0;

/// Share of `HOV_ATT_ACC` the attitude integrator may hold, so the law keeps authority for
/// the transients on top of it.
const ATTITUDE_INTEGRAL_SHARE: f64 = 0.5;

/// The parameters of the hold (`Q_*`, `HOV_*` in the vehicle's table), SI units.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct HoverHoldGains {
    /// Which law the position modes fly in `physical` mode.
    pub law: HoverLaw,
    /// k_p, 1/s: `Q_P_POSXY_P`.
    pub pos_p: f64,
    /// k_v, 1/s: `Q_P_VELXY_P`.
    pub vel_p: f64,
    /// k_i, 1/s²: `Q_P_VELXY_I`.
    pub vel_i: f64,
    /// |I| bound, m/s²: `Q_P_VELXY_IMAX` (cm/s² in the table).
    pub vel_imax_m_s2: f64,
    /// |v_d| bound, m/s: `Q_WP_SPEED` (cm/s in the table).
    pub speed_max_m_s: f64,
    /// Tilt limit, rad: `Q_ANGLE_MAX` (centidegrees in the table).
    pub angle_max_rad: f64,
    /// λ, rad/s: `HOV_ATT_BW`.
    pub att_bw_rad_s: f64,
    /// a + b of the attitude law, rad/s²: `HOV_ATT_ACC`.
    pub att_acc_rad_s2: f64,
    /// a + b of the heading law, rad/s²: `HOV_YAW_ACC`.
    pub yaw_acc_rad_s2: f64,
}

/// The law of the position modes in `physical` mode (`HOV_POS_LAW`).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum HoverLaw {
    /// The paper's nested-saturation chains in the heading frame (no integrator).
    PaperChains,
    /// The cascade of this module.
    Cascade,
}

impl Default for HoverHoldGains {
    fn default() -> Self {
        Self {
            law: HoverLaw::Cascade,
            pos_p: 0.6,
            vel_p: 2.0,
            vel_i: 0.4,
            vel_imax_m_s2: 6.0,
            speed_max_m_s: 1.5,
            angle_max_rad: 30f64.to_radians(),
            att_bw_rad_s: 10.0,
            att_acc_rad_s2: 12.0,
            yaw_acc_rad_s2: 24.0,
        }
    }
}

impl HoverHoldGains {}

/// Tilt setpoint of the hold (heading frame): θ_d and φ_d, rad.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct TiltSetpoint {
    /// θ_d (tilts the thrust toward +x of the heading frame).
    pub theta_rad: f64,
    /// φ_d (tilts the thrust toward −y of the heading frame).
    pub phi_rad: f64,
}

/// The hold's state: the wind estimate and the attitude integrators.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct HoverHold {
    /// I of the velocity PI: the acceleration the controller adds to hold against the air,
    /// inertial frame (x, y), m/s².
    wind_accel_m_s2: Vector2<f64>,
    /// J of the attitude laws (θ, φ, ψ), rad/s².
    attitude_integral: [f64; 3],
}

impl HoverHold {
    /// Clears both integrators.
    pub fn reset(&mut self) {
        *self = Self::default();
    }

    /// The wind estimate: the horizontal acceleration the hold adds against the air, inertial
    /// frame (paper, z up), m/s².
    #[must_use]
    pub fn wind_accel_m_s2(&self) -> Vector2<f64> {
        self.wind_accel_m_s2
    }

    /// The outer loops: the tilt that brings the vehicle from `pos` (velocity `vel`) to
    /// `target`, inertial x, y; `psi_rad` the heading; `lift_m_s2` = g + r_z, the specific
    /// thrust's vertical part the altitude law holds. Advances the wind estimate by `dt_s`.
    // The loop's inputs, each a plain quantity; a struct would only rename them.
    #[allow(clippy::too_many_arguments)]
    pub fn tilt_setpoint(
        &mut self,
        k: &HoverHoldGains,
        target: Vector2<f64>,
        pos: Vector2<f64>,
        vel: Vector2<f64>,
        psi_rad: f64,
        lift_m_s2: f64,
        dt_s: f64,
    ) -> TiltSetpoint {
        let lift = lift_m_s2.max(1.0);
        let mut v_d = k.pos_p * (target - pos);
        let speed = v_d.norm();
        if speed > k.speed_max_m_s {
            v_d *= k.speed_max_m_s / speed;
        }
        let v_err = v_d - vel;
        let a_raw = k.vel_p * v_err + self.wind_accel_m_s2;
        let a_max = lift * k.angle_max_rad.tan();
        let a_norm = a_raw.norm();
        let saturated = a_norm > a_max;
        let a = if saturated {
            a_raw * (a_max / a_norm)
        } else {
            a_raw
        };
        // Conditional integration: frozen while the tilt is at its limit, unless the step
        // unwinds it.
        let step = k.vel_i * dt_s * v_err;
        if !saturated || step.dot(&self.wind_accel_m_s2) < 0.0 {
            self.wind_accel_m_s2 += step;
            let n = self.wind_accel_m_s2.norm();
            if n > k.vel_imax_m_s2 {
                self.wind_accel_m_s2 *= k.vel_imax_m_s2 / n;
            }
        }
        let a_h = to_heading_frame(psi_rad, a);
        let theta = (a_h.x / lift).atan();
        let phi = -(a_h.y * theta.cos() / lift).atan();
        TiltSetpoint {
            theta_rad: theta,
            phi_rad: phi,
        }
    }

    /// The inner loops: τ̃θ and τ̃φ driving (θ, φ) to `sp`, rates the Euler rates θ̇, φ̇.
    /// Advances the attitude integrators by `dt_s`.
    #[allow(clippy::too_many_arguments)]
    pub fn attitude_tau(
        &mut self,
        k: &HoverHoldGains,
        sp: TiltSetpoint,
        theta: f64,
        theta_dot: f64,
        phi: f64,
        phi_dot: f64,
        dt_s: f64,
    ) -> (f64, f64) {
        let tau_theta = self.axis(
            0,
            k.att_acc_rad_s2,
            k,
            theta - sp.theta_rad,
            theta_dot,
            dt_s,
        );
        let tau_phi = self.axis(1, k.att_acc_rad_s2, k, phi - sp.phi_rad, phi_dot, dt_s);
        (tau_theta, tau_phi)
    }

    /// The heading law of the hold, τ̃ψ: the attitude law at `HOV_ATT_BW` with the budget
    /// `HOV_YAW_ACC`, for the heading error `psi_err_rad` (wrapped) and the rate ψ̇. The paper's
    /// yaw law (45) is ten times softer than the plate's weathercock moment in a 1.5 m/s wind
    /// along its span (`docs/model.md`).
    pub fn yaw_tau(
        &mut self,
        k: &HoverHoldGains,
        psi_err_rad: f64,
        psi_dot: f64,
        dt_s: f64,
    ) -> f64 {
        self.axis(2, k.yaw_acc_rad_s2, k, psi_err_rad, psi_dot, dt_s)
    }

    /// One axis: ω_d = clip(−λ e / 2, ±[`ATTITUDE_RATE_MAX_RAD_S`]),
    /// τ̃ = clip(2λ (ω_d − ė), ±`budget`) plus its integrator J, bounded by
    /// [`ATTITUDE_INTEGRAL_SHARE`] of the budget.
    fn axis(
        &mut self,
        i: usize,
        budget: f64,
        k: &HoverHoldGains,
        e: f64,
        e_dot: f64,
        dt_s: f64,
    ) -> f64 {
        let l = k.att_bw_rad_s;
        let j_max = ATTITUDE_INTEGRAL_SHARE * budget;
        let j = &mut self.attitude_integral[i];
        *j = (*j - ATTITUDE_INTEGRAL_RATE_PER_S * l * l * e * dt_s).clamp(-j_max, j_max);
        let rate_target = (-0.5 * l * e).clamp(-ATTITUDE_RATE_MAX_RAD_S, ATTITUDE_RATE_MAX_RAD_S);
        (2.0 * l * (rate_target - e_dot)).clamp(-budget, budget) + *j
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const G: f64 = 9.8;

    #[test]
    fn leans_toward_the_target_and_limits_the_tilt() {
        let k = HoverHoldGains::default();
        let mut h = HoverHold::default();
        // Target 100 m ahead (+x) at ψ = 0, flying away from it at 5 m/s: pitch forward, at
        // most Q_ANGLE_MAX.
        let sp = h.tilt_setpoint(
            &k,
            Vector2::new(100.0, 0.0),
            Vector2::zeros(),
            Vector2::new(-5.0, 0.0),
            0.0,
            G,
            0.01,
        );
        assert!((sp.theta_rad - k.angle_max_rad).abs() < 1e-12, "{sp:?}");
        assert_eq!(sp.phi_rad, 0.0);
        // Saturated: the wind estimate did not wind up.
        assert_eq!(h.wind_accel_m_s2(), Vector2::zeros());
        // Target to the left (+y): ÿ = −g tan φ, so roll negative.
        let sp = h.tilt_setpoint(
            &k,
            Vector2::new(0.0, 0.1),
            Vector2::zeros(),
            Vector2::zeros(),
            0.0,
            G,
            0.01,
        );
        assert!(sp.phi_rad < 0.0 && sp.theta_rad.abs() < 1e-12, "{sp:?}");
        // The same target with the heading turned 90° left: it is now ahead.
        let mut h = HoverHold::default();
        let sp = h.tilt_setpoint(
            &k,
            Vector2::new(0.0, 0.1),
            Vector2::zeros(),
            Vector2::zeros(),
            std::f64::consts::FRAC_PI_2,
            G,
            0.01,
        );
        assert!(sp.theta_rad > 0.0 && sp.phi_rad.abs() < 1e-12, "{sp:?}");
    }

    #[test]
    fn a_steady_push_is_learned_and_bounded() {
        let k = HoverHoldGains::default();
        // Held 0.2 m/s short of the setpoint's demand for `steps` of 10 ms: the wind estimate
        // it has learned by then.
        let learned = |k: &HoverHoldGains, steps: usize| {
            let mut h = HoverHold::default();
            for _ in 0..steps {
                h.tilt_setpoint(
                    k,
                    Vector2::zeros(),
                    Vector2::zeros(),
                    Vector2::new(-0.2, 0.0),
                    0.0,
                    G,
                    0.01,
                );
            }
            h.wind_accel_m_s2()
        };
        // For a long time: I grows toward it and stops where the tilt reaches Q_ANGLE_MAX (no
        // wind-up beyond the limit).
        let w = learned(&k, 100_000);
        let a_max = G * k.angle_max_rad.tan();
        assert!(
            w.x > 0.0 && (w.x + k.vel_p * 0.2 - a_max).abs() < 0.01,
            "{w}"
        );
        // With a lower IMAX it stops there.
        let k = HoverHoldGains {
            vel_imax_m_s2: 1.0,
            ..k
        };
        assert!((learned(&k, 10_000).norm() - 1.0).abs() < 1e-9);
    }

    #[test]
    fn attitude_law_is_bounded_and_opposes_the_error() {
        let k = HoverHoldGains::default();
        let mut h = HoverHold::default();
        let sp = TiltSetpoint::default();
        let (t, p) = h.attitude_tau(&k, sp, 0.3, 0.0, -0.3, 0.0, 0.01);
        assert!(t < 0.0 && p > 0.0);
        let (t, _) = h.attitude_tau(&k, sp, 10.0, 50.0, 0.0, 0.0, 0.01);
        assert!(t.abs() <= 1.5 * k.att_acc_rad_s2 + 1e-9, "{t}");
        let y = h.yaw_tau(&k, 0.2, 0.0, 0.01);
        assert!(y < 0.0 && y.abs() <= 1.5 * k.yaw_acc_rad_s2 + 1e-9, "{y}");
    }
}
