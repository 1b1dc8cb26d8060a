//! The paper's control law as onboard firmware (`PHYSICS.md` §3): nested saturation chains for
//! the lateral (y–φ) and longitudinal (x–θ) dynamics, the altitude law (37), the yaw law (45),
//! the input change (33), and the mixer from forces and torques to PWM (§5).
//!
//! The controller is a plain struct: no I/O, no clock, no allocation. The vehicle feeds it an
//! estimate and a setpoint and gets actuator commands back.
//!
//! One tick ([`Controller::update`]), each step a method named for it:
//! 1. sanitise the input (NaN → 0, everything clamped to generous physical ranges) so that every
//!    output is finite for any input (`Tick::sanitise`), then mode entry (`enter_mode`);
//! 2. η̇ = W_n⁻¹ Ω ([I17]); the three virtual inputs Γ̃ = (τ̃ψ, τ̃θ, τ̃φ) [I5] from the chains
//!    (`chains`), the attitude-hold laws (pilot modes) or the hover hold (`tilt_torques`), and
//!    the yaw law (`yaw`, `yaw_torque`);
//! 3. f_z from (37) [I6] (`altitude`) or the pilot throttle, f_x from (43) in `paper` mode
//!    (`thrust`);
//! 4. Γc from the input change (33) solved with the mixer's rotor speeds [I19] (`input_change`);
//! 5. actuator commands and PWM (`mixer`, §5).
//!
//! Flight modes: QLOITER is the paper's controller to `setpoint_m`; QHOVER holds altitude at
//! `HOVER_ALT` and the pilot's attitude; QSTABILIZE holds the pilot's attitude with pilot
//! throttle; QLAND holds the horizontal position where it began and descends at `land_speed`.
//! In `physical` mode the position chains run in the heading frame (§0).

pub mod altitude;
pub mod chains;
pub mod forward;
pub mod forward_gains;
pub mod input_change;
pub mod mixer;
pub mod position;
pub mod saturation;
pub mod tecs;
pub mod yaw;

#[cfg(test)]
mod closed_loop_tests;
#[cfg(test)]
mod tests;

use nalgebra::{Vector2, Vector3};

use crate::model::airframe::{Airframe, ModelMode};
use crate::model::frames::{Euler, wrap_pi};
use crate::model::mode::FlightMode;
use crate::model::signals::{ActuatorCommand, CRASH_TILT_RAD, PilotInput, PwmOutputs};
use position::{HoverHold, HoverHoldGains, HoverLaw};

/// Full-stick tilt setpoint (φ_d, θ_d) in the attitude-hold modes, rad. Equal to c + d of the
/// default levels, so a full stick stays where the paper's x loop is well behaved (§0).
pub const PILOT_TILT_MAX_RAD: f64 = 0.35;

/// Full-stick yaw rate in the attitude-hold modes, rad/s.
pub const PILOT_YAW_RATE_MAX_RAD_S: f64 = 1.0;

/// How far the stick-driven heading target may lead the actual heading, rad (no wind-up when the
/// vehicle cannot follow).
pub const YAW_LEASH_RAD: f64 = 0.5;

/// Cancel the modelled aerodynamic moment in the input change (`physical` mode).
const CANCEL_AERO_MOMENT: bool = true;

/// Time scale λ of the attitude-hold law τ̃ = −σa(λ ė) − σb(λ ė + λ² e) in the pilot modes,
/// rad/s: both poles at −λ. Twice the chains' inner poles (−1): crisper under the pilot, still
/// well below the motor (0.04 s) and servo (0.02 s) lags.
pub const ATTITUDE_BANDWIDTH_RAD_S: f64 = 2.0;

/// Sanitising bounds: beyond these the input is not physical (the gyros saturate at 2.6 rad/s),
/// and clamping keeps every product in (33) far from overflow.
const POS_LIMIT_M: f64 = 1.0e4;
const VEL_LIMIT_M_S: f64 = 1.0e3;
const RATE_LIMIT_RAD_S: f64 = 50.0;
const ROTOR_SPEED_LIMIT_RAD_S: f64 = 1.0e4;
const DT_LIMIT_S: f64 = 1.0;
/// |θ| used in W_n, W_n⁻¹ and Ẇ_n: keeps 1/cos θ ≤ 14 (the Euler singularity is at π/2).
const KINEMATIC_THETA_LIMIT_RAD: f64 = 1.5;

/// NaN → 0, then clamp to ±`limit`.
fn clean(v: f64, limit: f64) -> f64 {
    if v.is_nan() {
        0.0
    } else {
        v.clamp(-limit, limit)
    }
}

fn clean_vec(v: &Vector3<f64>, limit: f64) -> Vector3<f64> {
    v.map(|x| clean(x, limit))
}

/// Saturation levels (a, b, c, d) of one nested-saturation chain, in rad/s² (bounds on τ̃).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SaturationLevels {
    /// Outermost level a: bound on the rate term.
    pub a: f64,
    /// Level b.
    pub b: f64,
    /// Level c.
    pub c: f64,
    /// Level d: bound on the position term.
    pub d: f64,
}

/// Relative margin by which a saturation level must exceed the sum it is compared with: a few
/// float32 rounding steps (2⁻²³ ≈ 1.2e-7).
pub const LEVEL_MARGIN: f64 = 1e-6;

impl SaturationLevels {
    /// The defaults of `PHYSICS.md` §0.
    pub const DEFAULT: Self = Self {
        a: 1.2,
        b: 0.6,
        c: 0.22,
        d: 0.18,
    };

    /// Checks the hypotheses of the convergence proof: a > b + c + d, b > c + d, c > d > 0,
    /// all finite.
    ///
    /// # Errors
    /// [`GainError::SaturationConditions`] naming the violated condition.
    pub fn validate(&self, chain: &'static str) -> Result<(), GainError> {
        let Self { a, b, c, d } = *self;
        let fail = |condition: &'static str| {
            Err(GainError::SaturationConditions {
                chain,
                condition,
                a,
                b,
                c,
                d,
            })
        };
        if ![a, b, c, d].iter().all(|v| v.is_finite()) {
            return fail("all levels finite");
        }
        // The levels travel as float32 parameters, so a sum that equals a level in exact
        // arithmetic can land a rounding step either side of it. "Greater" therefore means
        // greater by more than float32 rounding: b = c + d is refused however it was typed.
        let greater = |lhs: f64, rhs: f64| lhs > rhs + LEVEL_MARGIN * rhs.abs().max(1.0);
        if !greater(d, 0.0) {
            return fail("d > 0");
        }
        if !greater(c, d) {
            return fail("c > d");
        }
        if !greater(b, c + d) {
            return fail("b > c + d");
        }
        if !greater(a, b + c + d) {
            return fail("a > b + c + d");
        }
        Ok(())
    }
}

/// Every tunable of the control law (the onboard parameters of `PHYSICS.md` §0).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Gains {
    /// Lateral chain (y–φ): `LAT_SAT_A` … `LAT_SAT_D`.
    pub lateral: SaturationLevels,
    /// Longitudinal chain (x–θ): `LON_SAT_A` … `LON_SAT_D`.
    pub longitudinal: SaturationLevels,
    /// a_z1 of (37), multiplies ż: `ALT_KD`, 1/s.
    pub alt_kd: f64,
    /// a_z2 of (37), multiplies z − z_d: `ALT_KP`, 1/s².
    pub alt_kp: f64,
    /// a_ψ1 of (45), multiplies ψ̇: `YAW_KD`, 1/s.
    pub yaw_kd: f64,
    /// a_ψ2 of (45), multiplies ψ: `YAW_KP`, 1/s².
    pub yaw_kp: f64,
    /// Altitude setpoint z_d in QHOVER and QLOITER: `HOVER_ALT`, m (z up).
    pub hover_alt_m: f64,
    /// Descent speed in QLAND, m/s.
    pub land_speed_m_s: f64,
    /// Fastest climb of the altitude hold in `physical` mode: `Q_PILOT_SPEED_UP`, m/s.
    pub climb_max_m_s: f64,
    /// Fastest descent of the altitude hold in `physical` mode: `Q_PILOT_SPEED_DN` (0 = the
    /// climb's), m/s.
    pub sink_max_m_s: f64,
    /// Forward flight and the transitions (`forward_gains`).
    pub forward: forward_gains::ForwardGains,
    /// The position modes' hold in `physical` mode (`position`).
    pub hover: HoverHoldGains,
}

impl Default for Gains {
    fn default() -> Self {
        Self {
            lateral: SaturationLevels::DEFAULT,
            longitudinal: SaturationLevels::DEFAULT,
            alt_kd: 2.0,
            alt_kp: 5.0,
            yaw_kd: 5.0,
            yaw_kp: 5.0,
            hover_alt_m: 1.0,
            land_speed_m_s: 0.5,
            climb_max_m_s: 2.5,
            sink_max_m_s: 2.5,
            forward: forward_gains::ForwardGains::default(),
            hover: HoverHoldGains::default(),
        }
    }
}

/// The first of `gains` that is not a positive, finite number, as the error naming it.
fn all_positive(gains: &[(&'static str, f64)]) -> Result<(), GainError> {
    match gains.iter().find(|(_, v)| !(v.is_finite() && *v > 0.0)) {
        Some(&(name, value)) => Err(GainError::NotPositive { name, value }),
        None => Ok(()),
    }
}

impl Gains {
    /// Checks every constraint of the set: the saturation conditions of both chains and positive,
    /// finite linear gains.
    ///
    /// # Errors
    /// The first violated constraint.
    pub fn validate(&self) -> Result<(), GainError> {
        self.lateral.validate("LAT_SAT")?;
        self.longitudinal.validate("LON_SAT")?;
        all_positive(&[
            ("ALT_KD", self.alt_kd),
            ("ALT_KP", self.alt_kp),
            ("YAW_KD", self.yaw_kd),
            ("YAW_KP", self.yaw_kp),
            ("LAND_SPEED", self.land_speed_m_s),
            ("Q_PILOT_SPEED_UP", self.climb_max_m_s),
            ("Q_PILOT_SPEED_DN", self.sink_max_m_s),
            ("HOVER_ALT", self.hover_alt_m),
            ("Q_P_POSXY_P", self.hover.pos_p),
            ("Q_P_VELXY_P", self.hover.vel_p),
            ("Q_WP_SPEED", self.hover.speed_max_m_s),
            ("Q_ANGLE_MAX", self.hover.angle_max_rad),
            ("HOV_ATT_BW", self.hover.att_bw_rad_s),
            ("HOV_ATT_ACC", self.hover.att_acc_rad_s2),
            ("HOV_YAW_ACC", self.hover.yaw_acc_rad_s2),
        ])?;
        self.validate_hover()?;
        // The twin flies one airframe (Table I): the stall speed is checked against it.
        self.forward.validate(&Airframe::default())
    }

    /// The hold's gains (their signs are checked with the others): a tilt limit short of the
    /// crash tilt, and the cascade's cross-checks (`docs/model.md`, "Hover position hold").
    fn validate_hover(&self) -> Result<(), GainError> {
        let h = &self.hover;
        for (name, v) in [
            ("Q_P_VELXY_I", h.vel_i),
            ("Q_P_VELXY_IMAX", h.vel_imax_m_s2),
        ] {
            if !(v.is_finite() && v >= 0.0) {
                return Err(GainError::NotPositive { name, value: v });
            }
        }
        // s³ + k_v s² + (k_i + k_v k_p) s + k_i k_p (velocity PI under a position P, the
        // attitude taken as instantaneous) is stable by Routh when k_v (k_i + k_v k_p) > k_i k_p,
        // which a velocity loop at least as fast as the position loop guarantees.
        if h.vel_p < h.pos_p {
            return Err(GainError::CrossCheck("Q_P_VELXY_P >= Q_P_POSXY_P"));
        }
        // The velocity loop must be well inside the attitude loop that serves it: with
        // Q_P_VELXY_P = 3 /s under HOV_ATT_BW = 5 rad/s the lateral loop oscillated.
        if 2.0 * h.vel_p > h.att_bw_rad_s {
            return Err(GainError::CrossCheck("Q_P_VELXY_P <= HOV_ATT_BW / 2"));
        }
        if h.angle_max_rad >= CRASH_TILT_RAD {
            return Err(GainError::CrossCheck("Q_ANGLE_MAX < crash tilt 60 deg"));
        }
        Ok(())
    }
}

/// A gain set the controller refuses.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum GainError {
    /// The nested-saturation hypotheses a > b + c + d, b > c + d, c > d > 0 do not hold.
    #[error("{chain} levels a={a}, b={b}, c={c}, d={d} break the saturation condition {condition}")]
    SaturationConditions {
        /// `LAT_SAT` or `LON_SAT`.
        chain: &'static str,
        /// The violated inequality.
        condition: &'static str,
        /// Level a.
        a: f64,
        /// Level b.
        b: f64,
        /// Level c.
        c: f64,
        /// Level d.
        d: f64,
    },
    /// A forward-flight parameter set breaks one of its cross-checks.
    #[error("forward-flight parameters break the rule: {rule}")]
    Forward {
        /// The broken rule.
        rule: &'static str,
    },
    /// A cross-check between gains of the hover hold fails.
    #[error("the hover hold needs {0}")]
    CrossCheck(&'static str),
    /// A gain that must be positive and finite is not.
    #[error("{name} must be positive and finite, got {value}")]
    NotPositive {
        /// Parameter name.
        name: &'static str,
        /// Offending value.
        value: f64,
    },
}

/// What the controller sees each control tick (paper frame, z up).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct ControlInput {
    /// Control period, s.
    pub dt_s: f64,
    /// Active flight mode.
    pub mode: FlightMode,
    /// Attitude estimate η = (ψ, θ, φ).
    pub euler: Euler,
    /// Body rates Ω = (p, q, r), rad/s.
    pub omega_body_rad_s: Vector3<f64>,
    /// Position, m (from the external position sensor, or truth in `paper` mode).
    pub pos_m: Vector3<f64>,
    /// Inertial velocity, m/s.
    pub vel_m_s: Vector3<f64>,
    /// Position setpoint, m (z is used by QLOITER; QHOVER uses `HOVER_ALT`).
    pub setpoint_m: Vector3<f64>,
    /// Heading setpoint ψ_d, rad.
    pub yaw_setpoint_rad: f64,
    /// Current rotor speeds (for Γg and Γq in the input change), rad/s.
    pub rotor_speed_rad_s: [f64; 2],
    /// Pilot sticks.
    pub pilot: PilotInput,
}

/// Everything one control tick produces.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct ControlOutput {
    /// Γ̃ stacked as (τ̃ψ, τ̃θ, τ̃φ), rad/s² ([I5]).
    pub tau_tilde: Vector3<f64>,
    /// Γc = (Γx, Γy, Γz), N·m, after the input change (33).
    pub torque_body_nm: Vector3<f64>,
    /// Total thrust f_z, N.
    pub fz_n: f64,
    /// f_x of (43), N (`paper` mode only; 0 in `physical`).
    pub fx_n: f64,
    /// Physical actuator commands from the mixer.
    pub actuators: ActuatorCommand,
    /// PWM outputs, µs, each within 1000–2000.
    pub pwm_us: PwmOutputs,
}

/// The onboard controller.
#[derive(Debug, Clone)]
pub struct Controller {
    airframe: Airframe,
    model: ModelMode,
    /// Mode of the previous tick (`None` after construction or reset): mode entry is detected
    /// against it.
    prev_mode: Option<FlightMode>,
    /// QLAND: the horizontal position held during the descent, captured on entry.
    land_hold_xy_m: Option<Vector2<f64>>,
    /// Pilot modes: heading offset integrated from the yaw stick, added to the input's
    /// `yaw_setpoint_rad`. Cleared on every mode change.
    yaw_offset_rad: f64,
    /// ψ_d used on the last tick.
    yaw_target_rad: f64,
    /// PWM rounding error carried to the next tick, µs ([`mixer::pwm_us_dithered`]).
    pwm_residual_us: [f64; 5],
    /// The position modes' hold in `physical` mode: wind estimate and attitude integrators.
    hold: HoverHold,
}

impl Controller {
    /// A controller for this airframe and model mode.
    #[must_use]
    pub fn new(airframe: Airframe, model: ModelMode) -> Self {
        Self {
            airframe,
            model,
            prev_mode: None,
            land_hold_xy_m: None,
            yaw_offset_rad: 0.0,
            yaw_target_rad: 0.0,
            pwm_residual_us: [0.0; 5],
            hold: HoverHold::default(),
        }
    }

    /// Clears any internal state (filters, mode transitions).
    pub fn reset(&mut self) {
        self.prev_mode = None;
        self.land_hold_xy_m = None;
        self.yaw_offset_rad = 0.0;
        self.yaw_target_rad = 0.0;
        self.pwm_residual_us = [0.0; 5];
        self.hold.reset();
    }

    /// The hover hold's wind estimate: the horizontal acceleration it adds against the air,
    /// paper frame, m/s² (zero unless `physical` mode flies the cascade).
    #[must_use]
    pub fn wind_accel_estimate_m_s2(&self) -> Vector2<f64> {
        self.hold.wind_accel_m_s2()
    }

    /// The model mode this controller was built for.
    #[must_use]
    pub fn model(&self) -> ModelMode {
        self.model
    }

    /// The horizontal position QLAND is holding (paper frame), if QLAND is active.
    #[must_use]
    pub fn land_hold_xy_m(&self) -> Option<Vector2<f64>> {
        self.land_hold_xy_m
    }

    /// The heading setpoint ψ_d of the last tick (the input's setpoint plus the yaw-stick offset
    /// in QSTABILIZE/QHOVER), rad.
    #[must_use]
    pub fn yaw_target_rad(&self) -> f64 {
        self.yaw_target_rad
    }

    /// One control tick.
    ///
    /// The yaw stick is integrated here (QSTABILIZE/QHOVER): the caller should keep
    /// `yaw_setpoint_rad` fixed (e.g. the heading at mode entry) rather than integrate the stick
    /// itself.
    #[must_use]
    pub fn update(&mut self, input: &ControlInput, gains: &Gains) -> ControlOutput {
        // 1. Sanitise.
        let t = Tick::sanitise(input);
        self.enter_mode(&t);
        // 2. Euler rates (ψ̇, θ̇, φ̇) = W_n⁻¹ Ω.
        let eta_dot = t.kin.rates_from_body(&t.omega);
        // The autonomous modes fly QLOITER's law to the setpoint their navigator chose (the
        // vehicle passes the law itself as the mode; this branch keeps a direct caller safe).
        // `physical` mode flies its position modes on the hover hold (`position`).
        let pilot_attitude = t.mode.pilot_flies_attitude();
        let hold_flies = self.model == ModelMode::Physical
            && gains.hover.law == HoverLaw::Cascade
            && !pilot_attitude;
        let (tau_theta, tau_phi) =
            self.tilt_torques(&t, &eta_dot, gains, pilot_attitude, hold_flies);
        let tau_psi = self.yaw_torque(&t, eta_dot[0], gains, pilot_attitude, hold_flies);
        let tau_tilde = Vector3::new(tau_psi, tau_theta, tau_phi);
        // 3. Thrust.
        let (fz, fx) = self.thrust(&t, gains);
        // 4. Input change (33) with the rotor-speed loop [I19].
        let torque = self.input_change(&t, &eta_dot, &tau_tilde, fz);
        // 5. Mixer and PWM (§5).
        let actuators = mixer::mix(&self.airframe, self.model, fz, &torque);
        let pwm_us = mixer::pwm_us_dithered(&self.airframe, &actuators, &mut self.pwm_residual_us);
        ControlOutput {
            tau_tilde,
            torque_body_nm: torque,
            fz_n: fz,
            fx_n: fx,
            actuators,
            pwm_us,
        }
    }

    /// Mode entry: the yaw-stick offset cleared, QLAND's hold point captured.
    fn enter_mode(&mut self, t: &Tick) {
        let mode = t.mode;
        if self.prev_mode != Some(mode) {
            self.yaw_offset_rad = 0.0;
            self.land_hold_xy_m = (mode == FlightMode::QLand).then(|| t.pos.xy());
        }
        self.prev_mode = Some(mode);
    }

    /// The tilt virtual inputs (τ̃θ, τ̃φ): the attitude hold under the pilot, else the hover
    /// hold (`physical`) or the nested saturation chains towards the position target.
    fn tilt_torques(
        &mut self,
        t: &Tick,
        eta_dot: &Vector3<f64>,
        gains: &Gains,
        pilot_attitude: bool,
        hold_flies: bool,
    ) -> (f64, f64) {
        let (model, g) = (self.model, self.airframe.gravity_m_s2);
        let (euler, pos, vel) = (&t.euler, &t.pos, &t.vel);
        let (theta_dot, phi_dot) = (eta_dot[1], eta_dot[2]);
        if pilot_attitude {
            return (
                chains::attitude_hold_tau(
                    &gains.longitudinal,
                    ATTITUDE_BANDWIDTH_RAD_S,
                    euler.theta,
                    PILOT_TILT_MAX_RAD * t.pilot.pitch,
                    theta_dot,
                ),
                chains::attitude_hold_tau(
                    &gains.lateral,
                    ATTITUDE_BANDWIDTH_RAD_S,
                    euler.phi,
                    PILOT_TILT_MAX_RAD * t.pilot.roll,
                    phi_dot,
                ),
            );
        }
        let target = match (t.mode, self.land_hold_xy_m) {
            (FlightMode::QLand, Some(hold)) => hold,
            _ => t.setpoint.xy(),
        };
        if hold_flies {
            let sp = self.hold.tilt_setpoint(
                &gains.hover,
                target,
                pos.xy(),
                vel.xy(),
                euler.psi,
                g,
                t.dt,
            );
            return self.hold.attitude_tau(
                &gains.hover,
                sp,
                euler.theta,
                theta_dot,
                euler.phi,
                phi_dot,
                t.dt,
            );
        }
        let mut err = pos.xy() - target;
        let mut v = vel.xy();
        if model != ModelMode::Paper {
            err = chains::to_heading_frame(euler.psi, err);
            v = chains::to_heading_frame(euler.psi, v);
        }
        (
            chains::longitudinal_tau(
                &gains.longitudinal,
                model,
                g,
                err.x,
                v.x,
                euler.theta,
                theta_dot,
            ),
            chains::lateral_tau(&gains.lateral, g, err.y, v.y, euler.phi, phi_dot),
        )
    }

    /// The yaw virtual input τ̃ψ (45): the pilot modes integrate the stick into the heading
    /// target, on a leash.
    fn yaw_torque(
        &mut self,
        t: &Tick,
        psi_dot: f64,
        gains: &Gains,
        pilot_attitude: bool,
        hold_flies: bool,
    ) -> f64 {
        let (euler, dt, yaw_setpoint) = (&t.euler, t.dt, t.yaw_setpoint);
        let (psi_target, psi_rate_target) = if pilot_attitude {
            let rate = PILOT_YAW_RATE_MAX_RAD_S * t.pilot.yaw;
            let offset = wrap_pi(self.yaw_offset_rad + rate * dt);
            let lead =
                wrap_pi(yaw_setpoint + offset - euler.psi).clamp(-YAW_LEASH_RAD, YAW_LEASH_RAD);
            let target = wrap_pi(euler.psi + lead);
            self.yaw_offset_rad = wrap_pi(target - yaw_setpoint);
            (target, rate)
        } else {
            (yaw_setpoint, 0.0)
        };
        self.yaw_target_rad = psi_target;
        if hold_flies {
            self.hold
                .yaw_tau(&gains.hover, wrap_pi(euler.psi - psi_target), psi_dot, dt)
        } else {
            yaw::yaw_tau(
                gains.yaw_kd,
                gains.yaw_kp,
                euler.psi,
                psi_dot,
                psi_target,
                psi_rate_target,
            )
        }
    }

    /// The thrust f_z (altitude law (37), QLAND's descent or the pilot's throttle) and the f_x
    /// of (43) in `paper` mode, N.
    fn thrust(&self, t: &Tick, gains: &Gains) -> (f64, f64) {
        let a = &self.airframe;
        let (m, g) = (a.mass_kg, a.gravity_m_s2);
        let model = self.model;
        let (euler, pos, vel) = (&t.euler, &t.pos, &t.vel);
        let fz_max = 2.0 * a.k_thrust_n_per_rad2_s2 * a.rotor_speed_max_rad_s.powi(2);
        // The paper's altitude law (37); in `physical` mode with the climb and descent speeds
        // bounded, so a far altitude is flown to at a speed rather than with an acceleration.
        let hold_altitude = |z_setpoint: f64| match model {
            ModelMode::Paper => {
                altitude::altitude_accel_m_s2(gains.alt_kd, gains.alt_kp, pos.z, vel.z, z_setpoint)
            }
            ModelMode::Physical => altitude::altitude_accel_bounded_m_s2(
                gains.alt_kd,
                gains.alt_kp,
                pos.z,
                vel.z,
                z_setpoint,
                gains.climb_max_m_s,
                gains.sink_max_m_s,
            ),
        };
        let r_z = match t.mode {
            FlightMode::QLoiter
            | FlightMode::Guided
            | FlightMode::Auto
            | FlightMode::QRtl
            | FlightMode::Rtl
            | FlightMode::Fbwa
            | FlightMode::Cruise => Some(hold_altitude(t.setpoint.z)),
            FlightMode::QHover => Some(hold_altitude(gains.hover_alt_m)),
            FlightMode::QLand => Some(altitude::land_accel_m_s2(
                gains.alt_kd,
                vel.z,
                gains.land_speed_m_s,
            )),
            FlightMode::QStabilize => None,
        };
        let fz_raw = match r_z {
            Some(rz) => altitude::thrust_n(m, g, rz, euler.phi, euler.theta),
            // Throttle 0..1 spans the full thrust range: hover at mg / fz_max ≈ 0.46.
            None => t.pilot.throttle * fz_max,
        };
        let fz = match model {
            ModelMode::Paper => fz_raw,
            ModelMode::Physical => fz_raw.clamp(0.0, fz_max),
        };
        let fx = match model {
            ModelMode::Paper => chains::paper_fx_n(m, g, euler.theta),
            ModelMode::Physical => 0.0,
        };
        (fz, fx)
    }

    /// The body torque Γc from the input change (33) with the rotor-speed loop [I19], less the
    /// modelled aerodynamic moment in `physical` mode, N·m.
    fn input_change(
        &self,
        t: &Tick,
        eta_dot: &Vector3<f64>,
        tau_tilde: &Vector3<f64>,
        fz: f64,
    ) -> Vector3<f64> {
        let a = &self.airframe;
        let model = self.model;
        let (mut torque, _) = input_change::solve_input_change(
            a,
            model,
            &t.kin,
            &t.omega,
            eta_dot,
            tau_tilde,
            fz,
            t.rotor_start,
        );
        if model == ModelMode::Physical && CANCEL_AERO_MOMENT {
            // The airframe's aerodynamic moment is cancelled like Γg and Γq in (33), from the
            // model and the velocity the controller knows (the wind is unknown to it).
            let v_body = t.kin.rotation_body_to_inertial().tr_mul(&t.vel);
            torque -= crate::model::plant::aero::loads(a, &v_body, &t.rotor_start).torque_body_nm;
        }
        torque
    }
}

/// One tick's input, sanitised: NaN → 0 and everything clamped to generous physical ranges.
struct Tick {
    mode: FlightMode,
    euler: Euler,
    /// `euler` with θ kept off the kinematic singularity, for the rate and frame conversions.
    kin: Euler,
    omega: Vector3<f64>,
    pos: Vector3<f64>,
    vel: Vector3<f64>,
    setpoint: Vector3<f64>,
    dt: f64,
    rotor_start: [f64; 2],
    pilot: PilotInput,
    yaw_setpoint: f64,
}

impl Tick {
    fn sanitise(input: &ControlInput) -> Self {
        let euler = Euler::new(
            wrap_pi(clean(input.euler.psi, 1e6)),
            wrap_pi(clean(input.euler.theta, 1e6)),
            wrap_pi(clean(input.euler.phi, 1e6)),
        );
        let kin = Euler {
            theta: euler
                .theta
                .clamp(-KINEMATIC_THETA_LIMIT_RAD, KINEMATIC_THETA_LIMIT_RAD),
            ..euler
        };
        Self {
            mode: input.mode,
            euler,
            kin,
            omega: clean_vec(&input.omega_body_rad_s, RATE_LIMIT_RAD_S),
            pos: clean_vec(&input.pos_m, POS_LIMIT_M),
            vel: clean_vec(&input.vel_m_s, VEL_LIMIT_M_S),
            setpoint: clean_vec(&input.setpoint_m, POS_LIMIT_M),
            dt: clean(input.dt_s, DT_LIMIT_S).max(0.0),
            rotor_start: input
                .rotor_speed_rad_s
                .map(|w| clean(w, ROTOR_SPEED_LIMIT_RAD_S).max(0.0)),
            pilot: PilotInput {
                throttle: clean(input.pilot.throttle, 1.0).max(0.0),
                roll: clean(input.pilot.roll, 1.0),
                pitch: clean(input.pilot.pitch, 1.0),
                yaw: clean(input.pilot.yaw, 1.0),
            },
            yaw_setpoint: wrap_pi(clean(input.yaw_setpoint_rad, 1e6)),
        }
    }
}
