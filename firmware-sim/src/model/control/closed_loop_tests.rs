//! Closed loops of the paper's Section IV on an ideal rigid-body plant written here from
//! `PHYSICS.md` §2 (so a sign error in the controller shows up as divergence, independently of
//! the project's plant); in `physical` mode the plant adds the airframe's aerodynamics.

use nalgebra::Vector3;

use super::input_change::{gyroscopic_torque_nm, inertia_matrix, rotor_drag_torque_nm};
use super::mixer::forces_from_actuators;
use super::*;

// ---------------------------------------------------------------------------------------------
// Closed loop on an ideal plant (PHYSICS.md §2), 1 kHz RK4, controller at 100 Hz

#[derive(Clone, Copy)]
struct Rigid {
    pos: Vector3<f64>,
    vel: Vector3<f64>,
    eta: Vector3<f64>,
    omega: Vector3<f64>,
}

/// Derivative of the rigid body under f_z, f_x (body) and Γc, with Γg and Γq at the given
/// rotor speeds: the inertial form (9) and Euler's equation (13), corrected signs.
fn rigid_deriv(
    s: &Rigid,
    model: ModelMode,
    fz: f64,
    fx: f64,
    torque: &Vector3<f64>,
    w: [f64; 2],
) -> Rigid {
    let a = Airframe::default();
    let e = Euler::from_vector(&s.eta);
    let r = e.rotation_body_to_inertial();
    // `physical`: the airframe's aerodynamics, which the controller expects.
    let aero = match model {
        ModelMode::Paper => crate::model::plant::Loads::default(),
        ModelMode::Physical => crate::model::plant::aero::loads(&a, &r.tr_mul(&s.vel), &w),
    };
    let acc = r * (Vector3::new(fx, 0.0, fz) + aero.force_body_n) / a.mass_kg
        - Vector3::new(0.0, 0.0, a.gravity_m_s2);
    let i = inertia_matrix(&a);
    let total = torque
        + aero.torque_body_nm
        + gyroscopic_torque_nm(a.rotor_inertia_kg_m2, &s.omega, w)
        + rotor_drag_torque_nm(&a, model, w)
        - s.omega.cross(&(i * s.omega));
    let omega_dot = total.component_div(&i.diagonal());
    Rigid {
        pos: s.vel,
        vel: acc,
        eta: e.rates_from_body(&s.omega),
        omega: omega_dot,
    }
}

fn add(s: &Rigid, k: &Rigid, h: f64) -> Rigid {
    Rigid {
        pos: s.pos + k.pos * h,
        vel: s.vel + k.vel * h,
        eta: s.eta + k.eta * h,
        omega: s.omega + k.omega * h,
    }
}

/// Flies `t_s` seconds from the paper's initial conditions (ψ0 = `psi0`) toward `setpoint`.
/// Forces come from the commanded actuators through the §5 model (instantaneous actuators);
/// in `paper` mode f_x is (43) as an independent force, in `physical` mode the surfaces' f_x.
fn fly(model: ModelMode, psi0: f64, setpoint: Vector3<f64>, t_s: f64) -> Rigid {
    let a = Airframe::default();
    let gains = Gains::default();
    let mut c = Controller::new(Airframe::default(), model);
    let mut s = Rigid {
        pos: Vector3::new(0.1, 0.1, 0.1),
        vel: Vector3::zeros(),
        eta: Vector3::new(psi0, 0.1, 0.1),
        omega: Vector3::zeros(),
    };
    let mut w = [a.hover_rotor_speed_rad_s(); 2];
    let h = 0.001;
    for _ in 0..(t_s * 100.0).round() as usize {
        let input = ControlInput {
            dt_s: 0.01,
            mode: FlightMode::QLoiter,
            euler: Euler::from_vector(&s.eta),
            omega_body_rad_s: s.omega,
            pos_m: s.pos,
            vel_m_s: s.vel,
            setpoint_m: setpoint,
            yaw_setpoint_rad: 0.0,
            rotor_speed_rad_s: w,
            pilot: PilotInput::default(),
        };
        let out = c.update(&input, &gains);
        w = out.actuators.rotor_speed_rad_s;
        let (fz, torque, fx_surf) = forces_from_actuators(&a, &out.actuators);
        let fx = match model {
            ModelMode::Paper => out.fx_n,
            ModelMode::Physical => fx_surf,
        };
        for _ in 0..10 {
            let f = |st: &Rigid| rigid_deriv(st, model, fz, fx, &torque, w);
            let k1 = f(&s);
            let k2 = f(&add(&s, &k1, h / 2.0));
            let k3 = f(&add(&s, &k2, h / 2.0));
            let k4 = f(&add(&s, &k3, h));
            s = Rigid {
                pos: s.pos + (k1.pos + 2.0 * k2.pos + 2.0 * k3.pos + k4.pos) * (h / 6.0),
                vel: s.vel + (k1.vel + 2.0 * k2.vel + 2.0 * k3.vel + k4.vel) * (h / 6.0),
                eta: s.eta + (k1.eta + 2.0 * k2.eta + 2.0 * k3.eta + k4.eta) * (h / 6.0),
                omega: s.omega
                    + (k1.omega + 2.0 * k2.omega + 2.0 * k3.omega + k4.omega) * (h / 6.0),
            };
        }
        assert!(s.pos.norm() < 100.0, "{model:?} diverged: {:?}", s.pos);
    }
    s
}

/// At rest on `sp`: within 2 cm, level and still.
fn assert_settled(s: &Rigid, sp: Vector3<f64>) {
    assert!((s.pos - sp).norm() < 0.02, "{:?}", s.pos);
    assert!(
        s.eta.norm() < 0.01 && s.vel.norm() < 0.01,
        "{:?} {:?}",
        s.eta,
        s.vel
    );
}

#[test]
fn paper_section_iv_converges() {
    let sp = Vector3::new(0.0, 0.0, 1.0);
    let s = fly(ModelMode::Paper, 1.0, sp, 60.0);
    assert_settled(&s, sp);
}

#[test]
fn physical_converges_to_an_offset_setpoint_from_a_yawed_start() {
    let sp = Vector3::new(1.0, -1.5, 2.0);
    let s = fly(ModelMode::Physical, 1.0, sp, 40.0);
    assert_settled(&s, sp);
}
