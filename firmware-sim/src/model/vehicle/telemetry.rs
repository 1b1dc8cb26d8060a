//! What the twin reports: the system state, why an arm request was refused, and the telemetry
//! snapshot of every step.

use nalgebra::Vector3;

use crate::model::control::ControlOutput;
use crate::model::frames::Euler;
use crate::model::mode::{FlightMode, VtolState};
use crate::model::plant::aero;
use crate::model::plant::battery::BatteryState;
use crate::model::signals::PwmOutputs;

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
    /// The mode can only come down.
    #[error("mode {0} cannot take off")]
    Mode(FlightMode),
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
    /// The flight battery.
    pub battery: BatteryState,
    /// The body's true velocity relative to the air (wind and gusts included), in B, m/s.
    pub air_velocity_body_m_s: Vector3<f64>,
    /// Hover, forward flight or a transition between them.
    pub vtol_state: VtolState,
}

impl Telemetry {
    /// True airspeed, m/s.
    #[must_use]
    pub fn airspeed_m_s(&self) -> f64 {
        self.air_velocity_body_m_s.norm()
    }

    /// Angle of attack of the plate ([`aero::angle_of_attack_rad`]), rad.
    #[must_use]
    pub fn angle_of_attack_rad(&self) -> f64 {
        aero::angle_of_attack_rad(&self.air_velocity_body_m_s)
    }

    /// Sideslip, rad: the air-relative velocity's angle toward the right wing (−y_B in forward
    /// flight, where x_B points down), asin(−v_y / V); 0 in still air.
    #[must_use]
    pub fn sideslip_rad(&self) -> f64 {
        let v = &self.air_velocity_body_m_s;
        let speed = v.norm();
        if speed < 1e-9 {
            0.0
        } else {
            (-v.y / speed).clamp(-1.0, 1.0).asin()
        }
    }
}
