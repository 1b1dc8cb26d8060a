//! State-machine tests of the mission protocol, GUIDED/AUTO/QRTL and the globe telemetry:
//! frames in, frames out, sim time only.

use mavlink::dialects::ardupilotmega as apm;

use super::mission::{MISSION_ITEM_ID, MISSION_ITEM_INT_ID, item_payload, raw_item};
use super::test_support::{each, from_gcs, home_and_vtol_takeoff, item, raw_command, run_until};
use super::*;
use crate::model::mode::FlightMode;
use crate::nav::mission::MissionItem;
use apm::{MavCmd, MavFrame, MavResult};

const GCS: LinkKey = LinkKey(1);
const OTHER: LinkKey = LinkKey(2);
const GCS_SYSID: u8 = 255;
const GCS_COMPID: u8 = 190;

fn endpoint_with(param_file: Option<PathBuf>) -> Endpoint {
    let mut config = EndpointConfig::default();
    config.vehicle.ideal_sensors = true;
    config.vehicle.perfect_state = true;
    config.param_file = param_file;
    let mut ep = Endpoint::new(config);
    ep.add_link(GCS);
    ep
}

fn endpoint() -> Endpoint {
    endpoint_with(None)
}

/// The endpoint with the hover's envelope: targets within 100 m of home and 50 m above it
/// (the defaults are sized for forward flight), so the refusals can be tested close by.
fn endpoint_in_a_small_envelope() -> Endpoint {
    let mut ep = endpoint();
    ep.set_param("NAV_RADIUS_MAX", 100.0).unwrap();
    ep.set_param("NAV_ALT_MAX", 50.0).unwrap();
    ep
}

fn from(compid: u8, msg: &apm::MavMessage) -> Frame {
    Frame::encode_v2(
        vtol_link::SystemId(GCS_SYSID),
        vtol_link::ComponentId(compid),
        3,
        msg,
    )
}

fn v2(msg: &apm::MavMessage) -> Frame {
    from(GCS_COMPID, msg)
}

fn decode(out: &[Outbound]) -> Vec<apm::MavMessage> {
    out.iter().filter_map(|o| o.frame.decode().ok()).collect()
}

fn acks(out: &[Outbound]) -> Vec<(u16, u8)> {
    out.iter()
        .map(|o| &o.frame)
        .filter(|f| f.message_id() == vtol_link::protocol::id::COMMAND_ACK)
        .map(|f| {
            let p: [u8; 10] = f.payload_padded();
            (u16::from_le_bytes([p[0], p[1]]), p[2])
        })
        .collect()
}

fn texts(out: &[Outbound]) -> Vec<apm::STATUSTEXT_DATA> {
    each!(decode(out), STATUSTEXT(t) => t.clone())
}

fn mission_acks(out: &[Outbound]) -> Vec<apm::MavMissionResult> {
    each!(decode(out), MISSION_ACK(a) => a.mavtype)
}

#[allow(deprecated)] // MISSION_REQUEST: what ArduPilot (and so the twin) asks with
fn requests(out: &[Outbound]) -> Vec<u16> {
    each!(decode(out), MISSION_REQUEST(r) => r.seq)
}

fn reached(out: &[Outbound]) -> Vec<u16> {
    each!(decode(out), MISSION_ITEM_REACHED(r) => r.seq)
}

fn command(command: u16, p: [f32; 7]) -> Frame {
    raw_command(76, 33, command, &p)
}

fn command_int(command: u16, frame_no: u8, p: [f32; 4], x: i32, y: i32, z: f32) -> Frame {
    let mut payload = [0u8; 35];
    for (k, v) in p.iter().enumerate() {
        payload[4 * k..4 * k + 4].copy_from_slice(&v.to_le_bytes());
    }
    payload[16..20].copy_from_slice(&x.to_le_bytes());
    payload[20..24].copy_from_slice(&y.to_le_bytes());
    payload[24..28].copy_from_slice(&z.to_le_bytes());
    payload[28..30].copy_from_slice(&command.to_le_bytes());
    payload[30] = 1;
    payload[32] = frame_no;
    from_gcs(5, 75, &payload)
}

fn set_mode(ep: &mut Endpoint, mode: FlightMode) -> Vec<Outbound> {
    ep.handle(
        GCS,
        &command(
            176,
            [1.0, mode.custom_mode() as f32, 0.0, 0.0, 0.0, 0.0, 0.0],
        ),
    )
}

fn count_msg(count: u16) -> apm::MavMessage {
    apm::MavMessage::MISSION_COUNT(apm::MISSION_COUNT_DATA {
        count,
        target_system: 1,
        target_component: 1,
        mission_type: apm::MavMissionType::MAV_MISSION_TYPE_MISSION,
        opaque_id: 0,
    })
}

fn item_frame(seq: u16, it: &MissionItem) -> Frame {
    from_gcs(9, MISSION_ITEM_INT_ID, &item_payload(seq, it, (1, 1), true))
}

fn flight_plan() -> Vec<MissionItem> {
    let mut loiter = item(MavCmd::MAV_CMD_NAV_LOITER_TIME as u16, 3.0, 2.0, 2.0);
    loiter.params[0] = 1.0;
    let [home, takeoff] = home_and_vtol_takeoff(2.0);
    vec![
        home,
        takeoff,
        item(MavCmd::MAV_CMD_NAV_WAYPOINT as u16, 3.0, 0.0, 2.5),
        loiter,
        item(MavCmd::MAV_CMD_NAV_VTOL_LAND as u16, 0.0, 2.0, 0.0),
    ]
}

/// Uploads `items` item by item as a GCS answering each request; returns everything sent back.
fn upload(ep: &mut Endpoint, items: &[MissionItem]) -> Vec<Outbound> {
    let mut out = ep.handle(GCS, &v2(&count_msg(items.len() as u16)));
    let mut all = out.clone();
    while let Some(&seq) = requests(&out).last() {
        out = ep.handle(GCS, &item_frame(seq, &items[usize::from(seq)]));
        all.extend(out.iter().cloned());
    }
    all
}

/// Downloads the stored mission with MISSION_REQUEST_INT; returns each item's raw payload.
fn download(ep: &mut Endpoint) -> Vec<Vec<u8>> {
    let list = apm::MavMessage::MISSION_REQUEST_LIST(apm::MISSION_REQUEST_LIST_DATA {
        target_system: 1,
        target_component: 1,
        mission_type: apm::MavMissionType::MAV_MISSION_TYPE_MISSION,
    });
    let count = decode(&ep.handle(GCS, &v2(&list)))
        .into_iter()
        .find_map(|m| match m {
            apm::MavMessage::MISSION_COUNT(c) => Some(c.count),
            _ => None,
        })
        .expect("MISSION_COUNT");
    (0..count)
        .map(|seq| {
            let req = apm::MavMessage::MISSION_REQUEST_INT(apm::MISSION_REQUEST_INT_DATA {
                seq,
                target_system: 1,
                target_component: 1,
                mission_type: apm::MavMissionType::MAV_MISSION_TYPE_MISSION,
            });
            let out = ep.handle(GCS, &v2(&req));
            let f = &out[0].frame;
            assert_eq!(f.message_id(), MISSION_ITEM_INT_ID);
            f.payload_padded::<38>().to_vec()
        })
        .collect()
}

#[test]
fn upload_then_download_is_byte_identical() {
    let mut ep = endpoint();
    let items = flight_plan();
    let out = upload(&mut ep, &items);
    assert_eq!(requests(&out), vec![0, 1, 2, 3, 4], "one request per item");
    assert_eq!(
        mission_acks(&out),
        vec![apm::MavMissionResult::MAV_MISSION_ACCEPTED]
    );
    let back = download(&mut ep);
    assert_eq!(back.len(), items.len());
    // Item 0 is home as the vehicle has it (584 m above sea level), not the slot as sent.
    let home = item_payload(0, &ep.home_item(), (GCS_SYSID, GCS_COMPID), true);
    assert_eq!(&back[0][..32], &home[..32]);
    assert_eq!(
        f32::from_le_bytes(back[0][24..28].try_into().unwrap()),
        584.0
    );
    for (seq, (payload, it)) in back.iter().zip(&items).enumerate().skip(1) {
        let sent = item_payload(seq as u16, it, (GCS_SYSID, GCS_COMPID), true);
        // Everything but the target (ours on upload, the GCS's on download) is the same bytes.
        assert_eq!(&payload[..32], &sent[..32], "item {seq}");
        assert_eq!(&payload[34..37], &sent[34..37], "item {seq}");
        assert_eq!((payload[32], payload[33]), (GCS_SYSID, GCS_COMPID));
    }
    // The legacy MISSION_REQUEST gets MISSION_ITEM (degrees as floats).
    #[allow(deprecated)]
    let req = apm::MavMessage::MISSION_REQUEST(apm::MISSION_REQUEST_DATA {
        seq: 2,
        target_system: 1,
        target_component: 1,
        mission_type: apm::MavMissionType::MAV_MISSION_TYPE_MISSION,
    });
    let f = ep.handle(GCS, &v2(&req))[0].frame.clone();
    assert_eq!(f.message_id(), MISSION_ITEM_ID);
    let r = raw_item(&f).unwrap();
    assert!((r.item.x - items[2].x).abs() < 40);
    // Past the end: INVALID_SEQUENCE.
    let req = apm::MavMessage::MISSION_REQUEST_INT(apm::MISSION_REQUEST_INT_DATA {
        seq: 5,
        target_system: 1,
        target_component: 1,
        mission_type: apm::MavMissionType::MAV_MISSION_TYPE_MISSION,
    });
    assert_eq!(
        mission_acks(&ep.handle(GCS, &v2(&req))),
        vec![apm::MavMissionResult::MAV_MISSION_INVALID_SEQUENCE]
    );
}

#[test]
fn a_refused_item_leaves_the_stored_mission_unchanged() {
    let mut ep = endpoint_in_a_small_envelope();
    upload(&mut ep, &flight_plan());
    let before = ep.mission().clone();
    // DO_SET_SERVO (183) in the middle.
    let mut bad = flight_plan();
    bad[2].command = 183;
    let out = upload(&mut ep, &bad);
    assert_eq!(
        requests(&out),
        vec![0, 1, 2],
        "the upload stops at the bad item"
    );
    assert_eq!(
        mission_acks(&out),
        vec![apm::MavMissionResult::MAV_MISSION_UNSUPPORTED]
    );
    let t = texts(&out);
    assert_eq!(
        t.last().unwrap().text.to_str().unwrap(),
        "Mission item 2: DO_SET_SERVO is not supported"
    );
    assert_eq!(ep.mission(), &before);
    // A command id the dialect does not know is refused the same way (read raw).
    bad[2].command = 65000;
    let out = upload(&mut ep, &bad);
    assert_eq!(
        mission_acks(&out),
        vec![apm::MavMissionResult::MAV_MISSION_UNSUPPORTED]
    );
    assert_eq!(ep.mission(), &before);
    // Outside the envelope: a 64-character reason, in two chunks of one text.
    let mut far = flight_plan();
    far[2] = item(MavCmd::MAV_CMD_NAV_WAYPOINT as u16, 111.0, 0.0, 2.0);
    let out = upload(&mut ep, &far);
    assert_eq!(
        mission_acks(&out),
        vec![apm::MavMissionResult::MAV_MISSION_INVALID_PARAM5_X]
    );
    let t = texts(&out);
    let chunks: Vec<_> = t.iter().filter(|s| s.id != 0).collect();
    assert_eq!(chunks.len(), 2, "{t:?}");
    assert_eq!((chunks[0].chunk_seq, chunks[1].chunk_seq), (0, 1));
    assert_eq!(chunks[0].id, chunks[1].id);
    let whole = format!(
        "{}{}",
        chunks[0].text.to_str().unwrap(),
        chunks[1].text.to_str().unwrap()
    );
    assert_eq!(
        whole,
        "Mission item 2 is 111.0 m from home, beyond NAV_RADIUS_MAX 100 m"
    );
    assert_eq!(ep.mission(), &before);
}

#[test]
fn upload_edge_cases() {
    let mut ep = endpoint();
    let items = flight_plan();
    // An item ahead of the one asked for is answered by asking again.
    ep.handle(GCS, &v2(&count_msg(5)));
    let out = ep.handle(GCS, &item_frame(2, &items[2]));
    assert_eq!(requests(&out), vec![0]);
    // Another GCS meanwhile is refused.
    let out = ep.handle(OTHER, &from(191, &count_msg(2)));
    assert_eq!(
        mission_acks(&out),
        vec![apm::MavMissionResult::MAV_MISSION_DENIED]
    );
    // Silence: the request is repeated, then the upload is cancelled.
    let out = run_until(&mut ep, 2_100_000);
    assert!(requests(&out).iter().all(|&s| s == 0) && !requests(&out).is_empty());
    let out = run_until(&mut ep, 9_000_000);
    assert_eq!(
        mission_acks(&out),
        vec![apm::MavMissionResult::MAV_MISSION_OPERATION_CANCELLED]
    );
    assert!(ep.mission().is_empty());
    // Too many items; a count of 0 clears.
    let out = ep.handle(GCS, &v2(&count_msg(5000)));
    assert_eq!(
        mission_acks(&out),
        vec![apm::MavMissionResult::MAV_MISSION_NO_SPACE]
    );
    upload(&mut ep, &items);
    assert_eq!(ep.mission().count(), 5);
    let out = ep.handle(GCS, &v2(&count_msg(0)));
    assert_eq!(
        mission_acks(&out),
        vec![apm::MavMissionResult::MAV_MISSION_ACCEPTED]
    );
    assert!(ep.mission().is_empty());
    // Fences and rally points: none, and none accepted.
    let fence = apm::MavMessage::MISSION_REQUEST_LIST(apm::MISSION_REQUEST_LIST_DATA {
        target_system: 1,
        target_component: 1,
        mission_type: apm::MavMissionType::MAV_MISSION_TYPE_FENCE,
    });
    let c = decode(&ep.handle(GCS, &v2(&fence)));
    assert!(matches!(&c[..], [apm::MavMessage::MISSION_COUNT(c)] if c.count == 0));
    let rally = apm::MavMessage::MISSION_COUNT(apm::MISSION_COUNT_DATA {
        mission_type: apm::MavMissionType::MAV_MISSION_TYPE_RALLY,
        ..match count_msg(1) {
            apm::MavMessage::MISSION_COUNT(c) => c,
            _ => unreachable!(),
        }
    });
    assert_eq!(
        mission_acks(&ep.handle(GCS, &v2(&rally))),
        vec![apm::MavMissionResult::MAV_MISSION_UNSUPPORTED]
    );
}

#[test]
fn mission_is_saved_beside_the_param_file() {
    let dir = tempfile::tempdir().unwrap();
    let parm = dir.path().join("twin.parm");
    let mut ep = endpoint_with(Some(parm.clone()));
    upload(&mut ep, &flight_plan());
    let saved = crate::nav::mission::Mission::load(&dir.path().join("twin.waypoints")).unwrap();
    assert_eq!(&saved, ep.mission());
    let clear = apm::MavMessage::MISSION_CLEAR_ALL(apm::MISSION_CLEAR_ALL_DATA {
        target_system: 1,
        target_component: 1,
        mission_type: apm::MavMissionType::MAV_MISSION_TYPE_MISSION,
    });
    assert_eq!(
        mission_acks(&ep.handle(GCS, &v2(&clear))),
        vec![apm::MavMissionResult::MAV_MISSION_ACCEPTED]
    );
    let saved = crate::nav::mission::Mission::load(&dir.path().join("twin.waypoints")).unwrap();
    assert!(saved.is_empty());
}

#[test]
fn legacy_set_mode_rtl_and_arming_refusals() {
    let mut ep = endpoint();
    run_until(&mut ep, 100_000);
    // Arming in QLAND is refused with the reason.
    set_mode(&mut ep, FlightMode::QLand);
    let out = ep.handle(GCS, &command(400, [1.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0]));
    assert_eq!(acks(&out), vec![(400, MavResult::MAV_RESULT_FAILED as u8)]);
    assert_eq!(
        texts(&out)[0].text.to_str().unwrap(),
        "Arm: mode QLAND cannot take off"
    );
    // RTL (11) is RTL, as on ArduPlane (QRTL with Q_RTL_MODE 3); an unknown mode is refused.
    #[allow(deprecated)]
    let legacy = |custom_mode| {
        apm::MavMessage::SET_MODE(apm::SET_MODE_DATA {
            custom_mode,
            target_system: 1,
            base_mode: apm::MavModeFlag::MAV_MODE_FLAG_CUSTOM_MODE_ENABLED,
        })
    };
    assert_eq!(acks(&ep.handle(GCS, &v2(&legacy(11)))), vec![(11, 0)]);
    assert_eq!(ep.vehicle().telemetry().mode, FlightMode::Rtl);
    ep.set_param("Q_RTL_MODE", 3.0).unwrap();
    assert_eq!(acks(&ep.handle(GCS, &v2(&legacy(11)))), vec![(11, 0)]);
    assert_eq!(ep.vehicle().telemetry().mode, FlightMode::QRtl);
    assert_eq!(
        acks(&ep.handle(GCS, &v2(&legacy(0)))),
        vec![(11, MavResult::MAV_RESULT_FAILED as u8)]
    );
    let out = ep.handle(GCS, &command(20, [0.0; 7]));
    assert_eq!(acks(&out), vec![(20, 0)]);
}

#[test]
fn telemetry_on_the_globe_and_a_healthy_fence() {
    let mut ep = endpoint();
    let out = run_until(&mut ep, 1_200_000);
    let msgs = decode(&out);
    let sys = msgs
        .iter()
        .rev()
        .find_map(|m| match m {
            apm::MavMessage::SYS_STATUS(s) => Some(s.clone()),
            _ => None,
        })
        .unwrap();
    use apm::MavSysStatusSensor as S;
    assert!(
        sys.onboard_control_sensors_health
            .contains(S::MAV_SYS_STATUS_GEOFENCE),
        "MAVProxy reports a fence breach when this bit is clear"
    );
    assert!(
        sys.onboard_control_sensors_present
            .contains(S::MAV_SYS_STATUS_SENSOR_GPS | S::MAV_SYS_STATUS_SENSOR_BATTERY)
    );
    assert!((12_000..=12_600).contains(&sys.voltage_battery), "{sys:?}");
    assert_eq!(sys.battery_remaining, 100);
    let gpi = msgs
        .iter()
        .find_map(|m| match m {
            apm::MavMessage::GLOBAL_POSITION_INT(g) => Some(g.clone()),
            _ => None,
        })
        .unwrap();
    assert_eq!(
        (gpi.lat, gpi.lon, gpi.alt),
        (-353_632_610, 1_491_652_300, 584_000)
    );
    for id in [24u32, 74, 147, 42] {
        assert!(
            out.iter().any(|o| o.frame.message_id() == id),
            "message {id} streamed"
        );
    }
    // HOME_POSITION on request.
    let out = ep.handle(GCS, &command(410, [0.0; 7]));
    assert_eq!(acks(&out), vec![(410, 0)]);
    assert!(
        decode(&out)
            .iter()
            .any(|m| matches!(m, apm::MavMessage::HOME_POSITION(h) if h.altitude == 584_000))
    );
}

/// Arm in GUIDED, take off, reposition (a refused one too), fly the mission in AUTO, land.
// Long: one flight told in order (arm, take off, reposition, a refusal, AUTO, land); each step
// starts from where the previous one left the vehicle.
#[test]
#[allow(deprecated)] // MAV_FRAME_GLOBAL_RELATIVE_ALT_INT, as ground stations still send it
fn guided_take_off_reposition_and_auto_mission() {
    let mut ep = endpoint_in_a_small_envelope();
    // The reposition held in a hover (Q_GUIDED_MODE 1; ArduPlane's default circles it on the
    // wing).
    ep.set_param("Q_GUIDED_MODE", 1.0).unwrap();
    // A DO_VTOL_TRANSITION to MC after the take-off: AUTO flies the waypoints in a hover (without
    // it they are flown on the wing, as ArduPlane does).
    let mut plan = flight_plan();
    let mut to_mc = super::test_support::transition_to_fw();
    to_mc.params[0] = 3.0;
    plan.insert(2, to_mc);
    upload(&mut ep, &plan);
    run_until(&mut ep, 200_000);
    assert_eq!(acks(&set_mode(&mut ep, FlightMode::Guided)), vec![(176, 0)]);
    // Take-off before arming: FAILED, with the reason.
    let out = ep.handle(GCS, &command(22, [0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 2.0]));
    assert_eq!(acks(&out), vec![(22, MavResult::MAV_RESULT_FAILED as u8)]);
    assert_eq!(
        texts(&out)[0].text.to_str().unwrap(),
        "Takeoff: must be armed"
    );
    assert_eq!(
        acks(&ep.handle(GCS, &command(400, [1.0; 7]))),
        vec![(400, 0)]
    );
    // 60 m is above NAV_ALT_MAX: DENIED.
    let out = ep.handle(GCS, &command(22, [0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 60.0]));
    assert_eq!(acks(&out), vec![(22, MavResult::MAV_RESULT_DENIED as u8)]);
    assert_eq!(
        acks(&ep.handle(GCS, &command(22, [0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 2.0]))),
        vec![(22, 0)]
    );
    run_until(&mut ep, 6_000_000);
    let z = ep.vehicle().telemetry().pos_m.z;
    assert!((z - 2.0).abs() < 0.15, "hovering at 2 m: {z}");
    // Reposition 3 m north (COMMAND_INT, relative altitude).
    let o = ep.params().origin();
    let p = o.to_global(&nalgebra::Vector3::new(3.0, 0.0, 0.0));
    let out = ep.handle(
        GCS,
        &command_int(
            192,
            MavFrame::MAV_FRAME_GLOBAL_RELATIVE_ALT_INT as u8,
            [-1.0, 1.0, 0.0, 0.0],
            p.lat_e7,
            p.lon_e7,
            2.0,
        ),
    );
    assert_eq!(acks(&out), vec![(192, 0)]);
    // 150 m away: DENIED, reason over 60 characters in chunks.
    let far = o.to_global(&nalgebra::Vector3::new(150.0, 0.0, 0.0));
    let out = ep.handle(
        GCS,
        &command_int(
            192,
            MavFrame::MAV_FRAME_GLOBAL_RELATIVE_ALT_INT as u8,
            [-1.0, 0.0, 0.0, 0.0],
            far.lat_e7,
            far.lon_e7,
            2.0,
        ),
    );
    assert_eq!(acks(&out), vec![(192, MavResult::MAV_RESULT_DENIED as u8)]);
    let t = texts(&out);
    let whole: String = t
        .iter()
        .map(|s| s.text.to_str().unwrap().to_owned())
        .collect();
    assert_eq!(
        whole,
        "Reposition refused: 150.0 m from home, beyond NAV_RADIUS_MAX 100 m"
    );
    assert!(t.len() == 2 && t[0].id != 0 && t[0].id == t[1].id);
    run_until(&mut ep, 14_000_000);
    let pos = ep.vehicle().telemetry().pos_m;
    // Paper frame: x is south.
    assert!((pos.x + 3.0).abs() < 0.3 && pos.y.abs() < 0.3, "{pos}");
    // AUTO: every item reached, landing at the last one.
    let mut out = set_mode(&mut ep, FlightMode::Auto);
    assert_eq!(acks(&out), vec![(176, 0)]);
    // Already at the take-off altitude: item 1 is reached at once.
    out.extend(run_until(&mut ep, 120_000_000));
    assert_eq!(reached(&out), vec![1, 2, 3, 4, 5]);
    let t = ep.vehicle().telemetry();
    assert!(!t.armed && t.landed, "landed and disarmed");
    assert_eq!(t.vtol_state, crate::model::mode::VtolState::Mc);
    assert!(
        (t.pos_m.y - 2.0).abs() < 0.3 && t.pos_m.x.abs() < 0.3,
        "{}",
        t.pos_m
    );
}

/// MISSION_REQUEST_INT for `seq`; returns the replies.
fn request_int(ep: &mut Endpoint, seq: u16) -> Vec<Outbound> {
    let req = apm::MavMessage::MISSION_REQUEST_INT(apm::MISSION_REQUEST_INT_DATA {
        seq,
        target_system: 1,
        target_component: 1,
        mission_type: apm::MavMissionType::MAV_MISSION_TYPE_MISSION,
    });
    ep.handle(GCS, &v2(&req))
}

#[test]
fn home_slot_is_readable_with_no_mission() {
    let mut ep = endpoint();
    assert!(download(&mut ep).is_empty(), "MISSION_COUNT 0");
    // DroneKit asks for item 0 even after a count of 0: home, as ArduPilot serves it.
    let out = request_int(&mut ep, 0);
    let f = &out[0].frame;
    assert_eq!(f.message_id(), MISSION_ITEM_INT_ID);
    let home = raw_item(f).unwrap();
    let o = ep.params().origin();
    let want = o.to_global(&ep.home_ned_m());
    assert_eq!(
        (home.seq, home.item.x, home.item.y),
        (0, want.lat_e7, want.lon_e7)
    );
    assert_eq!(home.item.frame, MavFrame::MAV_FRAME_GLOBAL as u8);
    assert!((f64::from(home.item.z) - want.alt_amsl_m).abs() < 0.01);
    // Past it: still INVALID_SEQUENCE.
    assert_eq!(
        mission_acks(&request_int(&mut ep, 1)),
        vec![apm::MavMissionResult::MAV_MISSION_INVALID_SEQUENCE]
    );
}

/// A MISSION_ITEM (floats, as DroneKit's `simple_goto` sends it) with `current` = 2.
fn guided_waypoint(north_m: f64, alt: f32) -> Frame {
    let mut it = item(MavCmd::MAV_CMD_NAV_WAYPOINT as u16, north_m, 0.0, alt);
    it.frame = MavFrame::MAV_FRAME_GLOBAL_RELATIVE_ALT as u8;
    it.current = 2;
    let p = item_payload(0, &it, (0, 0), false);
    from_gcs(4, MISSION_ITEM_ID, &p)
}

#[test]
fn guided_waypoint_is_acked_flown_and_refused_outside_guided() {
    let mut ep = endpoint_in_a_small_envelope();
    // Targets held in a hover (ArduPlane's default, 0, circles them on the wing).
    ep.set_param("Q_GUIDED_MODE", 1.0).unwrap();
    run_until(&mut ep, 200_000);
    // Not in GUIDED: refused with the reason, as ArduPlane refuses it.
    let out = ep.handle(GCS, &guided_waypoint(3.0, 2.0));
    assert_eq!(
        mission_acks(&out),
        vec![apm::MavMissionResult::MAV_MISSION_ERROR]
    );
    let why: String = texts(&out)
        .iter()
        .map(|t| t.text.to_str().unwrap().to_owned())
        .collect();
    assert!(why.contains("not GUIDED"), "{why}");
    assert!(ep.mission().is_empty(), "not stored as a mission");
    set_mode(&mut ep, FlightMode::Guided);
    ep.handle(GCS, &command(400, [1.0; 7]));
    ep.handle(GCS, &command(22, [0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 2.0]));
    run_until(&mut ep, 5_000_000);
    let out = ep.handle(GCS, &guided_waypoint(3.0, 2.0));
    assert_eq!(
        mission_acks(&out),
        vec![apm::MavMissionResult::MAV_MISSION_ACCEPTED]
    );
    run_until(&mut ep, 13_000_000);
    let pos = ep.vehicle().telemetry().pos_m;
    // Paper frame: x is south.
    assert!(
        (pos.x + 3.0).abs() < 0.3 && (pos.z - 2.0).abs() < 0.3,
        "{pos}"
    );
    // Beyond NAV_RADIUS_MAX: refused with the reason.
    let out = ep.handle(GCS, &guided_waypoint(150.0, 2.0));
    assert_eq!(
        mission_acks(&out),
        vec![apm::MavMissionResult::MAV_MISSION_ERROR]
    );
}

/// ArduPlane's default `Q_GUIDED_MODE` 0: a guided waypoint (DroneKit's `simple_goto`) after a
/// VTOL take-off is flown on the wing and circled at `WP_LOITER_RAD` (60 m).
#[test]
fn a_guided_waypoint_is_circled_on_the_wing_by_default() {
    let mut ep = endpoint();
    run_until(&mut ep, 200_000);
    set_mode(&mut ep, FlightMode::Guided);
    ep.handle(GCS, &command(400, [1.0; 7]));
    ep.handle(GCS, &command(22, [0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 20.0]));
    run_until(&mut ep, 30_000_000);
    assert_eq!(
        ep.vehicle().vtol_state(),
        crate::model::mode::VtolState::Mc,
        "the take-off hovers"
    );
    let out = ep.handle(GCS, &guided_waypoint(200.0, 20.0));
    assert_eq!(
        mission_acks(&out),
        vec![apm::MavMissionResult::MAV_MISSION_ACCEPTED]
    );
    run_until(&mut ep, 90_000_000);
    // Paper frame: x is south, so the point is at x = -200.
    let centre = nalgebra::Vector2::new(-200.0, 0.0);
    let (mut near, mut far) = (f64::INFINITY, 0.0_f64);
    let mut t = 90_000_000;
    while t < 120_000_000 {
        t += 500_000;
        run_until(&mut ep, t);
        let tel = ep.vehicle().telemetry();
        assert_eq!(tel.vtol_state, crate::model::mode::VtolState::Fw);
        let d = (tel.pos_m.xy() - centre).norm();
        (near, far) = (near.min(d), far.max(d));
    }
    assert!(
        near > 45.0 && far < 80.0,
        "circling at {near:.1}..{far:.1} m"
    );
}

#[test]
fn auto_with_no_mission_reaches_nothing() {
    let mut ep = endpoint();
    run_until(&mut ep, 200_000);
    set_mode(&mut ep, FlightMode::Guided);
    ep.handle(GCS, &command(400, [1.0; 7]));
    ep.handle(GCS, &command(22, [0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 2.0]));
    let mut out = run_until(&mut ep, 4_000_000);
    // MISSION_START with no mission: FAILED, said why.
    let start = ep.handle(GCS, &command(300, [0.0; 7]));
    assert_eq!(
        acks(&start),
        vec![(300, MavResult::MAV_RESULT_FAILED as u8)]
    );
    out.extend(set_mode(&mut ep, FlightMode::Auto));
    out.extend(run_until(&mut ep, 20_000_000));
    assert!(
        reached(&out).is_empty(),
        "no item reached: {:?}",
        reached(&out)
    );
}

/// ArduPlane's pre-arm mission check: a VTOL landing 5 m after the waypoint before it (under
/// 0.75 v² / (2 Q_TRANS_DECEL) = 9 m at 12 m/s and 6 m/s²) stops arming with ArduPlane's texts
/// ("Arm:" to the arming command, "PreArm:" while it fails), and SYS_STATUS shows the pre-arm
/// check failing; 10 m arms.
#[test]
fn a_vtol_landing_too_short_after_its_waypoint_stops_arming() {
    let prearm_healthy = |out: &[Outbound]| {
        decode(out).iter().rev().find_map(|m| match m {
            apm::MavMessage::SYS_STATUS(s) => Some(
                s.onboard_control_sensors_health
                    .contains(apm::MavSysStatusSensor::MAV_SYS_STATUS_PREARM_CHECK),
            ),
            _ => None,
        })
    };
    for (leg_m, arms) in [(5.0, false), (10.0, true)] {
        let mut ep = endpoint();
        let [home, takeoff] = home_and_vtol_takeoff(20.0);
        let plan = [
            home,
            takeoff,
            item(MavCmd::MAV_CMD_NAV_WAYPOINT as u16, 100.0, 0.0, 20.0),
            item(
                MavCmd::MAV_CMD_NAV_VTOL_LAND as u16,
                100.0 - leg_m,
                0.0,
                0.0,
            ),
        ];
        upload(&mut ep, &plan);
        let out = run_until(&mut ep, 3_000_000);
        assert_eq!(prearm_healthy(&out), Some(arms), "{leg_m} m");
        let reported = texts(&out)
            .iter()
            .any(|t| t.text.to_str().unwrap() == "PreArm: VTOL land too short, min 9m");
        assert_eq!(reported, !arms);
        let out = ep.handle(GCS, &command(400, [1.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0]));
        if arms {
            assert_eq!(acks(&out), vec![(400, 0)]);
        } else {
            assert_eq!(acks(&out), vec![(400, MavResult::MAV_RESULT_FAILED as u8)]);
            assert_eq!(
                texts(&out)[0].text.to_str().unwrap(),
                "Arm: VTOL land too short, min 9m"
            );
            assert!(!ep.vehicle().telemetry().armed);
        }
    }
    // With ArduPlane SITL's landing airspeed (its AIRSPEED_CRUISE of 22 m/s, as TECS_LAND_ARSPD
    // here) the minimum is SITL's 30 m, and its box mission's 29.9 m last leg is refused.
    let mut ep = endpoint();
    ep.set_param("TECS_LAND_ARSPD", 22.0).unwrap();
    let [home, takeoff] = home_and_vtol_takeoff(20.0);
    let plan = [
        home,
        takeoff,
        item(MavCmd::MAV_CMD_NAV_WAYPOINT as u16, 100.0, 0.0, 20.0),
        item(MavCmd::MAV_CMD_NAV_VTOL_LAND as u16, 70.1, 0.0, 0.0),
    ];
    upload(&mut ep, &plan);
    let out = run_until(&mut ep, 3_000_000);
    assert_eq!(prearm_healthy(&out), Some(false));
    assert!(
        texts(&out)
            .iter()
            .any(|t| t.text.to_str().unwrap() == "PreArm: VTOL land too short, min 30m")
    );
}
