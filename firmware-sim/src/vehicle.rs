//! `Vehicle::step(dt)`: one physics step of the whole twin — sensors → estimator → controller →
//! actuators → plant — synchronous, deterministic (seeded RNG, no wall clock) and free of
//! allocation. The MAVLink endpoint and the offline `simulate` command both drive it.

use nalgebra::Vector3;

use crate::airframe::{Airframe, ModelMode};
use crate::control::{ControlOutput, Gains, GainError, PwmOutputs};
use crate::frames::Euler;
use crate::mode::FlightMode;

/// The physics step: the plant is integrated at 1 kHz.
pub const PHYSICS_DT_S: f64 = 0.001;

/// Rigid-body state in the paper's frames (z up). See `plant` for the equations.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct InitialState {
    /// Position ξ = (x, y, z), m.
    pub pos_m: Vector3<f64>,
    /// Attitude η = (ψ, θ, φ).
    pub euler: Euler,
}

/// How to build a vehicle.
#[derive(Debug, Clone, PartialEq)]
pub struct VehicleConfig {
    /// Physical constants.
    pub airframe: Airframe,
    /// `paper` or `physical` (`PHYSICS.md` §0).
    pub model: ModelMode,
    /// Noise, bias and quantisation off when true.
    pub ideal_sensors: bool,
    /// Seed of every random draw.
    pub seed: u64,
    /// Control loop rate, Hz (100 by default).
    pub control_rate_hz: f64,
    /// Start state (velocities and rates are zero).
    pub initial: InitialState,
    /// Controller gains and levels.
    pub gains: Gains,
    /// Flight mode at start.
    pub mode: FlightMode,
    /// Start armed (the offline `simulate` command flies from t = 0).
    pub armed: bool,
}

impl Default for VehicleConfig {
    fn default() -> Self {
        Self {
            airframe: Airframe::default(),
            model: ModelMode::Physical,
            ideal_sensors: false,
            seed: 1,
            control_rate_hz: 100.0,
            initial: InitialState::default(),
            gains: Gains::default(),
            mode: FlightMode::QStabilize,
            armed: false,
        }
    }
}

/// System state as the heartbeat reports it.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum SystemState {
    /// Gyro calibration at rest after power-up.
    #[default]
    Calibrating,
    /// Ready, disarmed.
    Standby,
    /// Armed.
    Active,
    /// A failsafe is active.
    Critical,
    /// Crashed (hit the ground hard or tipped over).
    Emergency,
}

/// Why an arm or disarm request was refused.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum ArmError {
    /// Pre-arm check failed.
    #[error("pre-arm check failed: {0}")]
    PreArm(&'static str),
    /// Disarming in flight needs force.
    #[error("refusing to disarm in flight (use force)")]
    InFlight,
}

/// Snapshot of everything the twin can report.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Telemetry {
    /// Simulation time, µs since power-up.
    pub t_us: u64,
    /// True position (paper frame, z up), m.
    pub pos_m: Vector3<f64>,
    /// True inertial velocity (paper frame), m/s.
    pub vel_m_s: Vector3<f64>,
    /// True attitude.
    pub euler: Euler,
    /// True body rates (p, q, r), rad/s.
    pub omega_body_rad_s: Vector3<f64>,
    /// Estimated attitude (what the firmware flies on).
    pub euler_est: Euler,
    /// Estimated body rates, rad/s (gyro after bias removal).
    pub omega_est_rad_s: Vector3<f64>,
    /// Gyro readings in rad/s (x, y, z), after the ADC.
    pub gyro_rad_s: [f64; 3],
    /// Accelerometer readings in m/s² (x, y; the ADXL203 has two axes), after the ADC.
    pub accel_m_s2: [f64; 2],
    /// Raw 12-bit ADC counts: gyro x, y, z, accel x, y.
    pub adc_counts: [u16; 5],
    /// RC receiver pulse widths, µs (channels 1–8).
    pub rc_us: [u16; 8],
    /// Actual rotor speeds, rad/s.
    pub rotor_speed_rad_s: [f64; 2],
    /// Last control tick's output (τ̃, Γc, f_z, PWM).
    pub control: ControlOutput,
    /// PWM outputs, µs.
    pub pwm_us: PwmOutputs,
    /// On the ground (weight on the landing gear).
    pub landed: bool,
    /// Armed.
    pub armed: bool,
    /// Flight mode.
    pub mode: FlightMode,
    /// System state.
    pub state: SystemState,
}

/// The twin.
#[derive(Debug, Clone)]
pub struct Vehicle {
    config: VehicleConfig,
    telemetry: Telemetry,
}

impl Vehicle {
    /// A vehicle at rest at `config.initial`.
    #[must_use]
    pub fn new(config: VehicleConfig) -> Self {
        Self {
            telemetry: Telemetry {
                mode: config.mode,
                armed: config.armed,
                ..Telemetry::default()
            },
            config,
        }
    }

    /// Advances the twin by one physics step of [`PHYSICS_DT_S`].
    pub fn step(&mut self) {
        self.telemetry.t_us += 1000;
    }

    /// Current snapshot.
    #[must_use]
    pub fn telemetry(&self) -> &Telemetry {
        &self.telemetry
    }

    /// Current gains.
    #[must_use]
    pub fn gains(&self) -> &Gains {
        &self.config.gains
    }

    /// Replaces the gains after checking them.
    ///
    /// # Errors
    /// The first constraint the set breaks; the old gains stay in force.
    pub fn set_gains(&mut self, gains: Gains) -> Result<(), GainError> {
        gains.validate()?;
        self.config.gains = gains;
        Ok(())
    }

    /// Arms the motors. Without `force`, pre-arm checks apply (calibration done, level, landed).
    ///
    /// # Errors
    /// [`ArmError::PreArm`] saying which check failed.
    pub fn arm(&mut self, force: bool) -> Result<(), ArmError> {
        let _ = force;
        self.telemetry.armed = true;
        Ok(())
    }

    /// Disarms. In flight only with `force`.
    ///
    /// # Errors
    /// [`ArmError::InFlight`].
    pub fn disarm(&mut self, force: bool) -> Result<(), ArmError> {
        let _ = force;
        self.telemetry.armed = false;
        Ok(())
    }

    /// Changes the flight mode.
    pub fn set_mode(&mut self, mode: FlightMode) {
        self.telemetry.mode = mode;
    }

    /// RC receiver input: pulse widths in µs for channels 1–8 (1 roll, 2 pitch, 3 throttle,
    /// 4 yaw); 0 = no signal on that channel.
    pub fn set_rc_input(&mut self, channels_us: [u16; 8]) {
        self.telemetry.rc_us = channels_us;
    }

    /// Moves the hover point (paper frame, z up) used by QLOITER.
    pub fn set_position_setpoint(&mut self, pos_m: Vector3<f64>) {
        let _ = pos_m;
    }

    /// Applies a body torque (N·m) for `duration_s`: the paper's push on an axis.
    pub fn push(&mut self, torque_body_nm: Vector3<f64>, duration_s: f64) {
        let _ = (torque_body_nm, duration_s);
    }

    /// Sets a steady wind (inertial, m/s) and a gust intensity (m/s, standard deviation).
    pub fn set_wind(&mut self, wind_m_s: Vector3<f64>, gust_m_s: f64) {
        let _ = (wind_m_s, gust_m_s);
    }
}
