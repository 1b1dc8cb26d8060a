//! Plant self-checks (`PHYSICS.md` §2): trim, free fall, torque-free motion, actuator signs,
//! the inertial form (9) and the input change (33).

use nalgebra::{Matrix3, Vector3};

use super::*;
use crate::model::integrator::rk4_step;

fn hover_input(af: &Airframe) -> PlantInput {
    let w = af.hover_rotor_speed_rad_s();
    PlantInput {
        actuators: ActuatorCommand {
            rotor_speed_rad_s: [w, w],
            ..Default::default()
        },
        ..Default::default()
    }
}

fn inertia(af: &Airframe) -> Matrix3<f64> {
    Matrix3::from_diagonal(&Vector3::from(af.inertia_kg_m2))
}

/// η̈ from the plant: Ω̇ = Ẇ_n η̇ + W_n η̈ (4).
fn euler_accel(s: &PlantState, d: &PlantStateDot) -> Vector3<f64> {
    let eta_dot = d.euler_dot_rad_s;
    s.euler.w_n_inverse() * (d.omega_dot_rad_s2 - s.euler.w_n_dot(&eta_dot) * eta_dot)
}

#[test]
fn hover_trim_has_zero_acceleration() {
    let af = Airframe::default();
    for model in [ModelMode::Paper, ModelMode::Physical] {
        let s = PlantState::at_rest(Vector3::new(0.3, -0.2, 1.0), Euler::new(0.8, 0.0, 0.0));
        let d = derivative(&af, model, &s, &hover_input(&af));
        assert!(
            d.vel_body_dot_m_s2.norm() < 1e-12,
            "{model:?}: {:?}",
            d.vel_body_dot_m_s2
        );
        assert!(d.omega_dot_rad_s2.norm() < 1e-12);
        assert!(d.pos_dot_m_s.norm() < 1e-15 && d.euler_dot_rad_s.norm() < 1e-15);
    }
}

#[test]
fn free_fall_follows_parabola() {
    let af = Airframe::default();
    let v0 = Vector3::new(1.0, -0.5, 2.0);
    let e = Euler::new(0.4, 0.2, -0.3);
    let r = e.rotation_body_to_inertial();
    let mut s = PlantState {
        vel_body_m_s: r.transpose() * v0,
        euler: e,
        ..Default::default()
    };
    let u = PlantInput::default();
    for _ in 0..1000 {
        s = rk4_step(&s, 0.001, |x| derivative(&af, ModelMode::Physical, x, &u));
    }
    let t = 1.0;
    let expect = v0 * t + Vector3::new(0.0, 0.0, -0.5 * af.gravity_m_s2 * t * t);
    assert!((s.pos_m - expect).norm() < 1e-12, "{:?}", s.pos_m - expect);
    assert_eq!(s.euler, e, "no torque, no rotation");
}

#[test]
fn torque_free_spin_conserves_momentum_and_energy() {
    let af = Airframe::default();
    let i = inertia(&af);
    // Spin mostly about z_B (the minor axis, stable) so θ stays clear of ±π/2.
    let mut s = PlantState {
        euler: Euler::new(0.3, 0.1, -0.2),
        omega_body_rad_s: Vector3::new(0.4, -0.3, 4.0),
        ..Default::default()
    };
    let u = PlantInput::default();
    let momentum = |s: &PlantState| s.euler.rotation_body_to_inertial() * (i * s.omega_body_rad_s);
    let energy = |s: &PlantState| 0.5 * s.omega_body_rad_s.dot(&(i * s.omega_body_rad_s));
    let (h0, e0) = (momentum(&s), energy(&s));
    for _ in 0..3000 {
        s = rk4_step(&s, 0.001, |x| derivative(&af, ModelMode::Physical, x, &u));
    }
    assert!(s.euler.psi > 5.0, "it spun: ψ = {}", s.euler.psi);
    assert!(
        (momentum(&s) - h0).norm() / h0.norm() < 1e-9,
        "{:?} vs {h0:?}",
        momentum(&s)
    );
    assert!(((energy(&s) - e0) / e0).abs() < 1e-9);
}

#[test]
fn each_actuator_drives_its_angle_with_the_documented_sign() {
    // [I2]: rotor difference → φ, elevator → θ, differential ailerons → ψ; from rest, level.
    let af = Airframe::default();
    let w = af.hover_rotor_speed_rad_s();
    let s = PlantState::at_rest(Vector3::new(0.0, 0.0, 1.0), Euler::default());
    for model in [ModelMode::Paper, ModelMode::Physical] {
        let eta_dd = |act: ActuatorCommand| {
            let u = PlantInput {
                actuators: act,
                ..Default::default()
            };
            euler_accel(&s, &derivative(&af, model, &s, &u))
        };
        let base = ActuatorCommand {
            rotor_speed_rad_s: [w, w],
            ..Default::default()
        };
        let roll = eta_dd(ActuatorCommand {
            rotor_speed_rad_s: [w + 10.0, w - 10.0],
            ..base
        });
        assert!(roll[2] > 1.0, "rotor 1 faster → φ̈ > 0: {roll:?}");
        assert!(roll[1].abs() < 1e-12);
        let pitch = eta_dd(ActuatorCommand {
            elevator_rad: 0.1,
            ..base
        });
        assert!(
            pitch[1] > 1.0 && pitch[0].abs() < 1e-12 && pitch[2].abs() < 1e-12,
            "{pitch:?}"
        );
        let yaw = eta_dd(ActuatorCommand {
            aileron_left_rad: 0.1,
            aileron_right_rad: -0.1,
            ..base
        });
        assert!(
            yaw[0] > 1.0 && yaw[1].abs() < 1e-12 && yaw[2].abs() < 1e-12,
            "{yaw:?}"
        );
    }
}

#[test]
fn gyroscopic_torque_enters_with_the_sign_of_eq_11() {
    // Equal thrusts impossible with unequal speeds, so isolate Γg: Ix ṗ = l_r (T1 − T2) +
    // I_r q (ω2 − ω1) − qr(Iz − Iy).
    let af = Airframe::default();
    let w = [480.0, 400.0];
    let s = PlantState {
        pos_m: Vector3::new(0.0, 0.0, 1.0),
        omega_body_rad_s: Vector3::new(0.0, 2.0, 0.0),
        ..Default::default()
    };
    let u = PlantInput {
        actuators: ActuatorCommand {
            rotor_speed_rad_s: w,
            ..Default::default()
        },
        ..Default::default()
    };
    let d = derivative(&af, ModelMode::Paper, &s, &u);
    let t = rotors::thrusts_n(&af, &w);
    let gyro = af.rotor_inertia_kg_m2 * 2.0 * (w[1] - w[0]);
    let expect = (af.rotor_arm_m * (t[0] - t[1]) + gyro) / af.inertia_kg_m2[0];
    assert!(gyro < 0.0);
    assert!((d.omega_dot_rad_s2[0] - expect).abs() < 1e-12);
    // And p > 0 gives Γg,y = I_r p (ω1 − ω2) > 0.
    let s = PlantState {
        omega_body_rad_s: Vector3::new(2.0, 0.0, 0.0),
        ..s
    };
    let d = derivative(&af, ModelMode::Paper, &s, &u);
    let expect = af.rotor_inertia_kg_m2 * 2.0 * (w[0] - w[1]) / af.inertia_kg_m2[1];
    assert!(expect > 0.0 && (d.omega_dot_rad_s2[1] - expect).abs() < 1e-12);
}

#[test]
fn body_frame_integration_agrees_with_inertial_form_9() {
    let af = Airframe::default();
    let s = PlantState {
        pos_m: Vector3::new(0.1, 0.2, 1.0),
        vel_body_m_s: Vector3::new(0.3, -0.4, 0.5),
        euler: Euler::new(1.0, 0.15, -0.25),
        omega_body_rad_s: Vector3::new(0.7, -0.2, 0.4),
    };
    let act = ActuatorCommand {
        rotor_speed_rad_s: [470.0, 420.0],
        elevator_rad: 0.12,
        aileron_left_rad: 0.05,
        aileron_right_rad: -0.2,
    };
    for model in [ModelMode::Paper, ModelMode::Physical] {
        let u = PlantInput {
            actuators: act,
            fx_paper_n: 0.37,
            ..Default::default()
        };
        let d = derivative(&af, model, &s, &u);
        // ξ̈ = d/dt (R vᴮ) = R (v̇ᴮ + Ω × vᴮ).
        let r = s.euler.rotation_body_to_inertial();
        let acc = r * (d.vel_body_dot_m_s2 + s.omega_body_rad_s.cross(&s.vel_body_m_s));
        let t = rotors::thrusts_n(&af, &act.rotor_speed_rad_s);
        let fz = t[0] + t[1];
        let fx = match model {
            ModelMode::Paper => u.fx_paper_n,
            ModelMode::Physical => surfaces::force_body_n(&surfaces::lifts(&af, &act)).x,
        };
        let (m, g) = (af.mass_kg, af.gravity_m_s2);
        let Euler { psi, theta, phi } = s.euler;
        let (sps, cps, sth, cth, sph, cph) = (
            psi.sin(),
            psi.cos(),
            theta.sin(),
            theta.cos(),
            phi.sin(),
            phi.cos(),
        );
        // (9) with f_y = 0 and the corrected sign of [I4].
        let expect = Vector3::new(
            cps * cth * fx / m + (sps * sph + cps * sth * cph) * fz / m,
            sps * cth * fx / m + (-cps * sph + sps * sth * cph) * fz / m,
            -sth * fx / m + cth * cph * fz / m - g,
        );
        assert!(
            (acc - expect).norm() < 1e-13,
            "{model:?}: {:?}",
            acc - expect
        );
    }
}

#[test]
fn input_change_33_gives_eta_ddot_equal_to_gamma_tilde() {
    // Γc = I W_n Γ̃ + I Ẇ_n η̇ + Ω × IΩ − Γg − Γq, realised through the §5 mixer with the
    // fixed-point iteration of [I19]; the plant must then give η̈ = Γ̃.
    let af = Airframe::default();
    let i = inertia(&af);
    let euler = Euler::new(1.0, 0.2, -0.15);
    let eta_dot = Vector3::new(0.3, -0.5, 0.8);
    let omega = euler.w_n() * eta_dot;
    let s = PlantState {
        pos_m: Vector3::new(0.0, 0.0, 1.0),
        euler,
        omega_body_rad_s: omega,
        ..Default::default()
    };
    let gamma_tilde = Vector3::new(-0.4, 0.25, 0.6); // (τ̃ψ, τ̃θ, τ̃φ), [I5]
    let fz = af.weight_n() * 1.05;
    for model in [ModelMode::Paper, ModelMode::Physical] {
        let base = i * euler.w_n() * gamma_tilde
            + i * euler.w_n_dot(&eta_dot) * eta_dot
            + omega.cross(&(i * omega));
        let mut w = [af.hover_rotor_speed_rad_s(); 2];
        let mut act = ActuatorCommand::default();
        for _ in 0..8 {
            let drags = rotors::drags_n(&af, &w);
            let gc = base
                - rotors::gyroscopic_torque_body_nm(&af, &omega, &w)
                - rotors::drag_torque_body_nm(&af, model, &drags);
            let t1 = fz / 2.0 + gc.x / (2.0 * af.rotor_arm_m);
            let t2 = fz / 2.0 - gc.x / (2.0 * af.rotor_arm_m);
            w = [
                (t1 / af.k_thrust_n_per_rad2_s2).sqrt(),
                (t2 / af.k_thrust_n_per_rad2_s2).sqrt(),
            ];
            let v1 = af.k_wash_m_per_rad * w[0];
            let v2 = af.k_wash_m_per_rad * w[1];
            let cl = af.lift_slope_per_rad;
            let ve_sq = 0.5 * (v1 * v1 + v2 * v2);
            let de = gc.y / (af.elevator_arm_m * af.k_elevator_kg_m * cl * ve_sq);
            let da = gc.z / (af.aileron_arm_m * af.k_aileron_kg_m * cl * (v1 * v1 + v2 * v2));
            act = ActuatorCommand {
                rotor_speed_rad_s: w,
                elevator_rad: de,
                aileron_left_rad: da,
                aileron_right_rad: -da,
            };
        }
        let u = PlantInput {
            actuators: act,
            ..Default::default()
        };
        let got = euler_accel(&s, &derivative(&af, model, &s, &u));
        assert!(
            (got - gamma_tilde).norm() < 1e-12,
            "{model:?}: {:?}",
            got - gamma_tilde
        );
    }
}

#[test]
/// `paper` mode's wind perturbation: a linear drag, only when the wind is on. (`physical` mode
/// feels the wind through the air-relative velocity of `aero` instead.)
fn wind_drag_only_with_the_wind_perturbation() {
    let af = Airframe::default();
    let s = PlantState {
        pos_m: Vector3::new(0.0, 0.0, 1.0),
        vel_body_m_s: Vector3::new(0.0, 1.0, 0.0),
        ..Default::default()
    };
    let still = derivative(&af, ModelMode::Paper, &s, &hover_input(&af));
    assert!(
        still.vel_body_dot_m_s2.norm() < 1e-12,
        "no drag without the perturbation model"
    );
    let u = PlantInput {
        wind_m_s: Some(Vector3::zeros()),
        ..hover_input(&af)
    };
    let d = derivative(&af, ModelMode::Paper, &s, &u);
    let expect = -af.body_drag_n_s_per_m / af.mass_kg;
    assert!((d.vel_body_dot_m_s2.y - expect).abs() < 1e-12);
    // `physical` ignores the perturbation model: its drag comes in `PlantInput::aero`.
    let d = derivative(&af, ModelMode::Physical, &s, &u);
    assert!(d.vel_body_dot_m_s2.norm() < 1e-12);
    let v = PlantInput {
        aero: aero::loads(&af, &s.vel_body_m_s, &u.actuators.rotor_speed_rad_s),
        ..u
    };
    assert!(
        derivative(&af, ModelMode::Physical, &s, &v)
            .vel_body_dot_m_s2
            .y
            < 0.0
    );
}

/// The vehicle's form of an RK4 step (loads held over the step, the stages' sines and cosines
/// by angle addition from the step's start, ξ̇ by elementary rotations, the update as one
/// weighted sum) against the textbook form of the same equations (`sin_cos` at every stage, R
/// formed and multiplied, the update applied term by term): a 4 s open-loop tumble agrees to
/// rounding.
#[test]
fn fast_step_matches_textbook_rk4() {
    let af = Airframe::default();
    let body = RigidBody::new(&af);
    let w = af.hover_rotor_speed_rad_s();
    let h = 0.001;
    for model in [ModelMode::Paper, ModelMode::Physical] {
        let u = PlantInput {
            actuators: ActuatorCommand {
                rotor_speed_rad_s: [w * 1.0004, w * 0.9996],
                elevator_rad: 0.01,
                aileron_left_rad: 0.01,
                aileron_right_rad: -0.005,
            },
            fx_paper_n: 0.01,
            disturbance_torque_body_nm: Vector3::new(0.0, 0.0, 0.0004),
            ..Default::default()
        };
        let textbook = |x: &PlantState| {
            let f = |s: &PlantState| derivative(&af, model, s, &u);
            let k1 = f(x);
            let k2 = f(&x.advanced(&k1, 0.5 * h));
            let k3 = f(&x.advanced(&k2, 0.5 * h));
            let k4 = f(&x.advanced(&k3, h));
            x.advanced(&k1, h / 6.0)
                .advanced(&k2, h / 3.0)
                .advanced(&k3, h / 3.0)
                .advanced(&k4, h / 6.0)
        };
        let s0 = PlantState {
            pos_m: Vector3::new(0.1, -0.2, 1.0),
            vel_body_m_s: Vector3::new(0.2, 0.1, -0.1),
            euler: Euler::new(1.0, 0.1, -0.1),
            omega_body_rad_s: Vector3::new(0.3, -0.2, 0.5),
        };
        let (mut fast, mut slow) = (s0, s0);
        let mut trig = EulerTrig::new(&s0.euler);
        let held = HeldLoads::new(&af, model, &u);
        for step in 1..=4000 {
            let (start, start_trig) = (fast.euler, trig);
            let mut first_stage = true;
            fast = rk4_step(&fast, h, |s| {
                let t = if first_stage {
                    first_stage = false;
                    start_trig
                } else {
                    start_trig.shifted(&start, &s.euler)
                };
                derivative_held(&af, &body, s, &held, &t)
            });
            // As the vehicle: exact once per control period, by angle addition in between.
            trig = if step % 10 == 0 {
                EulerTrig::new(&fast.euler)
            } else {
                start_trig.shifted(&start, &fast.euler)
            };
            slow = textbook(&slow);
        }
        let moved = (slow.euler.psi - s0.euler.psi).abs()
            + (slow.euler.theta - s0.euler.theta).abs()
            + (slow.euler.phi - s0.euler.phi).abs();
        assert!(
            moved > 1.0 && slow.euler.theta.abs() < 1.2,
            "{model:?}: {slow:?}"
        );
        let d_pos = (fast.pos_m - slow.pos_m).amax();
        let d_vel = (fast.vel_body_m_s - slow.vel_body_m_s).amax();
        let d_eta = Vector3::new(
            fast.euler.psi - slow.euler.psi,
            fast.euler.theta - slow.euler.theta,
            fast.euler.phi - slow.euler.phi,
        )
        .amax();
        let d_omega = (fast.omega_body_rad_s - slow.omega_body_rad_s).amax();
        assert!(
            d_pos < 1e-11 && d_vel < 1e-11 && d_eta < 1e-12 && d_omega < 1e-12,
            "{model:?}: ξ {d_pos:e} m, v {d_vel:e} m/s, η {d_eta:e} rad, Ω {d_omega:e} rad/s"
        );
    }
}
