//! AUTO with fixed-wing legs: a VTOL take-off, a transition, a 400 m × 150 m rectangle on the
//! wing, a VTOL landing, frames in and out, sim time only.

use mavlink::dialects::ardupilotmega as apm;

use super::mission::{MISSION_ITEM_INT_ID, item_payload};
use super::test_support::{
    acks, decode, home_and_vtol_takeoff, item, param_set, raw_command, transition_to_fw, v2,
};
use super::*;
use crate::model::mode::{FlightMode, VtolState};
use crate::nav::mission::MissionItem;
use apm::MavCmd;

const GCS: LinkKey = LinkKey(1);

fn endpoint() -> Endpoint {
    endpoint_with(true)
}

/// The endpoint on the true state (`perfect`) or on the noisy sensors and the estimators.
fn endpoint_with(perfect: bool) -> Endpoint {
    let mut config = EndpointConfig::default();
    config.vehicle.ideal_sensors = perfect;
    config.vehicle.perfect_state = perfect;
    let mut ep = Endpoint::new(config);
    ep.add_link(GCS);
    ep
}

fn command(command: u16, p: [f32; 7]) -> Frame {
    raw_command(76, 33, command, &p)
}

/// MAV_CMD_DO_SET_MODE (176) to `mode`, as a GCS sends it.
fn set_mode(mode: FlightMode) -> Frame {
    command(
        176,
        [1.0, mode.custom_mode() as f32, 0.0, 0.0, 0.0, 0.0, 0.0],
    )
}

/// Uploads `items` as a GCS answering each request (the twin asks with MISSION_REQUEST, as
/// ArduPilot does).
#[allow(deprecated)]
fn upload(ep: &mut Endpoint, items: &[MissionItem]) {
    let count = apm::MavMessage::MISSION_COUNT(apm::MISSION_COUNT_DATA {
        count: items.len() as u16,
        target_system: 1,
        target_component: 1,
        mission_type: apm::MavMissionType::MAV_MISSION_TYPE_MISSION,
        opaque_id: 0,
    });
    let mut out = ep.handle(GCS, &v2(&count));
    loop {
        let next = decode(&out).iter().find_map(|m| match m {
            apm::MavMessage::MISSION_REQUEST_INT(r) => Some(r.seq),
            apm::MavMessage::MISSION_REQUEST(r) => Some(r.seq),
            _ => None,
        });
        let Some(seq) = next else { break };
        let f = Frame::encode_payload_v2(
            vtol_link::SystemId(255),
            vtol_link::ComponentId(190),
            9,
            MISSION_ITEM_INT_ID,
            &item_payload(seq, &items[usize::from(seq)], (1, 1), true),
        )
        .unwrap();
        out = ep.handle(GCS, &f);
    }
    let acked = decode(&out).iter().any(|m| {
        matches!(m, apm::MavMessage::MISSION_ACK(a)
            if a.mavtype == apm::MavMissionResult::MAV_MISSION_ACCEPTED)
    });
    assert!(acked, "mission accepted: {:?}", decode(&out));
}

/// The rectangle's long side (south from home), m.
const RECT_LONG_M: f64 = 400.0;
/// Its short side (east), m.
const RECT_SHORT_M: f64 = 150.0;

/// Home, a VTOL take-off to 20 m, the transition, a 400 m × 150 m rectangle of fixed-wing
/// waypoints back to home, a VTOL landing inside it.
fn rectangle_mission() -> Vec<MissionItem> {
    let [home, takeoff] = home_and_vtol_takeoff(20.0);
    vec![
        home,
        takeoff,
        transition_to_fw(),
        item(MavCmd::MAV_CMD_NAV_WAYPOINT as u16, -RECT_LONG_M, 0.0, 20.0),
        item(
            MavCmd::MAV_CMD_NAV_WAYPOINT as u16,
            -RECT_LONG_M,
            RECT_SHORT_M,
            20.0,
        ),
        item(MavCmd::MAV_CMD_NAV_WAYPOINT as u16, 0.0, RECT_SHORT_M, 20.0),
        item(MavCmd::MAV_CMD_NAV_WAYPOINT as u16, 0.0, 0.0, 20.0),
        item(MavCmd::MAV_CMD_NAV_VTOL_LAND as u16, -60.0, 50.0, 0.0),
    ]
}

/// The same rectangle without the DO_VTOL_TRANSITION item: ArduPlane flies the waypoints after
/// a VTOL take-off on the wing all the same.
fn rectangle_mission_without_the_transition_item() -> Vec<MissionItem> {
    let mut m = rectangle_mission();
    m.remove(2);
    m
}

#[test]
fn auto_flies_a_vtol_take_off_a_rectangle_on_the_wing_and_a_vtol_landing() {
    fly_rectangle(endpoint(), &[]);
}

#[test]
fn without_a_transition_item_the_waypoints_after_the_take_off_are_flown_on_the_wing_too() {
    let mut ep = endpoint();
    upload(&mut ep, &rectangle_mission_without_the_transition_item());
    fly_uploaded_rectangle(ep);
}

#[test]
fn the_same_mission_on_the_noisy_sensors_and_the_estimators() {
    fly_rectangle(endpoint_with(false), &[]);
}

#[test]
fn the_same_mission_on_the_noisy_sensors_in_a_3_m_s_wind_with_gusts() {
    fly_rectangle(
        endpoint_with(false),
        &[
            ("SIM_WIND_DIR", 45.0),
            ("SIM_WIND_TURB", 0.5),
            ("SIM_WIND_SPD", 3.0),
        ],
    );
}

fn fly_rectangle(mut ep: Endpoint, params: &[(&str, f32)]) {
    for (name, value) in params {
        ep.handle(GCS, &v2(&param_set(name, *value)));
    }
    upload(&mut ep, &rectangle_mission());
    fly_uploaded_rectangle(ep);
}

fn fly_uploaded_rectangle(mut ep: Endpoint) {
    ep.handle(GCS, &set_mode(FlightMode::Auto));
    // The gyros calibrate for 1 s after power-up.
    let mut t = 0u64;
    while t < 2_000_000 {
        t += 20_000;
        ep.tick(t);
    }
    assert_eq!(
        acks(&ep.handle(GCS, &command(400, [1.0; 7]))),
        vec![(400, 0)]
    );
    let mut phases = vec![VtolState::Mc];
    let (mut v_min_fw, mut z_min_fw, mut z_max_fw) = (f64::INFINITY, f64::INFINITY, 0.0_f64);
    // The farthest south and east flown on the wing (NED), m.
    let (mut south_fw, mut east_fw) = (0.0_f64, 0.0_f64);
    let mut trace = Vec::new();
    while t < 400_000_000 {
        t += 20_000;
        ep.tick(t);
        let tel = ep.vehicle().telemetry();
        if *phases.last().unwrap() != tel.vtol_state {
            phases.push(tel.vtol_state);
        }
        if t.is_multiple_of(500_000) {
            let e =
                tel.euler.rotation_body_to_inertial() - tel.euler_est.rotation_body_to_inertial();
            trace.push(format!(
                "{:4} {:?} {:?} pos {:6.1} {:6.1} {:5.1} V {:4.1} item {} err {:.3} psi {:.2} wind {:.1} {:.1}",
                t / 1_000_000,
                tel.mode,
                tel.vtol_state,
                tel.pos_m.x,
                tel.pos_m.y,
                tel.pos_m.z,
                tel.airspeed_m_s(),
                ep.navigator.current(),
                e.norm(),
                tel.euler.psi,
                ep.vehicle().forward_flight().wind_estimate_m_s().x,
                ep.vehicle().forward_flight().wind_estimate_m_s().y,
            ));
        }
        if tel.vtol_state == VtolState::Fw {
            v_min_fw = v_min_fw.min(tel.airspeed_m_s());
            z_min_fw = z_min_fw.min(tel.pos_m.z);
            z_max_fw = z_max_fw.max(tel.pos_m.z);
            let ned = crate::model::frames::paper_to_ned(&tel.pos_m);
            south_fw = south_fw.max(-ned.x);
            east_fw = east_fw.max(ned.y);
        }
        if !tel.armed && t > 5_000_000 {
            break;
        }
    }
    let tel = ep.vehicle().telemetry();
    let trace = trace.join("\n");
    assert!(!tel.armed, "landed and disarmed:\n{trace}");
    assert_ne!(
        tel.state,
        crate::model::vehicle::SystemState::Emergency,
        "{trace}"
    );
    assert_eq!(
        phases,
        [
            VtolState::Mc,
            VtolState::TransitionToFw,
            VtolState::Fw,
            VtolState::TransitionToMc,
            VtolState::Mc
        ],
        "{trace}"
    );
    // The whole rectangle is flown; each turn starts up to the L1 distance (28.6 m) short of its
    // corner (ArduPlane's turn distance) and swings out past the line.
    let flown = |reach: f64, side: f64| (side - 30.0..side + 30.0).contains(&reach);
    assert!(
        flown(south_fw, RECT_LONG_M) && flown(east_fw, RECT_SHORT_M),
        "the rectangle flown on the wing reached {south_fw:.1} m south, {east_fw:.1} m east:\n{trace}"
    );
    // On the wing the airspeed never falls below 10 m/s, gusts or not.
    let v_floor = 10.0;
    assert!(
        v_min_fw >= v_floor,
        "airspeed on the wing fell to {v_min_fw:.1}:\n{trace}"
    );
    assert!(
        z_min_fw > 17.0 && z_max_fw < 23.0,
        "height on the wing {z_min_fw:.1}..{z_max_fw:.1}:\n{trace}"
    );
    let land = crate::model::frames::ned_to_paper(&nalgebra::Vector3::new(-60.0, 50.0, 0.0));
    let miss = (tel.pos_m.xy() - land.xy()).norm();
    assert!(miss <= 2.0, "landed {miss:.2} m from the target:\n{trace}");
}

#[test]
fn a_loiter_on_the_wing_then_rtl_flies_home_as_a_plane_and_lands_vertically() {
    let mut ep = endpoint();
    // RTL lands vertically at home (not ArduPlane's default, which circles home).
    ep.handle(GCS, &v2(&param_set("Q_RTL_MODE", 1.0)));
    let mut loiter = item(MavCmd::MAV_CMD_NAV_LOITER_TIME as u16, -100.0, 0.0, 20.0);
    loiter.params[0] = 20.0;
    let [home, takeoff] = home_and_vtol_takeoff(20.0);
    upload(
        &mut ep,
        &[
            home,
            takeoff,
            transition_to_fw(),
            loiter,
            item(MavCmd::MAV_CMD_NAV_WAYPOINT as u16, -200.0, 100.0, 20.0),
        ],
    );
    ep.handle(GCS, &set_mode(FlightMode::Auto));
    assert_eq!(
        acks(&ep.handle(GCS, &command(400, [1.0; 7]))),
        vec![(400, 0)]
    );
    // Fly until the loiter is done and the next leg has begun.
    let mut t = 0u64;
    let mut circled_from = None;
    while ep.navigator.current() < 4 || circled_from.is_none() {
        t += 20_000;
        ep.tick(t);
        if ep.navigator.current() == 3 && circled_from.is_none() {
            let p = ep.vehicle().telemetry().pos_m;
            let d = (p.xy() - nalgebra::Vector2::new(100.0, 0.0)).norm();
            if (50.0..70.0).contains(&d) && ep.vehicle().vtol_state() == VtolState::Fw {
                circled_from = Some(t);
            }
        }
        assert!(t < 200_000_000, "the loiter never ended");
    }
    assert_eq!(ep.navigator.current(), 4);
    assert_eq!(ep.vehicle().vtol_state(), VtolState::Fw);
    // RTL on the wing: RTL, then QRTL at home, landing there.
    let out = ep.handle(GCS, &command(176, [1.0, 11.0, 0.0, 0.0, 0.0, 0.0, 0.0]));
    assert_eq!(acks(&out), vec![(176, 0)]);
    assert_eq!(ep.vehicle().telemetry().mode, FlightMode::Rtl);
    let mut modes = vec![FlightMode::Rtl];
    while ep.vehicle().telemetry().armed {
        t += 20_000;
        ep.tick(t);
        let m = ep.vehicle().telemetry().mode;
        if *modes.last().unwrap() != m {
            modes.push(m);
        }
        assert!(
            t < 600_000_000,
            "never landed: {:?}",
            ep.vehicle().telemetry().pos_m
        );
    }
    assert_eq!(modes, [FlightMode::Rtl, FlightMode::QRtl]);
    let tel = ep.vehicle().telemetry();
    assert_ne!(tel.state, crate::model::vehicle::SystemState::Emergency);
    assert!(
        tel.pos_m.xy().norm() < 2.0,
        "landed at home: {:?}",
        tel.pos_m
    );
}

/// ArduPlane's defaults (`Q_RTL_MODE` 0): a mission that ends on the wing changes to RTL, which
/// flies home and circles it on the wing at `WP_LOITER_RAD` (60 m) without landing.
#[test]
fn with_the_default_q_rtl_mode_rtl_circles_home_on_the_wing() {
    let mut ep = endpoint();
    let [home, takeoff] = home_and_vtol_takeoff(20.0);
    upload(
        &mut ep,
        &[
            home,
            takeoff,
            item(MavCmd::MAV_CMD_NAV_WAYPOINT as u16, -150.0, 0.0, 20.0),
        ],
    );
    ep.handle(GCS, &set_mode(FlightMode::Auto));
    let mut t = 0u64;
    while t < 2_000_000 {
        t += 20_000;
        ep.tick(t);
    }
    assert_eq!(
        acks(&ep.handle(GCS, &command(400, [1.0; 7]))),
        vec![(400, 0)]
    );
    while ep.vehicle().telemetry().mode == FlightMode::Auto {
        t += 20_000;
        ep.tick(t);
        assert!(t < 200_000_000, "the mission never ended");
    }
    assert_eq!(ep.vehicle().telemetry().mode, FlightMode::Rtl);
    let end = t + 150_000_000;
    let (mut near, mut far) = (f64::INFINITY, 0.0_f64);
    let (mut low, mut high) = (f64::INFINITY, 0.0_f64);
    while t < end {
        t += 20_000;
        ep.tick(t);
        let tel = ep.vehicle().telemetry();
        assert!(tel.armed && tel.mode == FlightMode::Rtl, "{:?}", tel.mode);
        if t + 60_000_000 > end {
            assert_eq!(tel.vtol_state, VtolState::Fw);
            let d = tel.pos_m.xy().norm();
            (near, far) = (near.min(d), far.max(d));
            (low, high) = (low.min(tel.pos_m.z), high.max(tel.pos_m.z));
        }
    }
    assert!(
        near > 45.0 && far < 80.0,
        "circling home at {near:.1}..{far:.1} m"
    );
    // At RTL_ALTITUDE, 100 m above home.
    assert!(low > 95.0 && high < 105.0, "at {low:.1}..{high:.1} m");
}

/// ArduPlane's battery failsafe action 1 is RTL: from a hover the vehicle goes to the wing and
/// flies home (with Q_RTL_MODE 3 it is QRTL).
#[test]
fn a_battery_failsafe_rtl_flies_home_on_the_wing() {
    for (q_rtl_mode, want) in [(0.0, FlightMode::Rtl), (3.0, FlightMode::QRtl)] {
        let mut ep = endpoint();
        ep.handle(GCS, &v2(&param_set("Q_RTL_MODE", q_rtl_mode)));
        let mut t = 0u64;
        while t < 2_000_000 {
            t += 20_000;
            ep.tick(t);
        }
        ep.handle(GCS, &set_mode(FlightMode::Guided));
        assert_eq!(
            acks(&ep.handle(GCS, &command(400, [1.0; 7]))),
            vec![(400, 0)]
        );
        ep.handle(GCS, &command(22, [0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 20.0]));
        while ep.vehicle().telemetry().pos_m.z < 19.0 {
            t += 20_000;
            ep.tick(t);
            assert!(t < 60_000_000, "never climbed");
        }
        // Low at 1 mAh used: RTL at once.
        ep.handle(GCS, &v2(&param_set("BATT_LOW_MAH", 1299.0)));
        ep.handle(GCS, &v2(&param_set("BATT_FS_LOW_ACT", 1.0)));
        let end = t + 20_000_000;
        while t < end {
            t += 20_000;
            ep.tick(t);
        }
        let tel = ep.vehicle().telemetry();
        assert_eq!(tel.mode, want);
        let wing = want == FlightMode::Rtl;
        assert_eq!(
            tel.vtol_state == VtolState::Fw,
            wing,
            "{:?}",
            tel.vtol_state
        );
    }
}
