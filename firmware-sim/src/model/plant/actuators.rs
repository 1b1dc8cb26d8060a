//! Actuator models of the `physical` twin (`PHYSICS.md` §5, [I18]): PWM in µs to rotor speed
//! through an ESC + geared DC motor (first-order lag), and PWM to surface deflection through a
//! servo (first-order lag, slew-rate limit, ±surface limit). PWM is an integer number of µs, so
//! outputs are quantised to 1 µs by construction.
//!
//! Channels: SERVO1/SERVO2 = ESC of rotor 1/2, SERVO3/SERVO4 = left/right aileron,
//! SERVO5 = elevator. In `paper` mode none of this runs: the plant gets the controller's
//! command directly (instantaneous, unlimited).

use crate::model::airframe::Airframe;
use crate::model::signals::{ActuatorCommand, PwmOutputs};

/// Minimum (idle, disarmed) ESC pulse, µs.
pub const ESC_IDLE_US: u16 = 1000;
/// Servo neutral pulse, µs.
pub const SERVO_NEUTRAL_US: u16 = 1500;
/// PWM outputs of a disarmed vehicle: motors idle, surfaces neutral.
pub const DISARMED_PWM_US: PwmOutputs = [
    ESC_IDLE_US,
    ESC_IDLE_US,
    SERVO_NEUTRAL_US,
    SERVO_NEUTRAL_US,
    SERVO_NEUTRAL_US,
];

/// Steady rotor speed for an ESC pulse: ω = ω_max (pwm − 1000)/1000, clamped to [0, ω_max]
/// (speed ∝ duty for a brushed DC motor behind an ESC).
#[must_use]
pub fn esc_pwm_to_rotor_speed_rad_s(af: &Airframe, pwm_us: u16) -> f64 {
    let duty = ((f64::from(pwm_us) - 1000.0) / 1000.0).clamp(0.0, 1.0);
    af.rotor_speed_max_rad_s * duty
}

/// ESC pulse for a rotor speed (the inverse map, rounded to 1 µs).
#[must_use]
pub fn rotor_speed_to_esc_pwm_us(af: &Airframe, rotor_speed_rad_s: f64) -> u16 {
    let duty = (rotor_speed_rad_s / af.rotor_speed_max_rad_s).clamp(0.0, 1.0);
    // The clamp bounds the value to 1000..=2000, so the cast cannot truncate.
    (1000.0 + 1000.0 * duty).round() as u16
}

/// Servo deflection for a pulse: δ = servo_throw (pwm − 1500)/500, clamped to ±surface limit.
#[must_use]
pub fn servo_pwm_to_deflection_rad(af: &Airframe, pwm_us: u16) -> f64 {
    let d = af.servo_throw_rad * (f64::from(pwm_us) - 1500.0) / 500.0;
    d.clamp(-af.surface_limit_rad, af.surface_limit_rad)
}

/// Servo pulse for a deflection: 1500 + 500 δ / servo_throw, rounded to 1 µs, in 1000..=2000.
#[must_use]
pub fn deflection_to_servo_pwm_us(af: &Airframe, deflection_rad: f64) -> u16 {
    let us = (1500.0 + 500.0 * deflection_rad / af.servo_throw_rad).clamp(1000.0, 2000.0);
    us.round() as u16
}

/// The motors and servos: their actual positions and the discrete lag factors for one step.
#[derive(Debug, Clone, PartialEq)]
pub struct ActuatorModel {
    /// Actual rotor speeds and surface deflections.
    pub state: ActuatorCommand,
    /// exp(−dt/τ_motor): exact discretisation of the first-order motor lag.
    motor_keep: f64,
    /// exp(−dt/τ_servo).
    servo_keep: f64,
    /// Largest deflection change in one step (slew-rate limit × dt).
    servo_step_max_rad: f64,
    /// Surface limit.
    surface_limit_rad: f64,
    /// The PWM outputs the targets below were computed for.
    targets_for: Option<PwmOutputs>,
    /// Rotor speeds and deflections those outputs command.
    targets: [f64; 5],
    /// Fraction of the full rotor speed the pack's voltage can drive (1 = a healthy pack).
    supply: f64,
}

impl ActuatorModel {
    /// Actuators at rest (rotors stopped, surfaces neutral) for steps of `dt_s`.
    #[must_use]
    pub fn new(af: &Airframe, dt_s: f64) -> Self {
        let keep = |tau: f64| if tau > 0.0 { (-dt_s / tau).exp() } else { 0.0 };
        Self {
            state: ActuatorCommand::default(),
            motor_keep: keep(af.motor_time_constant_s),
            servo_keep: keep(af.servo_time_constant_s),
            servo_step_max_rad: af.servo_rate_limit_rad_s * dt_s,
            surface_limit_rad: af.surface_limit_rad,
            targets_for: None,
            targets: [0.0; 5],
            supply: 1.0,
        }
    }

    /// Sets the fraction of the commanded rotor speed the battery can drive
    /// ([`super::battery::Battery::supply_ratio`]): a brushed motor's speed follows its voltage.
    pub fn set_supply(&mut self, ratio: f64) {
        self.supply = ratio.clamp(0.0, 1.0);
    }

    /// Advances every actuator one step toward the position its PWM pulse asks for.
    pub fn step(&mut self, af: &Airframe, pwm_us: &PwmOutputs) {
        // The outputs change at the control rate, the models run at the physics rate.
        if self.targets_for != Some(*pwm_us) {
            self.targets_for = Some(*pwm_us);
            self.targets = [
                esc_pwm_to_rotor_speed_rad_s(af, pwm_us[0]),
                esc_pwm_to_rotor_speed_rad_s(af, pwm_us[1]),
                servo_pwm_to_deflection_rad(af, pwm_us[2]),
                servo_pwm_to_deflection_rad(af, pwm_us[3]),
                servo_pwm_to_deflection_rad(af, pwm_us[4]),
            ];
        }
        let t = self.targets;
        let rotors = [t[0] * self.supply, t[1] * self.supply];
        for (w, target) in self.state.rotor_speed_rad_s.iter_mut().zip(rotors) {
            *w = target + (*w - target) * self.motor_keep;
        }
        let s = &mut self.state;
        for (pos, target) in [
            (&mut s.aileron_left_rad, t[2]),
            (&mut s.aileron_right_rad, t[3]),
            (&mut s.elevator_rad, t[4]),
        ] {
            let lagged = target + (*pos - target) * self.servo_keep;
            let step = (lagged - *pos).clamp(-self.servo_step_max_rad, self.servo_step_max_rad);
            *pos = (*pos + step).clamp(-self.surface_limit_rad, self.surface_limit_rad);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn pwm_maps_round_trip() {
        let af = Airframe::default();
        assert_eq!(esc_pwm_to_rotor_speed_rad_s(&af, 1000), 0.0);
        assert_eq!(esc_pwm_to_rotor_speed_rad_s(&af, 2000), 650.0);
        assert_eq!(esc_pwm_to_rotor_speed_rad_s(&af, 900), 0.0);
        assert_eq!(
            rotor_speed_to_esc_pwm_us(&af, af.hover_rotor_speed_rad_s()),
            1681
        );
        assert_eq!(deflection_to_servo_pwm_us(&af, 0.1), 1600);
        assert!((servo_pwm_to_deflection_rad(&af, 1600) - 0.1).abs() < 1e-12);
        assert_eq!(servo_pwm_to_deflection_rad(&af, 2000), af.surface_limit_rad);
    }

    #[test]
    fn motor_lag_reaches_63_percent_after_one_time_constant() {
        let af = Airframe::default();
        let mut m = ActuatorModel::new(&af, 0.001);
        let steps = (af.motor_time_constant_s / 0.001).round() as usize;
        for _ in 0..steps {
            m.step(&af, &[2000, 1000, 1500, 1500, 1500]);
        }
        let frac = m.state.rotor_speed_rad_s[0] / af.rotor_speed_max_rad_s;
        assert!((frac - (1.0 - (-1.0_f64).exp())).abs() < 1e-9, "{frac}");
        assert_eq!(m.state.rotor_speed_rad_s[1], 0.0);
    }

    #[test]
    fn servo_is_rate_limited_and_clamped() {
        let af = Airframe::default();
        let mut m = ActuatorModel::new(&af, 0.001);
        m.step(&af, &[1000, 1000, 2000, 1000, 2000]);
        // One step of a 0.35 rad demand: lag would give ~0.017 rad, the slew limit allows 0.01.
        assert!((m.state.aileron_left_rad - 0.01).abs() < 1e-12);
        assert!((m.state.aileron_right_rad + 0.01).abs() < 1e-12);
        for _ in 0..1000 {
            m.step(&af, &[1000, 1000, 2000, 1000, 2000]);
        }
        assert!((m.state.elevator_rad - af.surface_limit_rad).abs() < 1e-12);
    }
}
