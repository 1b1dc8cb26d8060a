//! Forward flight in lockstep: take off, transition, fly level, transition back.

use nalgebra::Vector3;

use super::*;
use crate::model::mode::VtolState;

/// A vehicle hovering armed at `height` in QLOITER, on the true state.
fn hovering(height: f64) -> Vehicle {
    hovering_with(height, true)
}

/// As [`hovering`], on the true state (`perfect`) or on its noisy sensors and estimators.
fn hovering_with(height: f64, perfect: bool) -> Vehicle {
    Vehicle::new(VehicleConfig {
        ideal_sensors: perfect,
        perfect_state: perfect,
        armed: true,
        mode: FlightMode::QLoiter,
        initial: InitialState {
            pos_m: Vector3::new(0.0, 0.0, height),
            ..InitialState::default()
        },
        position_setpoint_m: Some(Vector3::new(0.0, 0.0, height)),
        ..VehicleConfig::default()
    })
}

/// Steps until `done` or `limit_s`; returns the largest |z − z at the start| seen.
fn fly_until(v: &mut Vehicle, limit_s: f64, done: impl Fn(&Vehicle) -> bool) -> f64 {
    let z0 = v.telemetry().pos_m.z;
    let mut worst: f64 = 0.0;
    let steps = (limit_s / v.physics_dt_s()).round() as u64;
    for _ in 0..steps {
        v.step();
        worst = worst.max((v.telemetry().pos_m.z - z0).abs());
        assert_ne!(
            v.telemetry().state,
            SystemState::Emergency,
            "crashed at {:.2} s",
            v.time_s()
        );
        if done(v) {
            break;
        }
    }
    worst
}

#[test]
fn cruise_transitions_flies_level_and_comes_back_to_a_hover() {
    cruise_and_back(hovering(20.0));
}

#[test]
fn the_same_on_the_noisy_sensors_and_the_estimators() {
    cruise_and_back(hovering_with(20.0, false));
}

/// Hover at 20 m, CRUISE, forward transition, 20 s level, QLOITER, back transition, hover.
fn cruise_and_back(mut v: Vehicle) {
    fly_until(&mut v, 2.0, |_| false);
    v.set_mode(FlightMode::Cruise);
    assert_eq!(v.vtol_state(), VtolState::TransitionToFw);
    let dz_forward = fly_until(&mut v, 10.0, |v| v.vtol_state() == VtolState::Fw);
    assert_eq!(v.vtol_state(), VtolState::Fw, "forward transition done");
    assert!(
        dz_forward <= 3.0,
        "forward transition moved the height {dz_forward:.2} m"
    );
    assert!(v.telemetry().airspeed_m_s() >= 10.0);

    // Level flight: 20 s, the last 10 at the trim airspeed and the height held.
    fly_until(&mut v, 10.0, |_| false);
    let (mut v_min, mut dz_max) = (f64::INFINITY, 0.0_f64);
    let steps = (10.0 / v.physics_dt_s()).round() as u64;
    for _ in 0..steps {
        v.step();
        v_min = v_min.min(v.telemetry().airspeed_m_s());
        dz_max = dz_max.max((v.telemetry().pos_m.z - 20.0).abs());
    }
    assert_eq!(v.vtol_state(), VtolState::Fw);
    assert!(v_min >= 10.0, "airspeed fell to {v_min:.2} m/s");
    assert!(dz_max <= 1.0, "height off by {dz_max:.2} m in level flight");
    assert!(
        v.telemetry().pos_m.x > 150.0,
        "it flew forward: {:?}",
        v.telemetry().pos_m
    );

    v.set_mode(FlightMode::QLoiter);
    assert_eq!(v.vtol_state(), VtolState::TransitionToMc);
    let dz_back = fly_until(&mut v, 15.0, |v| v.vtol_state() == VtolState::Mc);
    assert_eq!(v.vtol_state(), VtolState::Mc, "back transition done");
    // The hover takes over with the vehicle still climbing: count its settling too.
    let z_start = 20.0;
    let mut worst_after: f64 = 0.0;
    let steps = (10.0 / v.physics_dt_s()).round() as u64;
    for _ in 0..steps {
        v.step();
        worst_after = worst_after.max((v.telemetry().pos_m.z - z_start).abs());
    }
    assert!(
        dz_back.max(worst_after) <= 3.0,
        "back transition moved the height {:.2} m",
        dz_back.max(worst_after)
    );
    assert_ne!(v.telemetry().state, SystemState::Emergency);
    let speed = v.telemetry().vel_m_s.norm();
    assert!(
        speed < 0.3,
        "hovering again, still moving at {speed:.2} m/s"
    );
}

#[test]
fn a_forward_transition_that_cannot_reach_the_airspeed_is_aborted_to_qloiter() {
    let mut v = hovering(20.0);
    let mut gains = *v.gains();
    // A nose-down rate so slow the airspeed cannot be reached within 2 s.
    gains.forward.transition_rate_fw_rad_s = 5f64.to_radians();
    gains.forward.transition_timeout_s = 2.0;
    v.set_gains(gains).unwrap();
    fly_until(&mut v, 1.0, |_| false);
    v.set_mode(FlightMode::Fbwa);
    fly_until(&mut v, 3.0, |v| v.vtol_state() != VtolState::TransitionToFw);
    assert!(v.forward_flight().last_transition_aborted());
    assert_eq!(v.telemetry().mode, FlightMode::QLoiter);
    fly_until(&mut v, 10.0, |v| v.vtol_state() == VtolState::Mc);
    assert_eq!(v.vtol_state(), VtolState::Mc);
}

#[test]
fn a_fixed_wing_mode_on_the_ground_starts_no_transition() {
    let mut v = Vehicle::new(VehicleConfig {
        ideal_sensors: true,
        ..VehicleConfig::default()
    });
    v.set_mode(FlightMode::Cruise);
    assert_eq!(v.vtol_state(), VtolState::Mc);
    assert!(v.arm(false).is_err(), "no arming in a fixed-wing mode");
}

#[test]
fn cruise_in_a_3_m_s_wind_with_gusts_holds_airspeed_and_height() {
    let mut v = hovering(20.0);
    v.set_wind(Vector3::new(2.1, 2.1, 0.0), 0.5);
    v.set_mode(FlightMode::Cruise);
    let dz_forward = fly_until(&mut v, 10.0, |v| v.vtol_state() == VtolState::Fw);
    assert_eq!(
        v.vtol_state(),
        VtolState::Fw,
        "forward transition done in the wind"
    );
    assert!(
        dz_forward <= 3.0,
        "forward transition moved the height {dz_forward:.2} m"
    );
    fly_until(&mut v, 10.0, |_| false);
    let (mut v_min, mut dz_max) = (f64::INFINITY, 0.0_f64);
    let steps = (20.0 / v.physics_dt_s()).round() as u64;
    for _ in 0..steps {
        v.step();
        v_min = v_min.min(v.telemetry().airspeed_m_s());
        dz_max = dz_max.max((v.telemetry().pos_m.z - 20.0).abs());
        assert_ne!(v.telemetry().state, SystemState::Emergency);
    }
    assert!(v_min >= 10.0, "airspeed fell to {v_min:.2} m/s");
    assert!(dz_max <= 2.0, "height off by {dz_max:.2} m in gusts");
}

/// Mean electrical power over `seconds`, W.
fn mean_power_w(v: &mut Vehicle, seconds: f64) -> f64 {
    let j0 = v.telemetry().battery.consumed_j;
    fly_until(v, seconds, |_| false);
    (v.telemetry().battery.consumed_j - j0) / seconds
}

#[test]
fn the_battery_pays_for_the_rotors_work_in_every_phase_and_cruise_costs_less_than_hover() {
    let mut v = hovering(20.0);
    fly_until(&mut v, 2.0, |_| false);
    let hover_w = mean_power_w(&mut v, 10.0);
    v.set_mode(FlightMode::Cruise);
    let t0 = v.time_s();
    let j0 = v.telemetry().battery.consumed_j;
    fly_until(&mut v, 10.0, |v| v.vtol_state() == VtolState::Fw);
    let transition_w = (v.telemetry().battery.consumed_j - j0) / (v.time_s() - t0);
    fly_until(&mut v, 20.0, |_| false);
    let cruise_w = mean_power_w(&mut v, 20.0);
    // Hover: about 16 W of shaft power per rotor through a 60 % efficient drive.
    assert!((45.0..70.0).contains(&hover_w), "hover {hover_w:.1} W");
    assert!(
        transition_w > hover_w,
        "the transition ({transition_w:.1} W) costs more than hover"
    );
    assert!(
        cruise_w < 0.6 * hover_w,
        "cruise {cruise_w:.1} W against hover {hover_w:.1} W"
    );
    // The thrust's work on the air at 12 m/s is part of it: cruise is not free.
    let thrust = v.telemetry().control.fz_n;
    assert!(
        cruise_w > thrust * 12.0 / 0.6,
        "cruise {cruise_w:.1} W for {thrust:.2} N at 12 m/s"
    );
}

#[test]
fn paper_mode_has_no_forward_flight() {
    let mut v = Vehicle::new(VehicleConfig {
        model: crate::model::airframe::ModelMode::Paper,
        armed: true,
        mode: FlightMode::QLoiter,
        initial: InitialState {
            pos_m: Vector3::new(0.0, 0.0, 1.0),
            ..InitialState::default()
        },
        ..VehicleConfig::default()
    });
    v.set_mode(FlightMode::Cruise);
    assert_eq!(v.vtol_state(), VtolState::Mc);
}
