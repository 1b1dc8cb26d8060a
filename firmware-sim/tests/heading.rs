//! Long flights and the heading: the twin hovers for a day in fast time with the motion-capture
//! heading fused, holds altitude with the heading sensor off, and its position chains hold with
//! a constant heading error. Seeded, fast time, no sleeps.

use firmware_sim::model::vehicle::InitialState;
use firmware_sim::{Euler, FlightMode, ModelMode, Vehicle, VehicleConfig};
use nalgebra::Vector3;

const TARGET: Vector3<f64> = Vector3::new(0.0, 0.0, 1.0);

/// The paper's initial conditions (Section IV), armed, in `mode`.
fn paper_start(seed: u64, mode: FlightMode) -> Vehicle {
    let mut v = Vehicle::new(VehicleConfig {
        model: ModelMode::Physical,
        seed,
        initial: InitialState {
            pos_m: Vector3::new(0.1, 0.1, 0.1),
            euler: Euler::new(1.0, 0.1, 0.1),
        },
        mode,
        armed: true,
        ..VehicleConfig::default()
    });
    v.set_position_setpoint(TARGET);
    v
}

/// Steps until `t_s`, calling `each` after every step.
fn fly_until(v: &mut Vehicle, t_s: f64, mut each: impl FnMut(&Vehicle)) {
    let dt = v.physics_dt_s();
    while v.time_s() < t_s - 0.5 * dt {
        v.step();
        each(v);
    }
}

/// Largest excursions over a stretch of flight.
#[derive(Debug, Default, Clone, Copy)]
struct Band {
    /// max |ξ − ξ_d| over the three axes, m.
    pos_m: f64,
    /// max |z − z_d|, m.
    alt_m: f64,
    /// max |φ|, |θ|, rad.
    tilt_rad: f64,
    /// max |ψ̂ − ψ| of the heading the controller flies on, rad.
    heading_err_rad: f64,
    /// max |ψ|, rad.
    yaw_rad: f64,
}

impl Band {
    fn add(&mut self, v: &Vehicle) {
        let t = v.telemetry();
        self.pos_m = self.pos_m.max((t.pos_m - TARGET).amax());
        self.alt_m = self.alt_m.max((t.pos_m.z - TARGET.z).abs());
        self.tilt_rad = self
            .tilt_rad
            .max(t.euler.phi.abs())
            .max(t.euler.theta.abs());
        self.heading_err_rad = self.heading_err_rad.max(v.heading_error_rad().abs());
        self.yaw_rad = self.yaw_rad.max(t.euler.psi.abs());
    }
}

/// Settling time from the paper's start before the hold is measured, s (the chains' slowest
/// poles are at −1 rad/s; the transient from ψ0 = 1 rad and 10 cm is over well before).
const SETTLE_S: f64 = 120.0;

#[test]
fn qloiter_hovers_for_24_hours_seeds_1_to_5() {
    // One thread per seed: a day of flight is ~86 million physics steps each.
    let started = std::time::Instant::now();
    let handles: Vec<_> = (1..=5)
        .map(|seed| {
            std::thread::spawn(move || {
                let mut v = paper_start(seed, FlightMode::QLoiter);
                fly_until(&mut v, SETTLE_S, |_| {});
                let mut band = Band::default();
                let mut hourly = Vec::new();
                for hour in 1..=24 {
                    let mut h = Band::default();
                    fly_until(&mut v, f64::from(hour) * 3600.0, |v| h.add(v));
                    hourly.push(h.pos_m);
                    band.pos_m = band.pos_m.max(h.pos_m);
                    band.alt_m = band.alt_m.max(h.alt_m);
                    band.tilt_rad = band.tilt_rad.max(h.tilt_rad);
                    band.heading_err_rad = band.heading_err_rad.max(h.heading_err_rad);
                    band.yaw_rad = band.yaw_rad.max(h.yaw_rad);
                }
                (seed, band, hourly, v.telemetry().armed)
            })
        })
        .collect();
    let results: Vec<_> = handles
        .into_iter()
        .map(|h| h.join().expect("flight thread"))
        .collect();
    for (seed, band, hourly, _) in &results {
        eprintln!(
            "seed {seed}: ±{:.1} mm, tilt ±{:.2}°, heading error ±{:.3}°, hourly maxima {:?} mm",
            band.pos_m * 1e3,
            band.tilt_rad.to_degrees(),
            band.heading_err_rad.to_degrees(),
            hourly
                .iter()
                .map(|p| (p * 1e4).round() / 10.0)
                .collect::<Vec<_>>()
        );
    }
    for (seed, band, _, armed) in results {
        assert!(armed, "seed {seed}: still flying");
        // Seeded, so deterministic: the day's maxima are 23–29 mm for seeds 1–5, hourly maxima
        // flat over the day (no growth, no breakdown).
        assert!(
            band.pos_m < 0.03,
            "seed {seed}: position band ±{} m",
            band.pos_m
        );
        assert!(
            band.tilt_rad < 1f64.to_radians(),
            "seed {seed}: tilt band ±{}°",
            band.tilt_rad.to_degrees()
        );
        assert!(
            band.heading_err_rad < 0.5f64.to_radians(),
            "seed {seed}: heading error ±{}°",
            band.heading_err_rad.to_degrees()
        );
    }
    eprintln!("5 × 24 h in {:.1} s wall", started.elapsed().as_secs_f64());
}

#[test]
fn qhover_without_heading_sensor_holds_altitude_and_reports_the_drift() {
    let mut v = Vehicle::new(VehicleConfig {
        heading_sensor: false,
        ..paper_start(2, FlightMode::QHover).config().clone()
    });
    fly_until(&mut v, SETTLE_S, |_| {});
    let mut band = Band::default();
    fly_until(&mut v, 3600.0, |v| band.add(v));
    eprintln!(
        "QHOVER, gyro-only yaw, 1 h: altitude ±{:.1} mm, heading error up to {:.2}°, \
horizontal drift {:.2} m",
        band.alt_m * 1e3,
        band.heading_err_rad.to_degrees(),
        v.telemetry().pos_m.xy().norm()
    );
    assert!(band.alt_m < 0.03, "altitude band ±{} m", band.alt_m);
    // The drift is real (gyro-only yaw wanders with the residual bias) and bounded by it.
    assert!(band.heading_err_rad > 0.0);
    assert!(v.telemetry().armed);
}

#[test]
fn heading_fusion_pulls_a_misaligned_estimate_back() {
    // Without the heading fix the estimate keeps a start error; with it the error decays at the
    // filter's bandwidth (1 rad/s) to the sensor's noise.
    let mut v = paper_start(3, FlightMode::QLoiter);
    fly_until(&mut v, SETTLE_S, |_| {});
    let mut band = Band::default();
    fly_until(&mut v, SETTLE_S + 30.0, |v| band.add(v));
    assert!(
        band.heading_err_rad < 0.2f64.to_radians(),
        "fused heading error ±{}°",
        band.heading_err_rad.to_degrees()
    );
}

#[test]
fn qloiter_converges_and_holds_with_a_constant_30_degree_heading_error() {
    for seed in 1..=2 {
        let mut v = paper_start(seed, FlightMode::QLoiter);
        v.set_controller_heading_error(30f64.to_radians());
        fly_until(&mut v, 60.0, |_| {});
        let mut band = Band::default();
        fly_until(&mut v, 300.0, |v| band.add(v));
        assert!(
            (band.heading_err_rad - 30f64.to_radians()).abs() < 1f64.to_radians(),
            "the error is there: {}°",
            band.heading_err_rad.to_degrees()
        );
        assert!(
            band.pos_m < 0.04,
            "seed {seed}: position band ±{} m",
            band.pos_m
        );
        assert!(band.tilt_rad < 1f64.to_radians(), "seed {seed}: tilt");
    }
}

#[test]
fn the_estimator_tracks_a_start_at_0_8_rad() {
    // Noiseless sensors, the firmware flying on its estimator (not the true state).
    for mode in [FlightMode::QLoiter, FlightMode::QHover] {
        let mut v = Vehicle::new(VehicleConfig {
            ideal_sensors: true,
            perfect_state: false,
            initial: InitialState {
                pos_m: Vector3::new(0.1, 0.1, 1.0),
                euler: Euler::new(1.0, 0.8, 0.1),
            },
            ..paper_start(1, mode).config().clone()
        });
        v.set_position_setpoint(TARGET);
        let mut worst = 0.0_f64;
        fly_until(&mut v, 20.0, |v| {
            let t = v.telemetry();
            let (e, h) = (t.euler, t.euler_est);
            worst = worst
                .max((e.theta - h.theta).abs())
                .max((e.phi - h.phi).abs())
                .max(v.heading_error_rad().abs());
        });
        assert!(v.telemetry().armed, "{mode}: still flying");
        assert!(worst < 0.05, "{mode}: estimation error up to {worst} rad");
    }
}
