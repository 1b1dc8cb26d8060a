//! Cost of the twin's flight core: one `Vehicle::step` (1 ms of physics with RK4; sensors,
//! estimator and controller every tenth step) and a whole 60 s physical flight from the paper's
//! initial conditions. Prints the real-time factor (simulated seconds per wall-clock second).
//!
//! The last line is the load-robust figure: the fastest of many 1 000-step chunks flown from
//! clones of the same vehicle at 0, 10, …, 50 s of the flight, summed to a 60 s flight. A chunk
//! takes ~0.2 ms, so some run undisturbed even while other processes share the cores; it
//! tracks the quiet-machine figure within a few per cent and compares code versions reliably.
//!
//! Run: `cargo bench -p firmware-sim --bench flight`

use std::hint::black_box;
use std::time::Instant;

use criterion::{Criterion, criterion_group};
use firmware_sim::model::plant::{self, PlantInput, PlantState};
use firmware_sim::model::signals::ActuatorCommand;
use firmware_sim::model::vehicle::InitialState;
use firmware_sim::{Airframe, Euler, FlightMode, ModelMode, Vehicle, VehicleConfig};
use nalgebra::Vector3;

const FLIGHT_S: f64 = 60.0;
const STEPS: usize = 60_000;

fn vehicle() -> Vehicle {
    let mut v = Vehicle::new(VehicleConfig {
        model: ModelMode::Physical,
        initial: InitialState {
            pos_m: Vector3::new(0.1, 0.1, 0.1),
            euler: Euler::new(1.0, 0.1, 0.1),
        },
        mode: FlightMode::QLoiter,
        armed: true,
        ..VehicleConfig::default()
    });
    v.set_position_setpoint(Vector3::new(0.0, 0.0, 1.0));
    v
}

fn flight() -> Vehicle {
    let mut v = vehicle();
    for _ in 0..STEPS {
        v.step();
    }
    v
}

fn bench(c: &mut Criterion) {
    let af = Airframe::default();
    let state = PlantState {
        pos_m: Vector3::new(0.1, 0.2, 1.0),
        vel_body_m_s: Vector3::new(0.1, -0.2, 0.05),
        euler: Euler::new(0.3, 0.05, -0.04),
        omega_body_rad_s: Vector3::new(0.2, -0.1, 0.3),
    };
    let input = PlantInput {
        actuators: ActuatorCommand {
            rotor_speed_rad_s: [450.0, 440.0],
            elevator_rad: 0.01,
            aileron_left_rad: 0.02,
            aileron_right_rad: -0.02,
        },
        ..PlantInput::default()
    };
    c.bench_function("plant_derivative", |b| {
        b.iter(|| {
            plant::derivative(
                &af,
                ModelMode::Physical,
                black_box(&state),
                black_box(&input),
            )
        })
    });
    {
        use firmware_sim::model::control::{ControlInput, Controller, Gains};
        let mut ctl = Controller::new(Airframe::default(), ModelMode::Physical);
        let gains = Gains::default();
        let inp = ControlInput {
            dt_s: 0.01,
            mode: FlightMode::QLoiter,
            euler: Euler::new(0.01, 0.02, -0.01),
            omega_body_rad_s: Vector3::new(0.01, 0.02, 0.0),
            pos_m: Vector3::new(0.01, 0.0, 1.0),
            setpoint_m: Vector3::new(0.0, 0.0, 1.0),
            rotor_speed_rad_s: [443.0, 443.0],
            ..ControlInput::default()
        };
        c.bench_function("controller_update", |b| {
            b.iter(|| ctl.update(black_box(&inp), &gains))
        });
        let mut s = firmware_sim::model::sensors::Sensors::new(false, 1, 0.01);
        let mut est = firmware_sim::model::estimator::Estimator::new(Euler::default(), 0.01, 9.8);
        est.skip_calibration();
        c.bench_function("sensors_estimator", |b| {
            b.iter(|| {
                let imu = s.sample_imu(&Vector3::zeros(), &Vector3::new(0.0, 0.0, 9.8));
                let fix = s.sample_position(&Vector3::new(0.0, 0.0, 1.0), 0.0);
                est.update(&imu, Some(&fix.pos_m), Some(fix.heading_rad));
            })
        });
    }
    let mut v = vehicle();
    c.bench_function("vehicle_step_physical", |b| {
        b.iter(|| black_box(&mut v).step())
    });
    let mut g = c.benchmark_group("flight");
    g.sample_size(20);
    g.bench_function("physical_60s", |b| b.iter(|| black_box(flight())));
    g.finish();
}

criterion_group!(benches, bench);

fn main() {
    benches();
    Criterion::default().configure_from_args().final_summary();
    // Real-time factor from the best of a few whole flights (criterion's estimate is above).
    let best = (0..10)
        .map(|_| {
            let t0 = Instant::now();
            black_box(flight());
            t0.elapsed().as_secs_f64()
        })
        .fold(f64::INFINITY, f64::min);
    println!(
        "60 s physical flight: {:.2} ms wall, real-time factor {:.0}x ({:.0} ns per 1 ms step)",
        best * 1e3,
        FLIGHT_S / best,
        best / STEPS as f64 * 1e9
    );
    let floor = chunk_floor_s();
    println!(
        "60 s physical flight, fastest 1 000-step chunks: {:.2} ms, real-time factor {:.0}x",
        floor * 1e3,
        FLIGHT_S / floor
    );
}

/// A 60 s flight summed from the fastest of many 1 000-step chunks at 0, 10, …, 50 s, s.
fn chunk_floor_s() -> f64 {
    const CHUNK: usize = 1000;
    const SEGMENT: usize = 10_000;
    let mut v = vehicle();
    let mut total = 0.0;
    for _ in 0..STEPS / SEGMENT {
        let fastest = (0..300)
            .map(|_| {
                let mut c = v.clone();
                let t0 = Instant::now();
                for _ in 0..CHUNK {
                    c.step();
                }
                black_box(&c);
                t0.elapsed().as_secs_f64()
            })
            .fold(f64::INFINITY, f64::min);
        total += fastest * (SEGMENT / CHUNK) as f64;
        for _ in 0..SEGMENT {
            v.step();
        }
    }
    total
}
