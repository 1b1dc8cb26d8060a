//! Airframe constants: Table I of the paper and the actuator constants it omits
//! (`PHYSICS.md` §0 and §5). Units are in the field names.

/// Standard gravity used by the paper (Table I).
pub const GRAVITY_M_S2: f64 = 9.8;

/// Physical constants of the prototype. `Airframe::default()` is the paper's vehicle.
#[derive(Debug, Clone, PartialEq)]
pub struct Airframe {
    /// Total mass (Table I).
    pub mass_kg: f64,
    /// Gravity (Table I).
    pub gravity_m_s2: f64,
    /// Principal inertias about the body axes x, y, z (Table I).
    pub inertia_kg_m2: [f64; 3],
    /// Rotor thrust coefficient kT = k_r C_Lr α_r: T = kT ω².
    pub k_thrust_n_per_rad2_s2: f64,
    /// Rotor drag coefficient kD = k_r C_Dr α_r: D = kD ω².
    pub k_drag_n_per_rad2_s2: f64,
    /// Rotor (propeller) inertia about its spin axis, for Γg.
    pub rotor_inertia_kg_m2: f64,
    /// Maximum rotor speed (propeller side of the 1:6 gear).
    pub rotor_speed_max_rad_s: f64,
    /// Gear ratio motor:propeller (1:6 in the prototype).
    pub gear_ratio: f64,
    /// Rotor arm: rotors sit at y = ±l_r.
    pub rotor_arm_m: f64,
    /// Aileron arm: ailerons sit at y = ±l_a.
    pub aileron_arm_m: f64,
    /// Elevator arm: aerodynamic centre of the elevator below the CG.
    pub elevator_arm_m: f64,
    /// Prop-wash speed per rotor speed: υ = k_υ ω.
    pub k_wash_m_per_rad: f64,
    /// ½ρS of the elevator.
    pub k_elevator_kg_m: f64,
    /// ½ρS of each aileron.
    pub k_aileron_kg_m: f64,
    /// Lift-curve slope of the flat-plate surfaces.
    pub lift_slope_per_rad: f64,
    /// Deflection limit used by the firmware and the servos.
    pub surface_limit_rad: f64,
    /// Servo deflection at ±500 µs from neutral.
    pub servo_throw_rad: f64,
    /// First-order time constant of ESC + geared DC motor.
    pub motor_time_constant_s: f64,
    /// First-order time constant of the servos.
    pub servo_time_constant_s: f64,
    /// Servo slew-rate limit.
    pub servo_rate_limit_rad_s: f64,
    /// Linear drag coefficient of the whole airframe against the relative wind
    /// (used only for wind and gust perturbations; the paper's model has none).
    pub body_drag_n_s_per_m: f64,
}

impl Default for Airframe {
    fn default() -> Self {
        Self {
            mass_kg: 0.5,
            gravity_m_s2: GRAVITY_M_S2,
            inertia_kg_m2: [0.0288, 0.020, 0.0088],
            k_thrust_n_per_rad2_s2: 1.25e-5,
            k_drag_n_per_rad2_s2: 1.25e-6,
            rotor_inertia_kg_m2: 6e-5,
            rotor_speed_max_rad_s: 650.0,
            gear_ratio: 6.0,
            rotor_arm_m: 0.15,
            aileron_arm_m: 0.15,
            elevator_arm_m: 0.20,
            k_wash_m_per_rad: 0.018,
            k_elevator_kg_m: 0.012,
            k_aileron_kg_m: 0.009,
            lift_slope_per_rad: 5.0,
            surface_limit_rad: 0.35,
            servo_throw_rad: 0.5,
            motor_time_constant_s: 0.04,
            servo_time_constant_s: 0.02,
            servo_rate_limit_rad_s: 10.0,
            body_drag_n_s_per_m: 0.15,
        }
    }
}

impl Airframe {
    /// Weight m·g.
    #[must_use]
    pub fn weight_n(&self) -> f64 {
        self.mass_kg * self.gravity_m_s2
    }

    /// Rotor speed at which the two rotors together carry the weight.
    #[must_use]
    pub fn hover_rotor_speed_rad_s(&self) -> f64 {
        (self.weight_n() / (2.0 * self.k_thrust_n_per_rad2_s2)).sqrt()
    }
}

/// Which of the two model modes of `PHYSICS.md` §0 the twin runs.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum ModelMode {
    /// The paper's idealised closed loop: perfect sensing, instantaneous unlimited actuators,
    /// f_x of (43) applied as an independent body force.
    Paper,
    /// Forces only from the actuators, lags and limits, sensors through the estimator.
    #[default]
    Physical,
}

impl std::str::FromStr for ModelMode {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        match s {
            "paper" => Ok(Self::Paper),
            "physical" => Ok(Self::Physical),
            other => Err(format!(
                "unknown model '{other}' (expected paper or physical)"
            )),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn table_one_plate_inertia_identity() {
        let a = Airframe::default();
        let [ix, iy, iz] = a.inertia_kg_m2;
        assert!((ix - (iy + iz)).abs() < 1e-12);
    }

    #[test]
    fn hover_near_1681_us() {
        let a = Airframe::default();
        let pwm = 1000.0 + 1000.0 * a.hover_rotor_speed_rad_s() / a.rotor_speed_max_rad_s;
        assert!((pwm - 1681.0).abs() < 2.0, "{pwm}");
    }
}
