//! FBWA flown by the sticks over MAVLink (RC_CHANNELS_OVERRIDE, as a ground station's joystick
//! sends them): a GUIDED take-off, FBWA starts the forward transition, the roll stick banks
//! and turns the aircraft, centred sticks fly straight, QLOITER transitions back. Sim time only.

use super::test_support::{acks, apm, command_long, endpoint, v2};
use super::*;
use crate::model::mode::{FlightMode, VtolState};

const GCS: LinkKey = LinkKey(1);

/// The sticks' PWM, µs: channels 1 roll, 2 pitch, 3 throttle, 4 yaw (centred).
fn sticks(roll: u16, pitch: u16, throttle: u16) -> Frame {
    v2(&apm::MavMessage::RC_CHANNELS_OVERRIDE(
        apm::RC_CHANNELS_OVERRIDE_DATA {
            chan1_raw: roll,
            chan2_raw: pitch,
            chan3_raw: throttle,
            chan4_raw: 1500,
            target_system: 1,
            target_component: 1,
            ..Default::default()
        },
    ))
}

fn command(ep: &mut Endpoint, cmd: apm::MavCmd, p: [f32; 7]) -> Vec<(u16, u8)> {
    acks(&ep.handle(GCS, &v2(&command_long(cmd, p, 0))))
}

fn set_mode(ep: &mut Endpoint, mode: FlightMode) {
    let p = [1.0, mode.custom_mode() as f32, 0.0, 0.0, 0.0, 0.0, 0.0];
    assert_eq!(
        command(ep, apm::MavCmd::MAV_CMD_DO_SET_MODE, p),
        vec![(176, 0)]
    );
}

/// The course over the ground (NED, clockwise from north), rad.
fn course_rad(ep: &Endpoint) -> f64 {
    let v = crate::model::frames::paper_to_ned(&ep.vehicle().telemetry().vel_m_s);
    v.y.atan2(v.x)
}

/// What a stretch of stick flying did: the course turned (unwrapped, rad), the lowest
/// airspeed, the lowest and highest height.
struct Stretch {
    turned_rad: f64,
    v_min: f64,
    z_min: f64,
    z_max: f64,
}

/// Flies `seconds` on the sticks (refreshed every second, as a joystick's stream is).
fn fly(ep: &mut Endpoint, t: &mut u64, seconds: f64, stick: &Frame) -> Stretch {
    let end = *t + (seconds * 1e6) as u64;
    let mut s = Stretch {
        turned_rad: 0.0,
        v_min: f64::INFINITY,
        z_min: f64::INFINITY,
        z_max: f64::NEG_INFINITY,
    };
    let mut course = course_rad(ep);
    while *t < end {
        if t.is_multiple_of(1_000_000) {
            ep.handle(GCS, stick);
        }
        *t += 20_000;
        ep.tick(*t);
        let c = course_rad(ep);
        s.turned_rad += crate::model::frames::wrap_pi(c - course);
        course = c;
        let tel = ep.vehicle().telemetry();
        s.v_min = s.v_min.min(tel.airspeed_m_s());
        s.z_min = s.z_min.min(tel.pos_m.z);
        s.z_max = s.z_max.max(tel.pos_m.z);
    }
    s
}

/// A GUIDED take-off to 20 m; returns the sim time, µs.
fn take_off_to_20_m(ep: &mut Endpoint) -> u64 {
    let mut t = 0u64;
    // The gyros calibrate for 1 s after power-up.
    while t < 2_000_000 {
        t += 20_000;
        ep.tick(t);
    }
    set_mode(ep, FlightMode::Guided);
    let arm = [1.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0];
    assert_eq!(
        command(ep, apm::MavCmd::MAV_CMD_COMPONENT_ARM_DISARM, arm),
        vec![(400, 0)]
    );
    let takeoff = [0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 20.0];
    assert_eq!(
        command(ep, apm::MavCmd::MAV_CMD_NAV_TAKEOFF, takeoff),
        vec![(22, 0)]
    );
    while ep.vehicle().telemetry().pos_m.z < 19.8 {
        t += 20_000;
        ep.tick(t);
        assert!(t < 60_000_000, "the take-off never reached 20 m");
    }
    t
}

#[test]
fn fbwa_on_the_sticks_transitions_turns_with_the_roll_stick_and_comes_back_to_a_hover() {
    let mut ep = endpoint();
    let mut t = take_off_to_20_m(&mut ep);
    let centred = sticks(1500, 1500, THROTTLE_US);
    ep.handle(GCS, &centred);
    set_mode(&mut ep, FlightMode::Fbwa);
    assert_eq!(ep.vehicle().vtol_state(), VtolState::TransitionToFw);
    let mut waited = 0;
    while ep.vehicle().vtol_state() != VtolState::Fw {
        fly(&mut ep, &mut t, 0.2, &centred);
        waited += 1;
        assert!(waited < 75, "no fixed-wing flight 15 s after FBWA");
    }
    let straight = fly(&mut ep, &mut t, 5.0, &centred);
    let right = fly(&mut ep, &mut t, 8.0, &sticks(1750, 1500, THROTTLE_US));
    let levelled = fly(&mut ep, &mut t, 3.0, &centred);
    let straight_again = fly(&mut ep, &mut t, 5.0, &centred);
    let left = fly(&mut ep, &mut t, 8.0, &sticks(1250, 1500, THROTTLE_US));
    let all = [&straight, &right, &levelled, &straight_again, &left];
    let report = all
        .iter()
        .map(|s| {
            format!(
                "turned {:.2} rad, airspeed >= {:.1}, height {:.1}..{:.1}",
                s.turned_rad, s.v_min, s.z_min, s.z_max
            )
        })
        .collect::<Vec<_>>()
        .join("\n");
    // Centred sticks: wings level, straight on.
    assert!(straight.turned_rad.abs() < 0.05, "{report}");
    assert!(straight_again.turned_rad.abs() < 0.05, "{report}");
    // Half right stick: a 22.5° bank, g tan μ / V ≈ 0.3 rad/s at 12 m/s; half left stick
    // turns back.
    assert!(right.turned_rad > 1.5, "{report}");
    assert!(left.turned_rad < -1.5, "{report}");
    // On the wing throughout, on a throttle near the level flight's, above ARSPD_FBW_MIN.
    for s in all {
        assert!(s.v_min >= 10.0, "{report}");
        assert!(s.z_min > 15.0 && s.z_max < 30.0, "{report}");
    }
    assert_eq!(ep.vehicle().vtol_state(), VtolState::Fw);
    // A last right turn, so the back transition ends on a heading well off north.
    fly(&mut ep, &mut t, 5.0, &sticks(1750, 1500, THROTTLE_US));
    fly(&mut ep, &mut t, 3.0, &centred);

    back_to_a_hover_and_land(&mut ep, &mut t, &centred);
}

/// QLOITER from the wing: the back transition (its height change at most 3 m), the hover,
/// then QLAND down to the ground.
fn back_to_a_hover_and_land(ep: &mut Endpoint, t: &mut u64, stick: &Frame) {
    set_mode(ep, FlightMode::QLoiter);
    assert_eq!(ep.vehicle().vtol_state(), VtolState::TransitionToMc);
    let back_from = ep.vehicle().telemetry().pos_m.z;
    let mut climb = 0.0_f64;
    while ep.vehicle().vtol_state() != VtolState::Mc {
        fly(ep, t, 0.2, stick);
        climb = climb.max((ep.vehicle().telemetry().pos_m.z - back_from).abs());
        assert!(*t < 200_000_000, "no hover after the back transition");
    }
    assert!(
        climb <= 3.0,
        "the back transition moved the height {climb:.2} m"
    );
    // The hover keeps the heading the transition ended with, as ArduPlane does.
    let heading = ep.vehicle().telemetry().euler.psi;
    fly(ep, t, 5.0, stick);
    let turned = crate::model::frames::wrap_pi(ep.vehicle().telemetry().euler.psi - heading);
    assert!(
        turned.abs() < 0.1,
        "the hover turned {turned:.2} rad from {heading:.2}"
    );
    set_mode(ep, FlightMode::QLand);
    while ep.vehicle().telemetry().armed {
        fly(ep, t, 1.0, stick);
        assert!(*t < 300_000_000, "never landed");
    }
    let tel = ep.vehicle().telemetry();
    assert_ne!(tel.state, crate::model::vehicle::SystemState::Emergency);
    assert!(tel.landed);
}

/// Throttle stick of the test's flight on the wing (10 % of the rotors' thrust range), µs.
const THROTTLE_US: u16 = 1100;
