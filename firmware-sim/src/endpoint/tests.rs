//! State-machine tests of the endpoint: frames in, frames out, no sockets and no sleeping.

use super::test_support::*;
use apm::MavResult;

#[test]
fn heartbeat_fields_and_not_armed_by_default() {
    let mut ep = endpoint();
    let out = run_until(&mut ep, 2_500_000);
    let hb = heartbeat_of(&decode(&out));
    assert_eq!(hb.mavtype, apm::MavType::MAV_TYPE_FIXED_WING);
    assert_eq!(hb.mavtype as u8, 1);
    assert_eq!(hb.autopilot, apm::MavAutopilot::MAV_AUTOPILOT_ARDUPILOTMEGA);
    assert!(
        hb.base_mode
            .contains(apm::MavModeFlag::MAV_MODE_FLAG_CUSTOM_MODE_ENABLED)
    );
    assert!(
        !hb.base_mode
            .contains(apm::MavModeFlag::MAV_MODE_FLAG_SAFETY_ARMED),
        "disarmed"
    );
    assert_eq!(hb.custom_mode, 17, "QSTABILIZE");
    assert_eq!(hb.system_status, apm::MavState::MAV_STATE_STANDBY);
    assert_eq!(hb.mavlink_version, 3);
    let count = decode(&out)
        .iter()
        .filter(|m| matches!(m, apm::MavMessage::HEARTBEAT(_)))
        .count();
    assert_eq!(count, 3, "1 Hz: at 0, 1 and 2 s");
}

#[test]
fn unknown_command_id_gets_unsupported_via_raw_path() {
    let mut ep = endpoint();
    // COMMAND_LONG with command 65000, which the dialect's MavCmd cannot represent.
    let mut payload = vec![0u8; 33];
    payload[28..30].copy_from_slice(&65000u16.to_le_bytes());
    payload[30] = 1;
    let frame = from_gcs(0, vtol_link::protocol::id::COMMAND_LONG, &payload);
    let out = ep.handle(GCS, &frame);
    assert_eq!(
        acks(&out),
        vec![(65000, MavResult::MAV_RESULT_UNSUPPORTED as u8)]
    );
    // A known but unimplemented command too.
    let out = ep.handle(
        GCS,
        &v2(&command_long(
            apm::MavCmd::MAV_CMD_DO_SET_SERVO,
            [0.0; 7],
            0,
        )),
    );
    assert_eq!(
        acks(&out),
        vec![(183, MavResult::MAV_RESULT_UNSUPPORTED as u8)]
    );
    // Addressed to another system: no ACK at all.
    payload[30] = 42;
    let frame = from_gcs(0, vtol_link::protocol::id::COMMAND_LONG, &payload);
    assert!(acks(&ep.handle(GCS, &frame)).is_empty());
}

#[test]
fn arm_acks_and_sets_bit_128_and_retry_is_not_acted_twice() {
    // Real sensors: the gyro calibration at power-up makes the pre-arm check refuse, with a reason.
    let mut ep = Endpoint::new(EndpointConfig::default());
    ep.add_link(GCS);
    let arm = command_long(
        apm::MavCmd::MAV_CMD_COMPONENT_ARM_DISARM,
        [1.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0],
        0,
    );
    let out = ep.handle(GCS, &v2(&arm));
    assert_eq!(acks(&out), vec![(400, MavResult::MAV_RESULT_FAILED as u8)]);
    assert!(
        texts(&decode(&out)).iter().any(|t| t.starts_with("PreArm")),
        "{:?}",
        decode(&out)
    );

    run_until(&mut ep, 2_000_000);
    let out = ep.handle(GCS, &v2(&arm));
    assert_eq!(
        acks(&out),
        vec![(400, MavResult::MAV_RESULT_ACCEPTED as u8)]
    );
    let out = run_until(&mut ep, 3_000_000);
    let hb = heartbeat_of(&decode(&out));
    assert!(
        hb.base_mode
            .contains(apm::MavModeFlag::MAV_MODE_FLAG_SAFETY_ARMED)
    );
    assert_eq!(hb.base_mode.bits() & 128, 128);

    // A bad p1 is DENIED.
    let bad = command_long(
        apm::MavCmd::MAV_CMD_COMPONENT_ARM_DISARM,
        [0.5, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0],
        0,
    );
    assert_eq!(
        acks(&ep.handle(GCS, &v2(&bad))),
        vec![(400, MavResult::MAV_RESULT_DENIED as u8)]
    );

    // Mode change, then its retransmission with confirmation 1: same ACK, no second action.
    let mode = |m: f32, c| {
        command_long(
            apm::MavCmd::MAV_CMD_DO_SET_MODE,
            [1.0, m, 0.0, 0.0, 0.0, 0.0, 0.0],
            c,
        )
    };
    assert_eq!(acks(&ep.handle(GCS, &v2(&mode(18.0, 0)))), vec![(176, 0)]);
    ep.vehicle
        .set_mode(crate::model::mode::FlightMode::QStabilize);
    assert_eq!(acks(&ep.handle(GCS, &v2(&mode(18.0, 1)))), vec![(176, 0)]);
    assert_eq!(
        ep.vehicle().telemetry().mode,
        crate::model::mode::FlightMode::QStabilize,
        "not redone"
    );
    // Another mode whose first send was lost comes with confirmation 1: it is a new command,
    // acted on, not answered with the remembered result of the mode change before it.
    let qland = crate::model::mode::FlightMode::QLand;
    assert_eq!(
        acks(&ep.handle(GCS, &v2(&mode(qland.custom_mode() as f32, 1)))),
        vec![(176, 0)]
    );
    assert_eq!(ep.vehicle().telemetry().mode, qland, "acted on");
    // Unknown mode number.
    assert_eq!(
        acks(&ep.handle(GCS, &v2(&mode(3.0, 0)))),
        vec![(176, MavResult::MAV_RESULT_FAILED as u8)]
    );
}

#[test]
fn set_message_interval_changes_the_rate() {
    let mut ep = endpoint();
    let set = command_long(
        apm::MavCmd::MAV_CMD_SET_MESSAGE_INTERVAL,
        [30.0, 200_000.0, 0.0, 0.0, 0.0, 0.0, 0.0],
        0,
    );
    assert_eq!(acks(&ep.handle(GCS, &v2(&set))), vec![(511, 0)]);
    let out = run_until(&mut ep, 2_000_000);
    let n = decode(&out)
        .iter()
        .filter(|m| matches!(m, apm::MavMessage::ATTITUDE(_)))
        .count();
    assert!((10..=11).contains(&n), "5 Hz for 2 s, got {n}");

    #[allow(deprecated)] // still what GCSs send to read an interval
    let get = command_long(
        apm::MavCmd::MAV_CMD_GET_MESSAGE_INTERVAL,
        [30.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0],
        0,
    );
    let out = ep.handle(GCS, &v2(&get));
    assert_eq!(acks(&out), vec![(510, 0)]);
    let interval = decode(&out).into_iter().find_map(|m| match m {
        apm::MavMessage::MESSAGE_INTERVAL(i) => Some(i),
        _ => None,
    });
    assert_eq!(
        interval.map(|i| (i.message_id, i.interval_us)),
        Some((30, 200_000))
    );

    // A message the twin cannot stream (RC_CHANNELS_RAW, MAVLink 1 only) is refused.
    let set = command_long(
        apm::MavCmd::MAV_CMD_SET_MESSAGE_INTERVAL,
        [35.0, 1e5, 0.0, 0.0, 0.0, 0.0, 0.0],
        0,
    );
    assert_eq!(
        acks(&ep.handle(GCS, &v2(&set))),
        vec![(511, MavResult::MAV_RESULT_DENIED as u8)]
    );
}

#[test]
fn request_message_autopilot_version_follows_the_ack() {
    let mut ep = endpoint();
    let req = command_long(
        apm::MavCmd::MAV_CMD_REQUEST_MESSAGE,
        [148.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0],
        0,
    );
    let out = ep.handle(GCS, &v2(&req));
    assert_eq!(acks(&out), vec![(512, 0)]);
    let msgs = decode(&out);
    assert!(
        matches!(msgs[0], apm::MavMessage::COMMAND_ACK(_)),
        "ACK first"
    );
    let apm::MavMessage::AUTOPILOT_VERSION(v) = &msgs[1] else {
        panic!("{msgs:?}")
    };
    use apm::MavProtocolCapability as C;
    assert!(v.capabilities.contains(
        C::MAV_PROTOCOL_CAPABILITY_MAVLINK2
            | C::MAV_PROTOCOL_CAPABILITY_PARAM_ENCODE_C_CAST
            | C::MAV_PROTOCOL_CAPABILITY_COMMAND_INT
    ));
    let bad = command_long(
        apm::MavCmd::MAV_CMD_REQUEST_MESSAGE,
        [9999.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0],
        0,
    );
    assert_eq!(
        acks(&ep.handle(GCS, &v2(&bad))),
        vec![(512, MavResult::MAV_RESULT_FAILED as u8)]
    );
}

#[test]
fn v1_input_is_accepted_and_answered_in_v2() {
    let mut ep = endpoint();
    let out = ep.handle(GCS, &v1(&param_set("HOVER_ALT", 2.0)));
    let msgs = decode(&out);
    assert_eq!(param_values(&msgs)[0].param_value, 2.0);
    let out = ep.handle(
        GCS,
        &v1(&command_long(
            apm::MavCmd::MAV_CMD_DO_VTOL_TRANSITION,
            [4.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0],
            0,
        )),
    );
    assert_eq!(acks(&out), vec![(3000, MavResult::MAV_RESULT_DENIED as u8)]);
}

#[test]
fn ftp_is_nakked_with_file_not_found() {
    let mut ep = endpoint();
    let mut payload = [0u8; 251];
    payload[0..2].copy_from_slice(&41u16.to_le_bytes());
    payload[3] = 4; // OpenFileRO
    let msgs = decode(&ep.handle(
        GCS,
        &v2(&apm::MavMessage::FILE_TRANSFER_PROTOCOL(
            apm::FILE_TRANSFER_PROTOCOL_DATA {
                target_network: 0,
                target_system: 1,
                target_component: 1,
                payload,
            },
        )),
    ));
    let apm::MavMessage::FILE_TRANSFER_PROTOCOL(r) = &msgs[0] else {
        panic!("{msgs:?}")
    };
    assert_eq!(u16::from_le_bytes([r.payload[0], r.payload[1]]), 42);
    assert_eq!(
        (r.payload[3], r.payload[4], r.payload[5], r.payload[12]),
        (129, 1, 4, 10)
    );
    assert_eq!(
        (r.target_system, r.target_component),
        (GCS_SYSID, GCS_COMPID)
    );
}

#[test]
fn rc_override_only_from_gcs_and_expires() {
    let mut ep = endpoint();
    let ov = apm::MavMessage::RC_CHANNELS_OVERRIDE(apm::RC_CHANNELS_OVERRIDE_DATA {
        chan1_raw: 1600,
        chan3_raw: 1300,
        chan2_raw: u16::MAX,
        target_system: 1,
        target_component: 1,
        ..Default::default()
    });
    // From another system id: ignored.
    let other = Frame::encode_v2(
        vtol_link::SystemId(200),
        vtol_link::ComponentId(190),
        0,
        &ov,
    );
    ep.handle(GCS, &other);
    assert_eq!(ep.vehicle().telemetry().rc_us[0], 0);
    ep.handle(GCS, &v2(&ov));
    assert_eq!(ep.vehicle().telemetry().rc_us[..3], [1600, 0, 1300]);
    run_until(&mut ep, 2_000_000);
    assert_eq!(ep.vehicle().telemetry().rc_us[0], 1600, "still fresh");
    run_until(&mut ep, 3_100_000);
    assert_eq!(ep.vehicle().telemetry().rc_us[0], 0, "expired after 3 s");
}

#[test]
fn gcs_failsafe_switches_to_qland_when_enabled() {
    let mut ep = endpoint();
    ep.set_param("FS_GCS_ENABL", 1.0).unwrap();
    let hb = vtol_link::gcs_heartbeat();
    run_until(&mut ep, 1_500_000);
    ep.handle(GCS, &v2(&hb));
    ep.vehicle.arm(true).unwrap();
    let out = run_until(&mut ep, 8_000_000);
    let msgs = decode(&out);
    assert!(
        texts(&msgs)
            .iter()
            .any(|t| t.contains("GCS heartbeat lost")),
        "{:?}",
        texts(&msgs)
    );
    assert_eq!(
        ep.vehicle().telemetry().mode,
        crate::model::mode::FlightMode::QLand
    );
    let hb = heartbeat_of(&msgs);
    assert_eq!(hb.system_status, apm::MavState::MAV_STATE_CRITICAL);
}

#[test]
fn bad_crc_is_counted_and_ignored() {
    let mut ep = endpoint();
    let mut bytes = v2(&param_set("HOVER_ALT", 2.0)).as_bytes().to_vec();
    let n = bytes.len();
    bytes[n - 1] ^= 0xFF;
    // As the serve loop does: the link's decoder splits and checks, the endpoint is told.
    let mut decoder = FrameDecoder::new();
    decoder.push(&bytes);
    let mut out = Vec::new();
    for f in decoder.frames().collect::<Vec<_>>() {
        out.extend(ep.handle(GCS, &f));
    }
    ep.note_bad_frames(decoder.stats().bad_crc);
    assert!(out.is_empty());
    assert_eq!(ep.stats().bad_frames, 1);
    assert_eq!(ep.params().value("HOVER_ALT"), 1.0);
}

#[test]
fn telemetry_streams_at_default_rates() {
    let mut ep = endpoint();
    let out = run_until(&mut ep, 10_000_000);
    let msgs = decode(&out);
    let count = |id: u32| {
        msgs.iter()
            .filter(|m| mavlink::Message::message_id(*m) == id)
            .count()
    };
    for (id, hz) in [
        (30, 20),
        (32, 10),
        (36, 10),
        (65, 4),
        (1, 1),
        (2, 1),
        (245, 1),
        (27, 2),
        (26, 2),
    ] {
        let n = count(id);
        assert!(
            (n as i64 - 10 * hz).abs() <= 1,
            "msg {id}: {n} in 10 s, want {hz} Hz"
        );
    }
    assert_eq!(count(31), 0, "ATTITUDE_QUATERNION only on request");
}

#[test]
#[allow(deprecated)] // SET_MODE and REQUEST_DATA_STREAM: legacy, still sent by MAVProxy
fn legacy_set_mode_and_request_data_stream() {
    let mut ep = endpoint();
    let set_mode = apm::MavMessage::SET_MODE(apm::SET_MODE_DATA {
        custom_mode: 19,
        target_system: 1,
        base_mode: apm::MavModeFlag::MAV_MODE_FLAG_CUSTOM_MODE_ENABLED,
    });
    // One ACK, with the message id as the command, as ArduPilot answers SET_MODE.
    assert_eq!(acks(&ep.handle(GCS, &v2(&set_mode))), vec![(11, 0)]);
    assert_eq!(
        ep.vehicle().telemetry().mode,
        crate::model::mode::FlightMode::QLoiter
    );

    // ALL at 2 Hz: ATTITUDE drops from 20 Hz to 2 Hz; the heartbeat stays at 1 Hz.
    let rds = apm::MavMessage::REQUEST_DATA_STREAM(apm::REQUEST_DATA_STREAM_DATA {
        req_message_rate: 2,
        target_system: 1,
        target_component: 1,
        req_stream_id: apm::MavDataStream::MAV_DATA_STREAM_ALL,
        start_stop: 1,
    });
    ep.handle(GCS, &v2(&rds));
    let msgs = decode(&run_until(&mut ep, 5_000_000));
    let count = |id: u32| {
        msgs.iter()
            .filter(|m| mavlink::Message::message_id(*m) == id)
            .count()
    };
    assert!((9..=11).contains(&count(30)), "ATTITUDE {}", count(30));
    assert_eq!(count(0), 6, "heartbeats at 0, 1, … 5 s");
}

#[test]
fn timesync_request_is_answered() {
    let mut ep = endpoint();
    run_until(&mut ep, 1_000_000);
    let req = apm::MavMessage::TIMESYNC(apm::TIMESYNC_DATA {
        tc1: 0,
        ts1: 123_456,
        target_system: 0,
        target_component: 0,
    });
    let msgs = decode(&ep.handle(GCS, &v2(&req)));
    let apm::MavMessage::TIMESYNC(t) = &msgs[0] else {
        panic!("{msgs:?}")
    };
    assert_eq!((t.ts1, t.tc1), (123_456, 1_000_000_000));
    assert_eq!(
        (t.target_system, t.target_component),
        (GCS_SYSID, GCS_COMPID)
    );
}

#[test]
fn manual_control_maps_sticks_to_rc() {
    let mut ep = endpoint();
    let mc = apm::MavMessage::MANUAL_CONTROL(apm::MANUAL_CONTROL_DATA {
        x: 1000,
        y: -1000,
        z: 500,
        r: i16::MAX,
        target: 1,
        ..Default::default()
    });
    ep.handle(GCS, &v2(&mc));
    assert_eq!(ep.vehicle().telemetry().rc_us[..4], [1000, 1000, 1500, 0]);
}

#[test]
fn sim_push_is_one_shot_and_resets() {
    let mut ep = endpoint();
    let msgs = decode(&ep.handle(GCS, &v2(&param_set("SIM_PUSH_ROLL", 0.05))));
    assert_eq!(param_values(&msgs)[0].param_value, 0.05);
    let msgs = decode(&run_until(&mut ep, 300_000));
    let reset = param_values(&msgs);
    assert_eq!(reset.len(), 1, "reset announced after SIM_PUSH_MS");
    assert_eq!(
        (reset[0].param_id.to_str().unwrap(), reset[0].param_value),
        ("SIM_PUSH_ROLL", 0.0)
    );
}

#[test]
fn messages_for_other_systems_are_ignored() {
    let mut ep = endpoint();
    let mut set = param_set("HOVER_ALT", 3.0);
    if let apm::MavMessage::PARAM_SET(p) = &mut set {
        p.target_system = 9;
    }
    assert!(ep.handle(GCS, &v2(&set)).is_empty());
    assert_eq!(ep.stats().not_for_us, 1);
    assert_eq!(ep.params().value("HOVER_ALT"), 1.0);
}

#[test]
fn controller_outputs_stream_as_named_value_float() {
    let mut ep = endpoint();
    let _ = ep.handle(
        GCS,
        &v2(&command_long(
            apm::MavCmd::MAV_CMD_COMPONENT_ARM_DISARM,
            [1.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0],
            0,
        )),
    );
    ep.vehicle.set_mode(crate::model::mode::FlightMode::QHover);
    let mut seen: std::collections::BTreeMap<String, (u32, f32)> = Default::default();
    for k in 1..=200 {
        let msgs = decode(&ep.tick(k * 10_000));
        for m in msgs {
            if let apm::MavMessage::NAMED_VALUE_FLOAT(d) = m {
                let name = d.name.to_str().unwrap_or_default().to_owned();
                let e = seen.entry(name).or_default();
                e.0 += 1;
                e.1 = d.value;
            }
        }
    }
    let names: Vec<&str> = seen.keys().map(String::as_str).collect();
    assert_eq!(names, ["FZ", "TAU_PHI", "TAU_PSI", "TAU_THETA"]);
    for (name, (count, _)) in &seen {
        assert!((18..=22).contains(count), "{name}: {count} in 2 s at 10 Hz");
    }
    // The last values are the controller's last output (it flies: thrust near the weight).
    let c = ep.vehicle().telemetry().control;
    assert_eq!(seen["FZ"].1, c.fz_n as f32);
    assert_eq!(seen["TAU_THETA"].1, c.tau_tilde[1] as f32);
    assert!(c.fz_n > 3.0, "{c:?}");
}

#[test]
fn reboot_clears_a_crash_after_a_silence() {
    let mut config = EndpointConfig::default();
    config.vehicle.ideal_sensors = true;
    // Dropped from 2 m, disarmed: a crash that latches.
    config.vehicle.initial.pos_m = nalgebra::Vector3::new(0.3, -0.2, 2.0);
    let mut ep = Endpoint::new(config);
    ep.add_link(GCS);
    let _ = ep.tick(2_000_000);
    assert_eq!(ep.vehicle().telemetry().state, SystemState::Emergency);
    let drawn_mah = ep.vehicle().telemetry().battery.consumed_mah;
    assert!(drawn_mah > 0.1, "the avionics draw: {drawn_mah} mAh");
    let reboot = |p1: f32| {
        v2(&command_long(
            apm::MavCmd::MAV_CMD_PREFLIGHT_REBOOT_SHUTDOWN,
            [p1, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0],
            0,
        ))
    };
    // Shutdown is not something a simulated board can do.
    assert_eq!(acks(&ep.handle(GCS, &reboot(2.0))), [(246, 3)]);
    assert_eq!(acks(&ep.handle(GCS, &reboot(1.0))), [(246, 0)]);
    assert!(ep.is_rebooting());
    // Silent and deaf while rebooting.
    let t0 = ep.now_us();
    assert!(ep.tick(t0 + 1_000_000).is_empty());
    assert!(ep.handle(GCS, &reboot(1.0)).is_empty());
    // Back: on the ground where it fell, disarmed, no longer crashed, talking again.
    let msgs = decode(&ep.tick(t0 + REBOOT_SILENCE_US + 1_000_000));
    assert!(!ep.is_rebooting());
    assert!(
        msgs.iter()
            .any(|m| matches!(m, apm::MavMessage::HEARTBEAT(_))),
        "heartbeats resume"
    );
    let t = ep.vehicle().telemetry();
    assert_eq!(t.state, SystemState::Standby);
    assert!(t.landed && !t.armed);
    // The pack is not refilled: what was drawn stays drawn.
    assert!(
        t.battery.consumed_mah >= drawn_mah && t.battery.remaining < 1.0,
        "{:?} after {drawn_mah} mAh",
        t.battery
    );
    assert!(
        (t.pos_m.x - 0.3).abs() < 0.1 && t.pos_m.z == 0.0,
        "{:?}",
        t.pos_m
    );
    // Armed, the reboot is refused.
    let _ = ep.handle(
        GCS,
        &v2(&command_long(
            apm::MavCmd::MAV_CMD_COMPONENT_ARM_DISARM,
            [1.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0],
            0,
        )),
    );
    assert!(ep.vehicle().telemetry().armed);
    assert_eq!(acks(&ep.handle(GCS, &reboot(1.0))), [(246, 2)]);
}

/// ArduPlane's QLOITER on the ground with no pilot throttle (no RC at all) stays on the ground,
/// motors at idle, and a disarm is accepted; the twin must not climb to a hover by itself.
#[test]
fn qloiter_armed_on_the_ground_without_sticks_stays_landed_and_disarms() {
    let mut ep = endpoint();
    run_until(&mut ep, 2_000_000);
    let set_mode = command_long(
        apm::MavCmd::MAV_CMD_DO_SET_MODE,
        [1.0, 19.0, 0.0, 0.0, 0.0, 0.0, 0.0],
        0,
    );
    assert_eq!(
        acks(&ep.handle(GCS, &v2(&set_mode))),
        vec![(176, MavResult::MAV_RESULT_ACCEPTED as u8)]
    );
    run_until(&mut ep, 2_500_000);
    let arm = |p1: f32| {
        command_long(
            apm::MavCmd::MAV_CMD_COMPONENT_ARM_DISARM,
            [p1, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0],
            0,
        )
    };
    assert_eq!(
        acks(&ep.handle(GCS, &v2(&arm(1.0)))),
        vec![(400, MavResult::MAV_RESULT_ACCEPTED as u8)]
    );
    run_until(&mut ep, 12_500_000);
    let t = ep.vehicle().telemetry();
    assert!(t.armed);
    assert!(t.landed, "lifted off: {:?}", t.pos_m);
    assert!(t.pos_m.z.abs() < 0.01, "{:?}", t.pos_m);
    assert_eq!(
        acks(&ep.handle(GCS, &v2(&arm(0.0)))),
        vec![(400, MavResult::MAV_RESULT_ACCEPTED as u8)]
    );
    assert!(!ep.vehicle().telemetry().armed);

    // The throttle stick at mid holds the ground; above mid QLOITER climbs to `HOVER_ALT`.
    let throttle = |us: u16| {
        v2(&apm::MavMessage::RC_CHANNELS_OVERRIDE(
            apm::RC_CHANNELS_OVERRIDE_DATA {
                chan1_raw: 1500,
                chan2_raw: 1500,
                chan3_raw: us,
                chan4_raw: 1500,
                target_system: 1,
                target_component: 1,
                ..Default::default()
            },
        ))
    };
    assert_eq!(
        acks(&ep.handle(GCS, &v2(&arm(1.0)))),
        vec![(400, MavResult::MAV_RESULT_ACCEPTED as u8)]
    );
    let _ = ep.handle(GCS, &throttle(1500));
    run_until(&mut ep, 15_000_000);
    assert!(ep.vehicle().telemetry().landed);
    let _ = ep.handle(GCS, &throttle(1800));
    run_until(&mut ep, 17_000_000);
    let _ = ep.handle(GCS, &throttle(1500));
    run_until(&mut ep, 19_000_000);
    let _ = ep.handle(GCS, &throttle(1500));
    run_until(&mut ep, 21_000_000);
    let t = ep.vehicle().telemetry();
    assert!(!t.landed && (t.pos_m.z - 1.0).abs() < 0.1, "{:?}", t.pos_m);
}
