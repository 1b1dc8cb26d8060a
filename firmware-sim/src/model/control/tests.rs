//! Controller-level tests: gain validation, the whole tick against its bounds for random inputs,
//! the input change through `update`, the flight-mode behaviours, and closed loops of the
//! paper's Section IV on an ideal rigid-body plant written here from `PHYSICS.md` §2 (so a sign
//! error in the controller shows up as divergence, independently of the project's plant).

use nalgebra::{Matrix3, Vector3};
use proptest::prelude::*;
use proptest::test_runner::{Config as ProptestConfig, RngSeed};

use super::input_change::{gyroscopic_torque_nm, inertia_matrix, rotor_drag_torque_nm};
use super::mixer::forces_from_actuators;
use super::*;

fn hover_input(mode: FlightMode) -> ControlInput {
    let w = Airframe::default().hover_rotor_speed_rad_s();
    ControlInput {
        dt_s: 0.01,
        mode,
        pos_m: Vector3::new(0.0, 0.0, 1.0),
        setpoint_m: Vector3::new(0.0, 0.0, 1.0),
        rotor_speed_rad_s: [w, w],
        pilot: PilotInput {
            throttle: 0.5,
            ..PilotInput::default()
        },
        ..ControlInput::default()
    }
}

fn controller(model: ModelMode) -> Controller {
    Controller::new(Airframe::default(), model)
}

const MODELS: [ModelMode; 2] = [ModelMode::Paper, ModelMode::Physical];

// ---------------------------------------------------------------------------------------------
// Gain validation

#[test]
fn default_gains_are_valid() {
    assert_eq!(Gains::default().validate(), Ok(()));
}

#[test]
fn each_saturation_condition_is_refused_with_its_name() {
    let cases = [
        (
            SaturationLevels {
                a: 1.0,
                b: 0.6,
                c: 0.22,
                d: 0.18,
            },
            "a > b + c + d",
        ),
        (
            SaturationLevels {
                a: 1.2,
                b: 0.4,
                c: 0.22,
                d: 0.18,
            },
            "b > c + d",
        ),
        (
            SaturationLevels {
                a: 1.2,
                b: 0.6,
                c: 0.18,
                d: 0.18,
            },
            "c > d",
        ),
        (
            SaturationLevels {
                a: 1.2,
                b: 0.6,
                c: 0.22,
                d: 0.0,
            },
            "d > 0",
        ),
        (
            SaturationLevels {
                a: f64::NAN,
                b: 0.6,
                c: 0.22,
                d: 0.18,
            },
            "all levels finite",
        ),
        (
            SaturationLevels {
                a: 1.2,
                b: 0.6,
                c: f64::INFINITY,
                d: 0.18,
            },
            "all levels finite",
        ),
    ];
    for (levels, expected) in cases {
        let gains = Gains {
            longitudinal: levels,
            ..Gains::default()
        };
        let err = gains.validate().expect_err("must be refused");
        match &err {
            GainError::SaturationConditions {
                chain, condition, ..
            } => {
                assert_eq!(*chain, "LON_SAT");
                assert_eq!(*condition, expected);
            }
            other => panic!("wrong error {other:?}"),
        }
        let msg = err.to_string();
        assert!(msg.contains("LON_SAT") && msg.contains(expected), "{msg}");
    }
    let gains = Gains {
        lateral: SaturationLevels {
            a: 1.2,
            b: 0.6,
            c: 0.3,
            d: 0.4,
        },
        ..Gains::default()
    };
    let msg = gains.validate().unwrap_err().to_string();
    assert!(
        msg.starts_with("LAT_SAT levels a=1.2, b=0.6, c=0.3, d=0.4"),
        "{msg}"
    );
    assert!(
        msg.ends_with("break the saturation condition c > d"),
        "{msg}"
    );
}

#[test]
fn linear_gains_must_be_positive_and_finite() {
    for (gains, name) in [
        (
            Gains {
                alt_kd: 0.0,
                ..Gains::default()
            },
            "ALT_KD",
        ),
        (
            Gains {
                alt_kp: f64::NAN,
                ..Gains::default()
            },
            "ALT_KP",
        ),
        (
            Gains {
                yaw_kd: -1.0,
                ..Gains::default()
            },
            "YAW_KD",
        ),
        (
            Gains {
                yaw_kp: f64::INFINITY,
                ..Gains::default()
            },
            "YAW_KP",
        ),
        (
            Gains {
                land_speed_m_s: 0.0,
                ..Gains::default()
            },
            "LAND_SPEED",
        ),
        (
            Gains {
                hover_alt_m: -1.0,
                ..Gains::default()
            },
            "HOVER_ALT",
        ),
    ] {
        let err = gains.validate().expect_err(name);
        assert!(
            matches!(err, GainError::NotPositive { name: n, .. } if n == name),
            "{err:?}"
        );
        assert!(
            err.to_string()
                .starts_with(&format!("{name} must be positive and finite"))
        );
    }
}

proptest! {
    #![proptest_config(ProptestConfig {
        cases: 512,
        rng_seed: RngSeed::Fixed(0x6A1E5),
        failure_persistence: None,
        ..ProptestConfig::default()
    })]

    /// `validate` accepts exactly the level sets satisfying the proof's hypotheses.
    #[test]
    fn validation_matches_the_hypotheses(l in proptest::array::uniform4(-0.5..2.0f64)) {
        let [a, b, c, d] = l;
        let levels = SaturationLevels { a, b, c, d };
        let ok = a > b + c + d && b > c + d && c > d && d > 0.0;
        prop_assert_eq!(levels.validate("LAT_SAT").is_ok(), ok);
    }
}

// ---------------------------------------------------------------------------------------------
// Bounds and finiteness for random inputs

fn any_mode() -> impl Strategy<Value = FlightMode> {
    prop::sample::select(FlightMode::ALL.to_vec())
}

fn wide() -> impl Strategy<Value = f64> {
    prop_oneof![
        6 => -5.0..5.0f64,
        3 => -1e3..1e3f64,
        1 => prop::num::f64::NORMAL | prop::num::f64::ZERO,
    ]
}

fn wide3() -> impl Strategy<Value = Vector3<f64>> {
    (wide(), wide(), wide()).prop_map(|(x, y, z)| Vector3::new(x, y, z))
}

prop_compose! {
    fn any_input()(
        mode in any_mode(),
        dt in prop_oneof![Just(0.01), 0.0..1.0f64],
        angles in (wide(), wide(), wide()),
        omega in wide3(),
        pos in wide3(),
        vel in wide3(),
        setpoint in wide3(),
        yaw_sp in wide(),
        rotors in (0.0..2000.0f64, 0.0..2000.0f64),
        pilot in (wide(), wide(), wide(), wide()),
    ) -> ControlInput {
        ControlInput {
            dt_s: dt,
            mode,
            euler: Euler::new(angles.0, angles.1, angles.2),
            omega_body_rad_s: omega,
            pos_m: pos,
            vel_m_s: vel,
            setpoint_m: setpoint,
            yaw_setpoint_rad: yaw_sp,
            rotor_speed_rad_s: [rotors.0, rotors.1],
            pilot: PilotInput { throttle: pilot.0, roll: pilot.1, pitch: pilot.2, yaw: pilot.3 },
        }
    }
}

fn check_output(out: &ControlOutput, gains: &Gains, model: ModelMode) -> Result<(), TestCaseError> {
    let a = Airframe::default();
    let lat = gains.lateral;
    let lon = gains.longitudinal;
    prop_assert!(out.tau_tilde.iter().all(|v| v.is_finite()), "{out:?}");
    // `physical` mode's position modes fly the hover hold: its law plus its integrator.
    let hold = match model {
        ModelMode::Paper => 0.0,
        ModelMode::Physical => 1.5 * gains.hover.att_acc_rad_s2,
    };
    prop_assert!(
        out.tau_tilde[2].abs() <= (lat.a + lat.b + lat.c + lat.d).max(hold) + 1e-12,
        "τ̃φ {out:?}"
    );
    prop_assert!(
        out.tau_tilde[1].abs() <= (lon.a + lon.b + lon.c + lon.d).max(hold) + 1e-12,
        "τ̃θ {out:?}"
    );
    prop_assert!(out.torque_body_nm.iter().all(|v| v.is_finite()), "{out:?}");
    prop_assert!(out.fz_n.is_finite() && out.fx_n.is_finite(), "{out:?}");
    let act = &out.actuators;
    let all = [
        act.rotor_speed_rad_s[0],
        act.rotor_speed_rad_s[1],
        act.elevator_rad,
        act.aileron_left_rad,
        act.aileron_right_rad,
    ];
    prop_assert!(all.iter().all(|v| v.is_finite()), "{act:?}");
    prop_assert!(act.rotor_speed_rad_s.iter().all(|w| *w >= 0.0), "{act:?}");
    prop_assert!(
        out.pwm_us.iter().all(|p| (1000..=2000).contains(p)),
        "{:?}",
        out.pwm_us
    );
    if model == ModelMode::Physical {
        let fz_max = 2.0 * a.k_thrust_n_per_rad2_s2 * a.rotor_speed_max_rad_s.powi(2);
        prop_assert!(out.fz_n >= 0.0 && out.fz_n <= fz_max + 1e-9, "{out:?}");
        prop_assert!(
            act.rotor_speed_rad_s
                .iter()
                .all(|w| *w <= a.rotor_speed_max_rad_s)
        );
        prop_assert!(
            all[2..].iter().all(|d| d.abs() <= a.surface_limit_rad),
            "{act:?}"
        );
        prop_assert!(out.fx_n == 0.0);
    }
    Ok(())
}

proptest! {
    #![proptest_config(ProptestConfig {
        cases: 1024,
        rng_seed: RngSeed::Fixed(0x0B0D5),
        failure_persistence: None,
        ..ProptestConfig::default()
    })]

    /// Every τ̃ within its chain's bound, every output finite, every PWM in 1000–2000 µs, for
    /// any finite input in every mode and both models (and over a few consecutive ticks, so the
    /// internal state is exercised too).
    #[test]
    fn outputs_bounded_and_finite(inputs in proptest::collection::vec(any_input(), 1..4)) {
        let gains = Gains::default();
        for model in MODELS {
            let mut c = controller(model);
            for input in &inputs {
                let out = c.update(input, &gains);
                check_output(&out, &gains, model)?;
            }
        }
    }
}

#[test]
fn non_finite_and_extreme_inputs_stay_finite() {
    let gains = Gains::default();
    let weird = [
        f64::NAN,
        f64::INFINITY,
        f64::NEG_INFINITY,
        f64::MAX,
        f64::MIN,
        1e-300,
    ];
    for model in MODELS {
        for mode in FlightMode::ALL {
            for &v in &weird {
                let mut c = controller(model);
                let input = ControlInput {
                    dt_s: v,
                    mode,
                    euler: Euler::new(v, v, v),
                    omega_body_rad_s: Vector3::repeat(v),
                    pos_m: Vector3::repeat(v),
                    vel_m_s: Vector3::new(v, -v, v),
                    setpoint_m: Vector3::repeat(-v),
                    yaw_setpoint_rad: v,
                    rotor_speed_rad_s: [v, v],
                    pilot: PilotInput {
                        throttle: v,
                        roll: v,
                        pitch: v,
                        yaw: v,
                    },
                };
                let out = c.update(&input, &gains);
                let r = check_output(&out, &gains, model);
                assert!(r.is_ok(), "{model:?} {mode:?} {v}: {r:?}");
            }
        }
    }
}

// ---------------------------------------------------------------------------------------------
// Input change through the whole tick

/// η̈ from Euler's equation (13) with the corrected signs, using the frames helpers.
fn eta_ddot(
    model: ModelMode,
    euler: &Euler,
    omega: &Vector3<f64>,
    torque_c: &Vector3<f64>,
    rotor_speed: [f64; 2],
) -> Vector3<f64> {
    let a = Airframe::default();
    let i = inertia_matrix(&a);
    let total = torque_c
        + gyroscopic_torque_nm(a.rotor_inertia_kg_m2, omega, rotor_speed)
        + rotor_drag_torque_nm(&a, model, rotor_speed)
        - omega.cross(&(i * omega));
    let omega_dot = Matrix3::from_diagonal(&i.diagonal().map(|v| 1.0 / v)) * total;
    let eta_dot = euler.rates_from_body(omega);
    euler.w_n_inverse() * (omega_dot - euler.w_n_dot(&eta_dot) * eta_dot)
}

proptest! {
    #![proptest_config(ProptestConfig {
        cases: 256,
        rng_seed: RngSeed::Fixed(0x33),
        failure_persistence: None,
        ..ProptestConfig::default()
    })]

    /// With the torques and rotor speeds `update` commands (nothing saturated), Euler's
    /// equation yields η̈ = Γ̃ to 1e-9 relative, in every mode and both models.
    #[test]
    fn update_makes_eta_ddot_equal_tau_tilde(
        mode in any_mode(),
        angles in (-3.0..3.0f64, -0.4..0.4f64, -0.4..0.4f64),
        omega in proptest::array::uniform3(-1.5..1.5f64),
        pos in proptest::array::uniform3(-1.0..1.0f64),
        vel in proptest::array::uniform3(-0.5..0.5f64),
        rotors in (300.0..550.0f64, 300.0..550.0f64),
        pilot in proptest::array::uniform3(-1.0..1.0f64),
    ) {
        let euler = Euler::new(angles.0, angles.1, angles.2);
        let omega = Vector3::from(omega);
        let input = ControlInput {
            dt_s: 0.01,
            mode,
            euler,
            omega_body_rad_s: omega,
            pos_m: Vector3::new(pos[0], pos[1], 1.0 + pos[2]),
            vel_m_s: Vector3::from(vel),
            setpoint_m: Vector3::new(0.0, 0.0, 1.0),
            yaw_setpoint_rad: 0.3,
            rotor_speed_rad_s: [rotors.0, rotors.1],
            pilot: PilotInput { throttle: 0.46, roll: pilot[0], pitch: pilot[1], yaw: pilot[2] },
        };
        for model in MODELS {
            let out = controller(model).update(&input, &Gains::default());
            let act = &out.actuators;
            let a = Airframe::default();
            prop_assume!(act.rotor_speed_rad_s.iter().all(|w| *w > 1.0 && *w < a.rotor_speed_max_rad_s));
            // `physical`: the plant adds the aerodynamic moment the controller cancels (at the
            // velocity and rotor speeds it was given).
            let aero = match model {
                ModelMode::Paper => Vector3::zeros(),
                ModelMode::Physical => {
                    let v_body = euler.rotation_body_to_inertial().tr_mul(&input.vel_m_s);
                    crate::model::plant::aero::loads(&a, &v_body, &input.rotor_speed_rad_s)
                        .torque_body_nm
                }
            };
            let edd = eta_ddot(
                model,
                &euler,
                &omega,
                &(out.torque_body_nm + aero),
                act.rotor_speed_rad_s,
            );
            // Relative: the hover hold's budgets reach 36 rad/s², where the fixed point of
            // [I19] settles to a few 1e-11 of the value.
            prop_assert!(
                (edd - out.tau_tilde).norm() < 1e-9 * (1.0 + out.tau_tilde.norm()),
                "{model:?}: {edd} vs {}",
                out.tau_tilde
            );
            // And the commanded actuators really produce Γc and f_z (§5 force model).
            let (fz, tq, _) = forces_from_actuators(&a, act);
            prop_assume!([act.elevator_rad, act.aileron_left_rad].iter().all(|d| d.abs() < a.surface_limit_rad));
            prop_assert!((fz - out.fz_n).abs() < 1e-9 && (tq - out.torque_body_nm).norm() < 1e-9);
        }
    }
}

// ---------------------------------------------------------------------------------------------
// Flight modes

#[test]
fn qstabilize_throttle_maps_to_thrust() {
    let a = Airframe::default();
    let fz_max = 2.0 * a.k_thrust_n_per_rad2_s2 * a.rotor_speed_max_rad_s.powi(2);
    for model in MODELS {
        let mut c = controller(model);
        for (throttle, expect) in [
            (0.0, 0.0),
            (0.5, 0.5 * fz_max),
            (1.0, fz_max),
            (1.7, fz_max),
        ] {
            let mut input = hover_input(FlightMode::QStabilize);
            input.pilot.throttle = throttle;
            let out = c.update(&input, &Gains::default());
            assert!(
                (out.fz_n - expect).abs() < 1e-12,
                "{model:?} {throttle}: {}",
                out.fz_n
            );
        }
        // Hover throttle ≈ 0.46, ESC ≈ 1681 µs.
        let mut input = hover_input(FlightMode::QStabilize);
        input.pilot.throttle = a.weight_n() / fz_max;
        let out = c.update(&input, &Gains::default());
        assert!((input.pilot.throttle - 0.464).abs() < 1e-3);
        assert!((out.fz_n - a.weight_n()).abs() < 1e-12);
        assert_eq!(out.pwm_us, [1681, 1681, 1500, 1500, 1500]);
    }
}

#[test]
fn attitude_modes_follow_the_sticks() {
    for model in MODELS {
        for mode in [FlightMode::QStabilize, FlightMode::QHover] {
            let mut c = controller(model);
            // Sticks centred and level: no angular command.
            let out = c.update(&hover_input(mode), &Gains::default());
            assert!(out.tau_tilde.norm() < 1e-12, "{mode:?} {}", out.tau_tilde);
            // Full right roll and forward pitch: φ̈ > 0 and θ̈ > 0 toward the 0.35 rad setpoints.
            let mut input = hover_input(mode);
            input.pilot.roll = 1.0;
            input.pilot.pitch = 1.0;
            let out = c.update(&input, &Gains::default());
            assert!(
                out.tau_tilde[2] > 0.0 && out.tau_tilde[1] > 0.0,
                "{}",
                out.tau_tilde
            );
            // At the setpoint, at rest: nothing more.
            input.euler = Euler::new(0.0, PILOT_TILT_MAX_RAD, PILOT_TILT_MAX_RAD);
            let out = c.update(&input, &Gains::default());
            assert!(out.tau_tilde[1].abs() < 1e-12 && out.tau_tilde[2].abs() < 1e-12);
            // Position errors are ignored (x/y not held).
            let mut input = hover_input(mode);
            input.pos_m.x = 5.0;
            input.pos_m.y = -3.0;
            let out = c.update(&input, &Gains::default());
            assert!(out.tau_tilde.norm() < 1e-12);
        }
    }
}

#[test]
fn qhover_holds_hover_alt_not_the_setpoint() {
    let gains = Gains {
        hover_alt_m: 2.5,
        ..Gains::default()
    };
    let a = Airframe::default();
    for model in MODELS {
        let mut c = controller(model);
        let mut input = hover_input(FlightMode::QHover);
        input.pos_m.z = 2.5;
        input.setpoint_m.z = 7.0;
        let out = c.update(&input, &gains);
        assert!((out.fz_n - a.weight_n()).abs() < 1e-12, "{}", out.fz_n);
        input.pos_m.z = 1.5;
        let out = c.update(&input, &gains);
        // r_z = −a_z2 (z − z_d) = 5 m/s².
        assert!(
            (out.fz_n - a.mass_kg * (5.0 + a.gravity_m_s2)).abs() < 1e-12,
            "{}",
            out.fz_n
        );
        // QLOITER flies to the setpoint's z instead.
        input.mode = FlightMode::QLoiter;
        input.pos_m.z = 7.0;
        let out = c.update(&input, &gains);
        assert!((out.fz_n - a.weight_n()).abs() < 1e-12);
    }
}

#[test]
fn qland_descends_and_holds_the_entry_position() {
    let a = Airframe::default();
    let gains = Gains::default();
    for model in MODELS {
        let mut c = controller(model);
        let mut input = hover_input(FlightMode::QLoiter);
        input.pos_m = Vector3::new(2.0, -1.0, 3.0);
        input.setpoint_m = input.pos_m;
        let _ = c.update(&input, &gains);
        input.mode = FlightMode::QLand;
        let out = c.update(&input, &gains);
        assert_eq!(c.land_hold_xy_m(), Some(nalgebra::Vector2::new(2.0, -1.0)));
        // At rest: thrust below weight, r_z = −a_z1 v_land.
        let expect = a.mass_kg * (a.gravity_m_s2 - gains.alt_kd * gains.land_speed_m_s);
        assert!((out.fz_n - expect).abs() < 1e-12 && out.fz_n < a.weight_n());
        // Descending at land speed: back to hover thrust, whatever the altitude.
        input.vel_m_s.z = -gains.land_speed_m_s;
        input.pos_m.z = 0.3;
        let out = c.update(&input, &gains);
        assert!((out.fz_n - a.weight_n()).abs() < 1e-12);
        // The position setpoint moving away does not matter: QLAND holds where it began.
        input.setpoint_m = Vector3::new(50.0, 50.0, 10.0);
        let out = c.update(&input, &gains);
        assert!(out.tau_tilde[1].abs() < 1e-12 && out.tau_tilde[2].abs() < 1e-12);
        // Drifting off the hold point is corrected (in +y: roll toward −y needs φ̈ > 0).
        input.pos_m.y = -0.5;
        let out = c.update(&input, &gains);
        assert!(out.tau_tilde[2] > 0.0);
        // Leaving QLAND drops the hold; re-entering captures the new position.
        input.mode = FlightMode::QHover;
        let _ = c.update(&input, &gains);
        assert_eq!(c.land_hold_xy_m(), None);
        input.mode = FlightMode::QLand;
        let _ = c.update(&input, &gains);
        assert_eq!(c.land_hold_xy_m(), Some(nalgebra::Vector2::new(2.0, -0.5)));
        c.reset();
        assert_eq!(c.land_hold_xy_m(), None);
    }
}

#[test]
fn yaw_stick_moves_the_heading_target_on_a_leash() {
    let gains = Gains::default();
    let mut c = controller(ModelMode::Physical);
    let mut input = hover_input(FlightMode::QStabilize);
    input.yaw_setpoint_rad = 0.2;
    input.euler.psi = 0.2;
    let _ = c.update(&input, &gains);
    assert!((c.yaw_target_rad() - 0.2).abs() < 1e-12);
    input.pilot.yaw = 1.0;
    for _ in 0..10 {
        let _ = c.update(&input, &gains);
    }
    // 10 ticks of 10 ms at 1 rad/s.
    assert!(
        (c.yaw_target_rad() - 0.3).abs() < 1e-9,
        "{}",
        c.yaw_target_rad()
    );
    for _ in 0..200 {
        let _ = c.update(&input, &gains);
    }
    // The vehicle did not turn: the target stops at the leash.
    assert!((c.yaw_target_rad() - (0.2 + YAW_LEASH_RAD)).abs() < 1e-9);
    // QLOITER uses the input's setpoint exactly.
    input.mode = FlightMode::QLoiter;
    let out = c.update(&input, &gains);
    assert!((c.yaw_target_rad() - 0.2).abs() < 1e-12);
    assert!(out.tau_tilde[0].abs() < 1e-12);
}

#[test]
fn physical_chains_act_in_the_heading_frame() {
    let gains = Gains::default();
    // Heading ψ = π/2 (nose-x along inertial +y). An inertial +y error is a heading-frame +x
    // error: the pitch chain must respond (θ̈ < 0), the roll chain must not.
    let mut input = hover_input(FlightMode::QLoiter);
    input.euler.psi = std::f64::consts::FRAC_PI_2;
    input.yaw_setpoint_rad = input.euler.psi;
    input.pos_m.y = 0.5;
    let out = controller(ModelMode::Physical).update(&input, &gains);
    assert!(
        out.tau_tilde[1] < 0.0 && out.tau_tilde[2].abs() < 1e-12,
        "{}",
        out.tau_tilde
    );
    // `paper` mode: exactly the paper's decoupled law, no rotation.
    let out = controller(ModelMode::Paper).update(&input, &gains);
    assert!(
        out.tau_tilde[2] > 0.0 && out.tau_tilde[1].abs() < 1e-12,
        "{}",
        out.tau_tilde
    );
}

#[test]
fn a_boundary_set_that_equals_in_exact_arithmetic_is_refused_in_float32() {
    // b = c + d typed as float32 parameters (0.22 + 0.18 = 0.4) must not slip through rounding.
    let f = |v: f32| f64::from(v);
    let levels = SaturationLevels {
        a: 1.2,
        b: f(0.4),
        c: f(0.22),
        d: f(0.18),
    };
    let err = levels.validate("LAT_SAT").unwrap_err();
    assert!(err.to_string().contains("b > c + d"), "{err}");
    let levels = SaturationLevels {
        a: f(1.0),
        b: f(0.55),
        c: f(0.25),
        d: f(0.2),
    };
    assert!(
        levels
            .validate("LON_SAT")
            .unwrap_err()
            .to_string()
            .contains("a > b + c + d")
    );
}
