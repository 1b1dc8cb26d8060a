//! The forward-flight law (`docs/forward-flight.md`): attitude by rotation error, valid at every
//! pitch from hover to level flight, with thrust and pitch from the energy controller
//! ([`super::tecs`]) or, in a transition, thrust holding the height at a commanded nose angle.
//!
//! The hover law's Euler angles are singular at θ = ±90°, which is where a tailsitter flies
//! level. This law builds the desired rotation R_d from the nose's heading χ, its angle γ above
//! the horizon and the bank μ about it, R_d = Rz(χ) Ry(π/2 − γ) Rz(μ) (γ = 90° is the hover),
//! and drives the error e_R = ½ vee(R_dᵀR − RᵀR_d), e_Ω = Ω − RᵀR_d Ω_d (Lee, Leok &
//! McClamroch 2010) to zero with the three actuators the hover uses: thrust difference about
//! x_B (yaw in forward flight), the elevator about y_B (pitch), differential ailerons about z_B
//! (roll). The surfaces' authority is the dynamic pressure of the wash plus the free stream
//! (`plant::surface_airflow`), so the mixer here divides by the sum.

use nalgebra::{Matrix3, Vector3};

use super::ControlOutput;
use super::altitude::altitude_accel_m_s2;
use super::forward_gains::ForwardGains;
use super::mixer::{self, MIN_WASH_SQ_M2_S2};
use super::tecs::{Tecs, TecsInput};
use crate::model::airframe::{Airframe, ModelMode};
use crate::model::frames::Euler;
use crate::model::plant::{aero, surface_airflow};
use crate::model::signals::ActuatorCommand;

/// The law's fixed tuning: what no parameter sets, kept together as ArduPilot keeps a
/// controller's tuning in one parameter group.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ForwardTuning {
    /// Damping ratio of the attitude law.
    pub attitude_damping: f64,
    /// Lowest nose angle above the horizon the law asks for, rad: the nose never goes below
    /// it in wings-level flight, which keeps the plant's Euler angles (θ = 90° − γ) off their
    /// singularity. Banking lowers θ further.
    pub nose_angle_min_rad: f64,
    /// Highest angle of attack fed forward for the lift the flight needs, rad.
    pub alpha_ff_max_rad: f64,
    /// Smallest vertical share of the thrust axis the height-holding thrust divides by.
    pub nose_vertical_min: f64,
    /// Height loop of the transitions, the hover's altitude law (37) with these gains:
    /// derivative gain, 1/s…
    pub transition_alt_kd: f64,
    /// …and proportional gain, 1/s².
    pub transition_alt_kp: f64,
    /// Lowest thrust in any phase, as a share of the weight: the rotors keep some wash over
    /// the surfaces and never stop in the air.
    pub thrust_min_weights: f64,
}

impl Default for ForwardTuning {
    fn default() -> Self {
        Self {
            attitude_damping: 0.8,
            nose_angle_min_rad: 0.05,
            alpha_ff_max_rad: 0.35,
            nose_vertical_min: 0.25,
            transition_alt_kd: 2.0,
            transition_alt_kp: 1.5,
            thrust_min_weights: 0.1,
        }
    }
}

impl ForwardTuning {
    /// Angle of attack whose lift coefficient is `cl` on the attached-flow curve
    /// C_N ≈ C_Lα α + K_v α², clamped to [0, [`Self::alpha_ff_max_rad`]].
    #[must_use]
    pub fn alpha_for_lift(&self, cl: f64) -> f64 {
        let (a, k) = (aero::LIFT_SLOPE_PER_RAD, aero::VORTEX_LIFT_K);
        let cl = cl.max(0.0);
        ((-a + (a * a + 4.0 * k * cl).sqrt()) / (2.0 * k)).min(self.alpha_ff_max_rad)
    }
}

/// How the law gets its thrust and nose angle.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Longitudinal {
    /// The energy controller holds this height and airspeed (m, m/s; the caller keeps the
    /// airspeed inside the modes' limits).
    Energy {
        /// Height, m (z up).
        height_m: f64,
        /// Airspeed, m/s.
        airspeed_m_s: f64,
    },
    /// A transition: the nose at this angle above the horizon (rad), thrust holding the height.
    NoseAngle {
        /// Nose angle above the horizon, rad.
        nose_rad: f64,
        /// Height, m.
        height_m: f64,
        /// Least thrust, N (the back transition keeps the wash over the elevator).
        thrust_min_n: f64,
    },
    /// FBWA: the nose at this angle, the thrust given (N).
    Manual {
        /// Nose angle above the horizon, rad.
        nose_rad: f64,
        /// Thrust, N.
        thrust_n: f64,
    },
}

/// What the law flies this tick.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ForwardCommand {
    /// Thrust and pitch.
    pub longitudinal: Longitudinal,
    /// Bank about the nose, rad (positive: right wing down, a turn to the right).
    pub bank_rad: f64,
    /// Nose heading in the transitions, rad (in flight the nose follows the air velocity).
    pub heading_rad: f64,
}

/// The state the law reads (paper frames, z up).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ForwardInput {
    /// Tick, s.
    pub dt_s: f64,
    /// Attitude.
    pub euler: Euler,
    /// Body rates, rad/s.
    pub omega_body_rad_s: Vector3<f64>,
    /// Position, m.
    pub pos_m: Vector3<f64>,
    /// Inertial velocity, m/s.
    pub vel_m_s: Vector3<f64>,
    /// Air-relative velocity in B (the airspeed sensor), m/s.
    pub air_velocity_body_m_s: Vector3<f64>,
    /// Rotor speeds, rad/s.
    pub rotor_speed_rad_s: [f64; 2],
}

/// The law's state.
#[derive(Debug, Clone, Default)]
pub struct ForwardLaw {
    tuning: ForwardTuning,
    tecs: Tecs,
    energy_active: bool,
    pwm_residual_us: [f64; 5],
}

/// R_d = Rz(χ) Ry(π/2 − γ) Rz(μ).
#[must_use]
pub fn desired_rotation(heading_rad: f64, nose_rad: f64, bank_rad: f64) -> Matrix3<f64> {
    let rz = |a: f64| {
        let (s, c) = a.sin_cos();
        Matrix3::new(c, -s, 0.0, s, c, 0.0, 0.0, 0.0, 1.0)
    };
    let (s, c) = (std::f64::consts::FRAC_PI_2 - nose_rad).sin_cos();
    let ry = Matrix3::new(c, 0.0, s, 0.0, 1.0, 0.0, -s, 0.0, c);
    rz(heading_rad) * ry * rz(bank_rad)
}

/// The rotation error e_R = ½ vee(R_dᵀR − RᵀR_d).
#[must_use]
pub fn rotation_error(r: &Matrix3<f64>, r_d: &Matrix3<f64>) -> Vector3<f64> {
    let m = r_d.transpose() * r - r.transpose() * r_d;
    0.5 * Vector3::new(m[(2, 1)], m[(0, 2)], m[(1, 0)])
}

/// Surface deflections (δ_e, δ_L, δ_R) for Γy, Γz with the wash and the free stream.
fn surfaces_rad(af: &Airframe, w: [f64; 2], vs_sq: f64, gy: f64, gz: f64) -> [f64; 3] {
    let kv = af.k_wash_m_per_rad;
    let (v1, v2) = ((kv * w[0]).powi(2), (kv * w[1]).powi(2));
    let elev_q = 0.5 * (v1 + v2) + vs_sq;
    let ail_q = v1 + v2 + 2.0 * vs_sq;
    if elev_q < MIN_WASH_SQ_M2_S2 {
        return [0.0; 3];
    }
    let cl = af.lift_slope_per_rad;
    let de = gy / (af.elevator_arm_m * af.k_elevator_kg_m * cl * elev_q);
    let da = gz / (af.aileron_arm_m * af.k_aileron_kg_m * cl * ail_q);
    let lim = af.surface_limit_rad;
    [de, da, -da].map(|x| x.clamp(-lim, lim))
}

impl ForwardLaw {
    /// Clears the law's state (a new flight phase).
    pub fn reset(&mut self) {
        *self = Self::default();
    }

    /// The law's fixed tuning.
    #[must_use]
    pub fn tuning(&self) -> &ForwardTuning {
        &self.tuning
    }

    /// One tick. The longest function of the law: the three steps (thrust and nose angle,
    /// attitude, mixing) share a dozen intermediate values.
    pub fn update(
        &mut self,
        af: &Airframe,
        gains: &ForwardGains,
        inp: &ForwardInput,
        cmd: &ForwardCommand,
    ) -> ControlOutput {
        let t = self.tuning;
        let (m, g) = (af.mass_kg, af.gravity_m_s2);
        let r = inp.euler.rotation_body_to_inertial();
        let v_air = inp.air_velocity_body_m_s;
        let airspeed = v_air.norm();
        let air_inertial = r * v_air;
        let fz_max = 2.0 * af.k_thrust_n_per_rad2_s2 * af.rotor_speed_max_rad_s.powi(2);
        let loads = aero::loads(af, &v_air, &inp.rotor_speed_rad_s);
        let aero_inertial = r * loads.force_body_n;
        let nose = r.column(2).into_owned();
        let bank = cmd
            .bank_rad
            .clamp(-gains.roll_limit_rad, gains.roll_limit_rad);

        // 1. Thrust and the nose angle above the horizon.
        let height_hold = |height: f64| {
            let (kd, kp) = (t.transition_alt_kd, t.transition_alt_kp);
            let rz = altitude_accel_m_s2(kd, kp, inp.pos_m.z, inp.vel_m_s.z, height);
            (m * (g + rz) - aero_inertial.z) / nose.z.max(t.nose_vertical_min)
        };
        let (thrust, nose_rad) = match cmd.longitudinal {
            Longitudinal::Energy {
                height_m,
                airspeed_m_s,
            } => {
                let drag = -(loads.force_body_n.z);
                if !self.energy_active {
                    // A fresh start: the transition's thrust held the height at a steep nose;
                    // on the wing the drag and the demanded energy rate set it.
                    self.tecs.reset();
                    self.energy_active = true;
                }
                let out = self.tecs.update(
                    &gains.tecs,
                    &TecsInput {
                        dt_s: inp.dt_s,
                        h_m: inp.pos_m.z,
                        h_dot_m_s: inp.vel_m_s.z,
                        airspeed_m_s: airspeed,
                        h_demand_m: height_m,
                        airspeed_demand_m_s: airspeed_m_s,
                        drag_n: drag.max(0.0),
                        mass_kg: m,
                        gravity_m_s2: g,
                        thrust_max_n: fz_max,
                    },
                );
                let q = 0.5 * aero::AIR_DENSITY_KG_M3 * airspeed.max(3.0).powi(2);
                let load = m * g * out.path_angle_rad.cos() / bank.cos().max(0.3);
                let alpha = t.alpha_for_lift(load / (q * aero::WING_AREA_M2));
                (out.thrust_n, out.path_angle_rad + alpha)
            }
            Longitudinal::NoseAngle {
                nose_rad,
                height_m,
                thrust_min_n,
            } => {
                self.energy_active = false;
                (height_hold(height_m).max(thrust_min_n), nose_rad)
            }
            Longitudinal::Manual { nose_rad, thrust_n } => {
                self.energy_active = false;
                (thrust_n, nose_rad)
            }
        };
        let thrust = thrust.clamp(t.thrust_min_weights * m * g, fz_max);
        let nose_rad = nose_rad.clamp(t.nose_angle_min_rad, std::f64::consts::FRAC_PI_2);

        // 2. Attitude: the nose follows the air's heading once the wing flies, the command's
        //    heading before; the coordinated turn rate g tan μ / V is fed forward.
        let flying = matches!(
            cmd.longitudinal,
            Longitudinal::Energy { .. } | Longitudinal::Manual { .. }
        ) && air_inertial.xy().norm() > 3.0;
        let heading = if flying {
            air_inertial.y.atan2(air_inertial.x)
        } else {
            cmd.heading_rad
        };
        let r_d = desired_rotation(heading, nose_rad, bank);
        let turn_rate = if flying {
            -g * bank.tan() / airspeed.max(3.0)
        } else {
            0.0
        };
        let omega_d_body_d = r_d.tr_mul(&Vector3::new(0.0, 0.0, turn_rate));
        let e_r = rotation_error(&r, &r_d);
        let e_w = inp.omega_body_rad_s - r.tr_mul(&(r_d * omega_d_body_d));
        let wn = gains.attitude_bandwidth_rad_s;
        let accel = -(wn * wn) * e_r - 2.0 * t.attitude_damping * wn * e_w;
        let inertia = Vector3::from(af.inertia_kg_m2);
        let w = inp.omega_body_rad_s;
        let iw = inertia.component_mul(&w);
        let torque = inertia.component_mul(&accel) + w.cross(&iw) - loads.torque_body_nm;

        // 3. Mixing: rotors for thrust and Γx, surfaces with the wash and the free stream.
        let rotors = mixer::rotor_speeds_rad_s(af, ModelMode::Physical, thrust, torque.x);
        let vs_sq = surface_airflow::axial_speed_sq(&v_air);
        let [de, dl, dr] = surfaces_rad(af, rotors, vs_sq, torque.y, torque.z);
        let actuators = ActuatorCommand {
            rotor_speed_rad_s: rotors,
            elevator_rad: de,
            aileron_left_rad: dl,
            aileron_right_rad: dr,
        };
        let pwm_us = mixer::pwm_us_dithered(af, &actuators, &mut self.pwm_residual_us);
        ControlOutput {
            tau_tilde: accel,
            torque_body_nm: torque,
            fz_n: thrust,
            fx_n: 0.0,
            actuators,
            pwm_us,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn hover_attitude_is_the_desired_rotation_at_ninety_degrees() {
        let e = Euler::new(0.7, 0.0, 0.0);
        let r_d = desired_rotation(0.7, std::f64::consts::FRAC_PI_2, 0.0);
        assert!((e.rotation_body_to_inertial() - r_d).norm() < 1e-12);
    }

    #[test]
    fn level_flight_is_theta_ninety_minus_nose_angle() {
        let e = Euler::new(0.3, std::f64::consts::FRAC_PI_2 - 0.1, 0.0);
        let r_d = desired_rotation(0.3, 0.1, 0.0);
        assert!((e.rotation_body_to_inertial() - r_d).norm() < 1e-12);
        assert!(rotation_error(&r_d, &r_d).norm() < 1e-15);
    }

    #[test]
    fn a_small_rotation_gives_its_own_axis_as_error() {
        let r_d = desired_rotation(0.0, 0.2, 0.0);
        let tilt = nalgebra::Rotation3::from_axis_angle(&Vector3::y_axis(), 0.01);
        let e = rotation_error(&(r_d * tilt.matrix()), &r_d);
        assert!((e - Vector3::new(0.0, 0.01, 0.0)).norm() < 1e-6, "{e}");
    }

    #[test]
    fn positive_bank_tilts_the_lift_to_the_right() {
        // Heading +x, so right is −y (z up); the lift is along −x_B.
        let r_d = desired_rotation(0.0, 0.1, 0.3);
        let lift = -r_d.column(0);
        assert!(lift.y < 0.0 && lift.z > 0.0, "{lift}");
    }
}
