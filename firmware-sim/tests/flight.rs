//! Closed-loop flights of the whole twin (plant, sensors, estimator, controller) and the
//! `simulate` command line. Seeded and in fast time: no sleeps.

use firmware_sim::model::vehicle::{InitialState, PHYSICS_DT_S, SystemState, Telemetry};
use firmware_sim::{Euler, FlightMode, ModelMode, Vehicle, VehicleConfig};
use nalgebra::Vector3;

/// The initial conditions of Section IV ([I10]).
fn paper_initial() -> InitialState {
    InitialState {
        pos_m: Vector3::new(0.1, 0.1, 0.1),
        euler: Euler::new(1.0, 0.1, 0.1),
    }
}

fn flying(model: ModelMode, seed: u64) -> Vehicle {
    let mut v = Vehicle::new(VehicleConfig {
        model,
        seed,
        initial: paper_initial(),
        mode: FlightMode::QLoiter,
        armed: true,
        ..VehicleConfig::default()
    });
    v.set_position_setpoint(Vector3::new(0.0, 0.0, 1.0));
    v
}

/// Steps until `t_s`, calling `each` after every step.
fn fly_until(v: &mut Vehicle, t_s: f64, mut each: impl FnMut(&Telemetry)) {
    while v.time_s() < t_s - 0.5 * PHYSICS_DT_S {
        v.step();
        each(v.telemetry());
    }
}

/// ψ(t) of ψ̈ = −5ψ̇ − 5ψ, ψ(0) = 1, ψ̇(0) = 0 (the yaw law (45) with a_ψ1 = a_ψ2 = 5).
fn psi_closed_form(t: f64) -> f64 {
    let r1 = (-5.0 + 5.0_f64.sqrt()) / 2.0;
    let r2 = (-5.0 - 5.0_f64.sqrt()) / 2.0;
    (r2 * (r1 * t).exp() - r1 * (r2 * t).exp()) / (r2 - r1)
}

#[test]
fn paper_mode_reproduces_section_iv() {
    let mut v = flying(ModelMode::Paper, 1);
    let mut worst_psi = 0.0_f64;
    fly_until(&mut v, 25.0, |t| {
        let time = t.t_us as f64 * 1e-6;
        worst_psi = worst_psi.max((t.euler.psi - psi_closed_form(time)).abs());
    });
    let t = v.telemetry();
    let err = (t.pos_m - Vector3::new(0.0, 0.0, 1.0)).norm();
    assert!(
        err < 0.01,
        "position error at 25 s: {err} m ({:?})",
        t.pos_m
    );
    // The controller runs at 100 Hz with a zero-order hold, the closed form is continuous.
    assert!(
        worst_psi < 5e-3,
        "ψ departs from the closed form by {worst_psi} rad"
    );
    assert_eq!(t.state, SystemState::Active);
}

/// The paper's flight with a physics step of `dt_us`: the trajectory sampled every 10 ms.
fn paper_trajectory(dt_us: u64) -> Vec<Vector3<f64>> {
    let mut v = Vehicle::new(VehicleConfig {
        physics_dt_us: dt_us,
        ..flying(ModelMode::Paper, 1).config().clone()
    });
    v.set_position_setpoint(Vector3::new(0.0, 0.0, 1.0));
    let mut out = vec![v.telemetry().pos_m];
    let every = 10_000 / dt_us;
    let mut k = 0;
    fly_until(&mut v, 25.0, |t| {
        k += 1;
        if k % every == 0 {
            out.push(t.pos_m);
        }
    });
    out
}

#[test]
fn paper_mode_is_continuous_time_halving_the_step_moves_it_less_than_a_millimetre() {
    let a = paper_trajectory(1000);
    let b = paper_trajectory(500);
    assert_eq!(a.len(), b.len());
    let worst = a
        .iter()
        .zip(&b)
        .map(|(p, q)| (p - q).norm())
        .fold(0.0_f64, f64::max);
    assert!(worst < 1e-3, "25 s trajectories differ by up to {worst} m");
}

#[test]
fn paper_mode_first_row_carries_the_controllers_output_at_t0() {
    use firmware_sim::model::control::{ControlInput, Controller, Gains};
    let v = flying(ModelMode::Paper, 1);
    let t = v.telemetry();
    let mut c = Controller::new(firmware_sim::Airframe::default(), ModelMode::Paper);
    let expect = c.update(
        &ControlInput {
            dt_s: v.physics_dt_s(),
            mode: FlightMode::QLoiter,
            euler: paper_initial().euler,
            pos_m: paper_initial().pos_m,
            setpoint_m: Vector3::new(0.0, 0.0, 1.0),
            ..ControlInput::default()
        },
        &Gains::default(),
    );
    assert_eq!(t.t_us, 0);
    assert_eq!(t.control.tau_tilde, expect.tau_tilde);
    assert_eq!(t.control.fz_n, expect.fz_n);
    // τ̃ψ(0) = −a_ψ2 ψ0 = −5 (45): the row is not the idle output.
    assert!((t.control.tau_tilde[0] + 5.0).abs() < 1e-12);
    assert!(t.pwm_us[0] > 1000);
}

#[test]
fn physical_mode_with_noise_converges_then_holds() {
    let mut v = flying(ModelMode::Physical, 1);
    fly_until(&mut v, 25.0, |_| {});
    let (mut pos, mut tilt, mut psi) = (0.0_f64, 0.0_f64, 0.0_f64);
    fly_until(&mut v, 60.0, |t| {
        pos = pos.max((t.pos_m - Vector3::new(0.0, 0.0, 1.0)).amax());
        tilt = tilt.max(t.euler.phi.abs()).max(t.euler.theta.abs());
        psi = psi.max(t.euler.psi.abs());
    });
    assert!(pos < 0.03, "position band ±{pos} m over 25–60 s");
    assert!(
        tilt < 1f64.to_radians(),
        "tilt band ±{}°",
        tilt.to_degrees()
    );
    // Yaw has no absolute reference (gyro only): it may drift by the calibration residual.
    assert!(
        psi < 5f64.to_radians(),
        "heading drift {}°",
        psi.to_degrees()
    );
}

#[test]
fn physical_mode_with_ideal_sensors_settles_without_a_limit_cycle() {
    // Servo PWM comes in 1 µs steps (≈ 1 mrad of elevator). Rounded plainly, that step kept
    // the x chain in a ±9 cm limit cycle; the firmware dithers the rounding error instead.
    let mut v = Vehicle::new(VehicleConfig {
        ideal_sensors: true,
        ..flying(ModelMode::Physical, 1).config().clone()
    });
    v.set_position_setpoint(Vector3::new(0.0, 0.0, 1.0));
    fly_until(&mut v, 30.0, |_| {});
    let mut pos = 0.0_f64;
    fly_until(&mut v, 60.0, |t| {
        pos = pos.max((t.pos_m - Vector3::new(0.0, 0.0, 1.0)).amax());
    });
    assert!(
        pos < 0.005,
        "position band ±{pos} m over 30–60 s with ideal sensors"
    );
}

/// Hovering at (0, 0, 1) m in QLOITER from 10 s, `push` applied at 12 s for 200 ms; the largest
/// horizontal distance from the point over the next 20 s, and the state at the end.
fn qloiter_push_excursion(push_body_nm: Vector3<f64>) -> (f64, Telemetry) {
    let mut v = flying(ModelMode::Physical, 5);
    fly_until(&mut v, 12.0, |_| {});
    v.push(push_body_nm, 0.2);
    let mut worst = 0.0_f64;
    fly_until(&mut v, 32.0, |t| worst = worst.max(t.pos_m.xy().norm()));
    (worst, *v.telemetry())
}

/// The acceptance: in QLOITER a 0.1 N·m roll push moves the vehicle at most 1 m (the
/// hover hold, docs/model.md); pitch too, and it comes back onto its point.
#[test]
fn qloiter_push_of_a_tenth_newton_metre_moves_it_less_than_a_metre() {
    for (axis, push) in [
        ("roll", Vector3::new(0.1, 0.0, 0.0)),
        ("pitch", Vector3::new(0.0, 0.1, 0.0)),
    ] {
        let (worst, end) = qloiter_push_excursion(push);
        assert!(worst < 1.0, "{axis} push: {worst} m");
        assert!(
            end.pos_m.xy().norm() < 0.05,
            "{axis}: back at {}",
            end.pos_m
        );
        assert_eq!(end.state, SystemState::Active);
    }
}

/// A gusty wind (0.5 m/s gusts, seeded) arriving while the vehicle hovers: the hold leans into
/// it, learns it and keeps the vehicle near its point (docs/model.md, "Hover position hold").
/// 2 m/s on the plate's face and along its span, and 3 m/s along its span; 3 m/s on the face
/// needs a 34° lean, beyond `Q_ANGLE_MAX` (30°).
#[test]
fn qloiter_holds_its_point_in_a_gusty_wind() {
    for (wind, edge, radius) in [
        // The step onset of the wind carries it furthest: 1.7–2.5 m on the face, where the
        // drag is four times the edgewise one.
        (Vector3::new(2.0, 0.0, 0.0), "2 m/s broadside", 3.0),
        (Vector3::new(0.0, 2.0, 0.0), "2 m/s edgewise", 1.5),
        (Vector3::new(0.0, 3.0, 0.0), "3 m/s edgewise", 2.0),
    ] {
        for seed in 1..=3 {
            let mut v = flying(ModelMode::Physical, seed);
            fly_until(&mut v, 10.0, |_| {});
            v.set_wind(wind, 0.5);
            let mut worst = 0.0_f64;
            fly_until(&mut v, 100.0, |t| worst = worst.max(t.pos_m.xy().norm()));
            let t = v.telemetry();
            assert_eq!(t.state, SystemState::Active, "{edge} seed {seed}");
            assert!(
                worst < radius,
                "{edge} seed {seed}: {worst} m from the point"
            );
            // Leaning into the wind: the thrust tilted upwind (paper frame, ÿ = −g φ).
            let lean = if wind.x > 0.0 {
                -t.euler.theta
            } else {
                t.euler.phi
            };
            assert!(lean > 0.05, "{edge} seed {seed}: lean {lean} rad");
        }
    }
}

#[test]
fn takes_off_in_qhover_and_holds_hover_alt() {
    let mut v = Vehicle::new(VehicleConfig {
        mode: FlightMode::QHover,
        ..VehicleConfig::default()
    });
    fly_until(&mut v, 1.2, |_| {});
    assert!(v.telemetry().landed);
    v.arm(false).expect("arms after calibration");
    fly_until(&mut v, 10.0, |_| {});
    let hover = v.gains().hover_alt_m;
    let mut band = 0.0_f64;
    fly_until(&mut v, 20.0, |t| band = band.max((t.pos_m.z - hover).abs()));
    assert!(band < 0.03, "altitude band ±{band} m");
    assert!(!v.telemetry().landed && v.telemetry().armed);
}

#[test]
fn qland_lands_comes_to_rest_and_disarms() {
    let mut v = flying(ModelMode::Physical, 3);
    fly_until(&mut v, 15.0, |_| {});
    v.set_mode(FlightMode::QLand);
    let mut max_sink = 0.0_f64;
    fly_until(&mut v, 25.0, |t| max_sink = max_sink.max(-t.vel_m_s.z));
    let t = v.telemetry();
    assert!(t.landed && t.pos_m.z == 0.0, "{:?}", t.pos_m);
    assert!(!t.armed, "QLAND disarms after touchdown");
    assert_eq!(t.state, SystemState::Standby, "a landing, not a crash");
    assert!(max_sink < 1.0, "descent at {max_sink} m/s");
    assert_eq!(t.pwm_us, [1000, 1000, 1500, 1500, 1500]);
    assert_eq!(t.vel_m_s, Vector3::zeros());
}

mod cli {
    use std::process::Command;

    fn bin() -> Command {
        Command::new(env!("CARGO_BIN_EXE_firmware-sim"))
    }

    #[test]
    fn simulate_writes_the_csv() {
        let out = bin()
            .args([
                "simulate",
                "--duration",
                "2",
                "--model",
                "paper",
                "--csv",
                "-",
            ])
            .args([
                "--initial",
                "phi=0.1,theta=0.1,psi=1,x=0.1,y=0.1,z=0.1",
                "--rate",
                "50",
            ])
            .output()
            .expect("runs");
        assert!(
            out.status.success(),
            "{}",
            String::from_utf8_lossy(&out.stderr)
        );
        let text = String::from_utf8(out.stdout).expect("utf-8");
        let mut lines = text.lines();
        let header: Vec<&str> = lines.next().expect("header").split(',').collect();
        let want = "t,x,y,z,vx,vy,vz,phi,theta,psi,p,q,r,tau_phi,tau_theta,tau_psi,fz,\
pwm1,pwm2,pwm3,pwm4,pwm5";
        for (i, name) in want.split(',').enumerate() {
            assert_eq!(header[i], name);
        }
        let rows: Vec<Vec<f64>> = lines
            .map(|l| l.split(',').map(|f| f.parse().expect("number")).collect())
            .collect();
        assert_eq!(rows.len(), 101, "2 s at 50 rows/s plus t = 0");
        assert!(rows.iter().all(|r| r.len() == header.len()));
        assert_eq!(rows[0][0], 0.0);
        assert!((rows[0][9] - 1.0).abs() < 1e-9, "ψ0 = 1 rad");
        assert!((rows[100][0] - 2.0).abs() < 1e-9);
        assert!(rows[100][9] < 0.5, "yaw law pulls ψ toward 0");
    }

    #[test]
    fn bad_flags_exit_nonzero_with_one_line() {
        for args in [
            vec!["simulate", "--model", "wrong"],
            vec!["simulate", "--initial", "roll=1"],
            vec!["simulate", "--param", "NOPE=1"],
            vec!["simulate", "--param", "LAT_SAT_D=0.5"],
            vec!["simulate", "--duration", "-3"],
            vec!["simulate", "--bogus"],
            // The vehicle refuses it, so does simulate (same table, same text).
            vec!["simulate", "--param", "ALT_KP=1e6"],
            vec!["simulate", "--param", "SR0_EXTRA1=4"],
            // A tilted start on the ground is not silently levelled.
            vec!["simulate", "--initial", "phi=0.5"],
            vec!["simulate", "--initial", "phi=3.3,z=1"],
            vec!["simulate", "--initial", "theta=1.2,z=1"],
            // Setpoints outside the vehicle's limits.
            vec!["simulate", "--setpoint", "z=1e12"],
            vec!["simulate", "--setpoint", "x=1e4,z=1"],
            // Combinations that cannot be honoured.
            vec!["simulate", "--model", "paper", "--param", "CTRL_RATE_HZ=50"],
            vec!["simulate", "--mode", "QHOVER", "--setpoint", "z=2"],
            vec!["simulate", "--physics-rate", "3000"],
            vec!["simulate", "--push", "roll=0.1@30"],
            vec!["simulate", "--push", "roll=9@1"],
        ] {
            let out = bin().args(&args).output().expect("runs");
            assert!(!out.status.success(), "{args:?} should fail");
            let err = String::from_utf8_lossy(&out.stderr);
            assert_eq!(err.trim().lines().count(), 1, "{args:?}: {err}");
            assert!(!err.contains("panicked"), "{args:?}: {err}");
            assert!(out.stdout.is_empty());
        }
    }

    /// The paper's hover experiments (Figs 8–10) offline: a push on each axis in QSTABILIZE;
    /// the attitude comes back within 2° in under 3 s.
    #[test]
    fn pushes_in_qstabilize_return_within_2_degrees_in_3_s() {
        // Torques scaled to each axis' inertia, so that each push tilts the vehicle by about 10°
        // as in the paper's figures; started at 3 m so the constant hover throttle (no altitude
        // hold in QSTABILIZE) keeps it in the air.
        for (axis, torque, col) in [("roll", 0.1, 7), ("pitch", 0.07, 8), ("yaw", 0.05, 9)] {
            let push = format!("{axis}={torque}@2:200");
            let out = bin()
                .args(["simulate", "--mode", "QSTABILIZE", "--initial", "z=3"])
                .args(["--duration", "8", "--push", &push, "--csv", "-"])
                .output()
                .expect("runs");
            assert!(
                out.status.success(),
                "{}",
                String::from_utf8_lossy(&out.stderr)
            );
            let text = String::from_utf8(out.stdout).expect("utf-8");
            let rows: Vec<Vec<f64>> = text
                .lines()
                .skip(1)
                .map(|l| l.split(',').map(|f| f.parse().expect("number")).collect())
                .collect();
            let angle = |r: &Vec<f64>| r[col];
            let peak = rows.iter().map(|r| angle(r).abs()).fold(0.0, f64::max);
            assert!(
                peak > 5f64.to_radians(),
                "{axis}: the push moved it ({peak} rad)"
            );
            assert!(rows.iter().all(|r| r[3] > 1.0), "{axis}: stayed in the air");
            // Last time the angle is outside ±2°.
            let last_out = rows
                .iter()
                .filter(|r| angle(r).abs() > 2f64.to_radians())
                .map(|r| r[0])
                .fold(0.0, f64::max);
            assert!(
                last_out - 2.0 < 3.0,
                "{axis}: back within 2° only {} s after the push (peak {}°)",
                last_out - 2.0,
                peak.to_degrees()
            );
        }
    }

    #[test]
    fn summary_without_csv() {
        let out = bin()
            .args(["simulate", "--duration", "1", "--model", "paper"])
            .output()
            .unwrap();
        assert!(out.status.success());
        assert!(String::from_utf8_lossy(&out.stdout).starts_with("t=1.000s"));
    }
}
