//! State-machine tests of what SDKs read before they fly: identity (HEARTBEAT,
//! AUTOPILOT_VERSION), EKF_STATUS_REPORT, the pre-arm bit and texts, and the commands answered
//! as ArduPlane answers them.

use super::test_support::*;

fn of<T>(msgs: &[apm::MavMessage], f: impl Fn(&apm::MavMessage) -> Option<T>) -> Vec<T> {
    msgs.iter().filter_map(f).collect()
}

fn ekf_flags(msgs: &[apm::MavMessage]) -> Vec<apm::EkfStatusFlags> {
    of(msgs, |m| match m {
        apm::MavMessage::EKF_STATUS_REPORT(e) => Some(e.flags),
        _ => None,
    })
}

fn prearm_health(msgs: &[apm::MavMessage]) -> Vec<bool> {
    use apm::MavSysStatusSensor as S;
    of(msgs, |m| match m {
        apm::MavMessage::SYS_STATUS(s) => {
            assert!(
                s.onboard_control_sensors_present
                    .contains(S::MAV_SYS_STATUS_PREARM_CHECK)
                    && s.onboard_control_sensors_enabled
                        .contains(S::MAV_SYS_STATUS_PREARM_CHECK)
            );
            Some(
                s.onboard_control_sensors_health
                    .contains(S::MAV_SYS_STATUS_PREARM_CHECK),
            )
        }
        _ => None,
    })
}

/// A COMMAND_INT with `command` and params 1–4 (frame 0, x = y = z = 0).
fn command_int(command: u16, p: [f32; 4]) -> Frame {
    raw_command(75, 35, command, &p)
}

/// A COMMAND_LONG with any command number (the dialect's enum lacks some).
fn command_raw(command: u16, p: [f32; 7]) -> Frame {
    raw_command(76, 33, command, &p)
}

#[test]
fn autopilot_version_has_honest_capabilities_and_a_stable_uid() {
    use apm::MavProtocolCapability as C;
    let mut ep = endpoint();
    let out = ep.handle(GCS, &command_raw(520, [1.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0]));
    assert_eq!(acks(&out), vec![(520, 0)]);
    let v = of(&decode(&out), |m| match m {
        apm::MavMessage::AUTOPILOT_VERSION(v) => Some(v.clone()),
        _ => None,
    });
    assert_eq!(v.len(), 1, "one AUTOPILOT_VERSION after the ACK");
    let caps = v[0].capabilities;
    for want in [
        C::MAV_PROTOCOL_CAPABILITY_MISSION_INT,
        C::MAV_PROTOCOL_CAPABILITY_MISSION_FLOAT,
        C::MAV_PROTOCOL_CAPABILITY_COMMAND_INT,
        C::MAV_PROTOCOL_CAPABILITY_SET_POSITION_TARGET_GLOBAL_INT,
        C::MAV_PROTOCOL_CAPABILITY_SET_POSITION_TARGET_LOCAL_NED,
        C::MAV_PROTOCOL_CAPABILITY_MAVLINK2,
    ] {
        assert!(caps.contains(want), "{want:?} missing from {caps:?}");
    }
    assert!(
        !caps.contains(C::MAV_PROTOCOL_CAPABILITY_FTP),
        "FTP is not served"
    );
    assert_ne!(v[0].flight_sw_version, 0);
    assert_eq!(v[0].uid, super::identity::uid(vtol_link::SystemId(1)));
    assert_ne!(
        super::identity::uid(vtol_link::SystemId(1)),
        super::identity::uid(vtol_link::SystemId(2))
    );
}

#[test]
fn ekf_report_and_prearm_bit_follow_the_calibration() {
    // Real (seeded) sensors: ideal ones need no calibration.
    let mut config = EndpointConfig::default();
    config.vehicle.calibrated = false;
    let mut ep = Endpoint::new(config);
    ep.add_link(GCS);
    // During the 1 s gyro calibration: nothing but UNINITIALIZED, pre-arm failing, said why.
    let early = decode(&run_until(&mut ep, 500_000));
    assert_eq!(
        ekf_flags(&early),
        vec![apm::EkfStatusFlags::EKF_UNINITIALIZED]
    );
    assert_eq!(prearm_health(&early), vec![false]);
    let t = texts(&early);
    assert_eq!(t, vec!["PreArm: gyro calibration in progress".to_owned()]);
    let arm = ep.handle(
        GCS,
        &v2(&command_long(
            apm::MavCmd::MAV_CMD_COMPONENT_ARM_DISARM,
            [1.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0],
            0,
        )),
    );
    assert_eq!(acks(&arm), vec![(400, 4)], "FAILED while calibrating");
    // After it: attitude, velocity and position (DroneKit's is_armable needs PRED_POS_HORIZ_ABS).
    let later = decode(&run_until(&mut ep, 2_600_000));
    let flags = *ekf_flags(&later).last().expect("an EKF report");
    use apm::EkfStatusFlags as F;
    for want in [
        F::EKF_ATTITUDE,
        F::EKF_VELOCITY_HORIZ,
        F::EKF_POS_HORIZ_ABS,
        F::EKF_PRED_POS_HORIZ_ABS,
        F::EKF_POS_VERT_ABS,
    ] {
        assert!(flags.contains(want), "{want:?} missing from {flags:?}");
    }
    assert!(!flags.contains(F::EKF_UNINITIALIZED));
    assert_eq!(prearm_health(&later).last(), Some(&true));
    assert!(texts(&later).is_empty(), "no pre-arm text once it passes");
}

#[test]
fn arming_sends_the_changed_heartbeat_at_once() {
    let mut ep = endpoint();
    run_until(&mut ep, 100_000);
    let out = decode(&ep.handle(
        GCS,
        &v2(&command_long(
            apm::MavCmd::MAV_CMD_COMPONENT_ARM_DISARM,
            [1.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0],
            0,
        )),
    ));
    let hb = heartbeat_of(&out);
    assert!(
        hb.base_mode
            .contains(apm::MavModeFlag::MAV_MODE_FLAG_SAFETY_ARMED)
    );
    // A mode change likewise.
    let out = decode(&ep.handle(
        GCS,
        &v2(&command_long(
            apm::MavCmd::MAV_CMD_DO_SET_MODE,
            [1.0, 18.0, 0.0, 0.0, 0.0, 0.0, 0.0],
            0,
        )),
    ));
    assert_eq!(heartbeat_of(&out).custom_mode, 18);
}

#[test]
fn sdk_commands_get_ardupilots_results_once_long_and_int() {
    let mut ep = endpoint();
    run_until(&mut ep, 100_000);
    // (command, params, result): DO_CHANGE_SPEED accepted and checked; the landing commands
    // are modes or mission items on ArduPlane; HOME_POSITION and AUTOPILOT_VERSION by request;
    // a message interval, home here, MISSION_START with no mission, and RTL last (it changes
    // the mode).
    let cases: [(u16, [f32; 4], u8); 11] = [
        (178, [1.0, 5.0, -1.0, 0.0], 0),
        (178, [9.0, 5.0, -1.0, 0.0], 4),
        (21, [0.0; 4], 3),
        (85, [0.0; 4], 3),
        (512, [242.0, 0.0, 0.0, 0.0], 0),
        (410, [0.0; 4], 0),
        (520, [1.0, 0.0, 0.0, 0.0], 0),
        (511, [30.0, 100_000.0, 0.0, 0.0], 0),
        (179, [1.0, 0.0, 0.0, 0.0], 0),
        (300, [0.0; 4], 4),
        (20, [0.0; 4], 0),
    ];
    for (command, p, want) in cases {
        for frame in [
            command_raw(command, [p[0], p[1], p[2], p[3], 0.0, 0.0, 0.0]),
            command_int(command, p),
        ] {
            let out = ep.handle(GCS, &frame);
            assert_eq!(acks(&out), vec![(command, want)], "command {command}");
            if matches!(command, 512 | 410) {
                let homes = of(&decode(&out), |m| {
                    matches!(m, apm::MavMessage::HOME_POSITION(_)).then_some(())
                });
                assert_eq!(homes.len(), 1, "one HOME_POSITION for {command}");
            }
        }
    }
}
