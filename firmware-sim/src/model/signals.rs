//! The signals that pass between the model's rooms: what the pilot's receiver gives the
//! controller (through the sensors), what the controller commands the actuators of the plant, and
//! the tilt past which the vehicle has crashed, which the controller's hover hold must stay
//! inside. Plant, sensors, control and the vehicle import them from here, so no room of the
//! model imports a sibling's types.

/// Tilt beyond which the vehicle is considered tipped over (crash), rad.
pub const CRASH_TILT_RAD: f64 = std::f64::consts::FRAC_PI_3;

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
