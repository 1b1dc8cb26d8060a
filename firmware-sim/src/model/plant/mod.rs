//! The paper's full nonlinear hover model (`PHYSICS.md` §1–§2, §5): a pure
//! [`derivative`] of the rigid-body state under the forces and torques of the rotors, the control
//! surfaces in their prop-wash, gravity and external disturbances.
//!
//! Frames: inertial I with **z up**; body B with thrust along +z_B, span along y_B, x_B normal
//! to the wing ([I1]). The state is ξ = (x, y, z) in I, vᴮ = (u, v, w) in B, η = (ψ, θ, φ) and
//! Ω = (p, q, r) in B. Each force and torque comes from its own small model function
//! ([`rotors`], [`surfaces`], [`disturbances`]); they are summed here and integrated once by
//! [`crate::model::integrator`]. Actuator dynamics ([`actuators`]) and ground contact ([`ground`]) act
//! between integration steps; the flight [`battery`] drains with the rotors' shaft power.

pub mod actuators;
pub mod aero;
pub mod battery;
pub mod disturbances;
pub mod ground;
pub mod rigid_body;
pub mod rotors;
pub mod surface_airflow;
pub mod surfaces;

use nalgebra::Vector3;

use crate::model::airframe::{Airframe, ModelMode};
use crate::model::frames::Euler;
use crate::model::integrator::OdeState;
use crate::model::signals::ActuatorCommand;

use rigid_body::{EulerTrig, RigidBody};

/// Rigid-body state s = [ξ, vᴮ, η, Ω] (paper frames).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct PlantState {
    /// Position ξ = (x, y, z) in I, m (z up).
    pub pos_m: Vector3<f64>,
    /// Velocity in B, (u, v, w), m/s.
    pub vel_body_m_s: Vector3<f64>,
    /// Attitude η = (ψ, θ, φ).
    pub euler: Euler,
    /// Body rates Ω = (p, q, r), rad/s.
    pub omega_body_rad_s: Vector3<f64>,
}

impl PlantState {
    /// At rest at `pos_m` with attitude `euler`.
    #[must_use]
    pub fn at_rest(pos_m: Vector3<f64>, euler: Euler) -> Self {
        Self {
            pos_m,
            euler,
            ..Self::default()
        }
    }

    /// Inertial velocity ξ̇ = R vᴮ, m/s.
    #[must_use]
    pub fn vel_inertial_m_s(&self) -> Vector3<f64> {
        self.euler.rotation_body_to_inertial() * self.vel_body_m_s
    }
}

/// Time derivative of [`PlantState`].
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct PlantStateDot {
    /// ξ̇ = R vᴮ, m/s.
    pub pos_dot_m_s: Vector3<f64>,
    /// v̇ᴮ, m/s².
    pub vel_body_dot_m_s2: Vector3<f64>,
    /// η̇ = (ψ̇, θ̇, φ̇), rad/s.
    pub euler_dot_rad_s: Vector3<f64>,
    /// Ω̇, rad/s².
    pub omega_dot_rad_s2: Vector3<f64>,
}

impl OdeState for PlantState {
    type Derivative = PlantStateDot;

    #[inline]
    fn advanced(&self, d: &PlantStateDot, h: f64) -> Self {
        let e = self.euler;
        Self {
            pos_m: self.pos_m + d.pos_dot_m_s * h,
            vel_body_m_s: self.vel_body_m_s + d.vel_body_dot_m_s2 * h,
            euler: Euler::new(
                e.psi + d.euler_dot_rad_s[0] * h,
                e.theta + d.euler_dot_rad_s[1] * h,
                e.phi + d.euler_dot_rad_s[2] * h,
            ),
            omega_body_rad_s: self.omega_body_rad_s + d.omega_dot_rad_s2 * h,
        }
    }

    /// The weighted sum first, k1 + k4 + 2 (k2 + k3), then one step along it: 12 operations
    /// per component where the term-by-term default takes 16.
    #[inline]
    fn rk4_update(&self, k: [&PlantStateDot; 4], h: f64) -> Self {
        let [k1, k2, k3, k4] = k;
        let sum = |f: fn(&PlantStateDot) -> &Vector3<f64>| f(k1) + f(k4) + (f(k2) + f(k3)) * 2.0;
        let e = self.euler;
        let euler_sum = sum(|d| &d.euler_dot_rad_s);
        let h6 = h / 6.0;
        Self {
            pos_m: self.pos_m + sum(|d| &d.pos_dot_m_s) * h6,
            vel_body_m_s: self.vel_body_m_s + sum(|d| &d.vel_body_dot_m_s2) * h6,
            euler: Euler::new(
                e.psi + euler_sum[0] * h6,
                e.theta + euler_sum[1] * h6,
                e.phi + euler_sum[2] * h6,
            ),
            omega_body_rad_s: self.omega_body_rad_s + sum(|d| &d.omega_dot_rad_s2) * h6,
        }
    }
}

/// Everything that drives the plant during one integration step (held constant over it).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct PlantInput {
    /// Actual actuator positions: rotor speeds and surface deflections (after the actuator
    /// models in `physical` mode; the controller's command itself in `paper` mode).
    pub actuators: ActuatorCommand,
    /// f_x of (43), N, applied as an independent body force along x_B. Used only in `paper`
    /// mode ([I8], [I16]); there the surfaces' own x force is not applied.
    pub fx_paper_n: f64,
    /// External torque in B (a push), N·m.
    pub disturbance_torque_body_nm: Vector3<f64>,
    /// Wind in I, m/s, when the wind perturbation is active. In `paper` mode the airframe then
    /// feels the drag −c (v − w) of `airframe.body_drag_n_s_per_m`; `None` is the paper's model,
    /// which has no aerodynamic drag on the airframe at all. In `physical` mode the wind acts
    /// only through the air-relative velocity of [`aero`], which the vehicle evaluates into
    /// [`PlantInput::aero`]; this field is then ignored.
    pub wind_m_s: Option<Vector3<f64>>,
    /// The airframe's aerodynamic loads ([`aero::loads`]), held over the step; applied in
    /// `physical` mode only.
    pub aero: Loads,
}

/// Sum of all non-gravitational forces and of all torques on the airframe, both in B.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Loads {
    /// Non-gravitational force in B, N.
    pub force_body_n: Vector3<f64>,
    /// Torque about the CG in B, N·m.
    pub torque_body_nm: Vector3<f64>,
}

/// The part of [`Loads`] fixed by the input alone: every force and torque except those that
/// depend on the state (the rotors' gyroscopic torque and the wind drag). The input is held over
/// a physics step, so the vehicle computes this once per step rather than at every RK4 stage.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct HeldLoads {
    /// Thrust, surface (or `paper` f_x) force in B, N.
    force_body_n: Vector3<f64>,
    /// Thrust, surface, rotor-drag and disturbance torque in B, N·m.
    torque_body_nm: Vector3<f64>,
    /// Rotor speeds, for the gyroscopic torque.
    rotor_speed_rad_s: [f64; 2],
    /// Wind in I when the wind perturbation is active.
    wind_m_s: Option<Vector3<f64>>,
}

impl HeldLoads {
    /// The input's own forces and torques (8), (10)–(12).
    #[must_use]
    pub fn new(af: &Airframe, model: ModelMode, u: &PlantInput) -> Self {
        let w = &u.actuators.rotor_speed_rad_s;
        let thrusts = rotors::thrusts_n(af, w);
        let drags = rotors::drags_n(af, w);
        let lifts = surfaces::lifts(af, &u.actuators);
        let force_body_n = rotors::thrust_force_body_n(&thrusts);
        let torque_body_nm = rotors::thrust_torque_body_nm(af, &thrusts)
            + surfaces::torque_body_nm(af, &lifts)
            + rotors::drag_torque_body_nm(af, model, &drags)
            + u.disturbance_torque_body_nm;
        match model {
            // [I16]: the paper's design applies f_x of (43) in place of the surfaces' force.
            ModelMode::Paper => Self {
                force_body_n: force_body_n + Vector3::new(u.fx_paper_n, 0.0, 0.0),
                torque_body_nm,
                rotor_speed_rad_s: *w,
                wind_m_s: u.wind_m_s,
            },
            ModelMode::Physical => Self {
                force_body_n: force_body_n + surfaces::force_body_n(&lifts) + u.aero.force_body_n,
                torque_body_nm: torque_body_nm + u.aero.torque_body_nm,
                rotor_speed_rad_s: *w,
                wind_m_s: None,
            },
        }
    }

    /// All the loads at state `s` (attitude `trig`).
    #[inline]
    #[must_use]
    pub fn at(&self, af: &Airframe, trig: &EulerTrig, s: &PlantState) -> Loads {
        let mut force = self.force_body_n;
        if let Some(wind) = &self.wind_m_s {
            let r = trig.rotation_body_to_inertial();
            force += disturbances::wind_drag_body_n(af, &r, &s.vel_body_m_s, wind);
        }
        Loads {
            force_body_n: force,
            torque_body_nm: self.torque_body_nm
                + rotors::gyroscopic_torque_body_nm(
                    af,
                    &s.omega_body_rad_s,
                    &self.rotor_speed_rad_s,
                ),
        }
    }
}

/// Forces and torques of every model, summed (8), (10)–(12).
#[must_use]
pub fn loads(
    af: &Airframe,
    model: ModelMode,
    trig: &EulerTrig,
    s: &PlantState,
    u: &PlantInput,
) -> Loads {
    HeldLoads::new(af, model, u).at(af, trig, s)
}

/// ṡ = f(s, u): the plant's equations of motion. Pure: no state, no allocation.
#[must_use]
pub fn derivative(
    af: &Airframe,
    model: ModelMode,
    s: &PlantState,
    u: &PlantInput,
) -> PlantStateDot {
    derivative_with_trig(af, model, s, u, &EulerTrig::new(&s.euler))
}

/// [`derivative`] with the sines and cosines of `s.euler` supplied by the caller (the vehicle's
/// RK4 derives them for each stage from the step's start, [`EulerTrig::shifted`]).
#[must_use]
pub fn derivative_with_trig(
    af: &Airframe,
    model: ModelMode,
    s: &PlantState,
    u: &PlantInput,
    trig: &EulerTrig,
) -> PlantStateDot {
    derivative_held(
        af,
        &RigidBody::new(af),
        s,
        &HeldLoads::new(af, model, u),
        trig,
    )
}

/// [`derivative`] from loads and constants prepared once per step ([`HeldLoads`],
/// [`RigidBody`]): the form the vehicle's RK4 stages call.
#[inline]
#[must_use]
pub fn derivative_held(
    af: &Airframe,
    body: &RigidBody,
    s: &PlantState,
    held: &HeldLoads,
    trig: &EulerTrig,
) -> PlantStateDot {
    let l = held.at(af, trig, s);
    PlantStateDot {
        pos_dot_m_s: trig.rotate_body_to_inertial(&s.vel_body_m_s),
        vel_body_dot_m_s2: body.body_acceleration_m_s2(
            trig,
            &s.vel_body_m_s,
            &s.omega_body_rad_s,
            &l.force_body_n,
        ),
        euler_dot_rad_s: trig.euler_rates(&s.omega_body_rad_s),
        omega_dot_rad_s2: body.angular_acceleration_rad_s2(&s.omega_body_rad_s, &l.torque_body_nm),
    }
}

/// Specific force in B (what an accelerometer at the CG measures in flight): the
/// non-gravitational force divided by the mass, m/s². `trig` holds the sines and cosines of
/// `s.euler`.
#[must_use]
pub fn specific_force_body_m_s2(
    af: &Airframe,
    model: ModelMode,
    trig: &EulerTrig,
    s: &PlantState,
    u: &PlantInput,
) -> Vector3<f64> {
    loads(af, model, trig, s, u).force_body_n * (1.0 / af.mass_kg)
}

#[cfg(test)]
mod tests;
