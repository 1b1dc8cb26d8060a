//! Frames built, parsed and read.

use super::*;
use crate::dialect as apm;

fn heartbeat() -> MavMessage {
    MavMessage::HEARTBEAT(apm::HEARTBEAT_DATA {
        custom_mode: 17,
        mavtype: apm::MavType::MAV_TYPE_VTOL_TAILSITTER_DUOROTOR,
        autopilot: apm::MavAutopilot::MAV_AUTOPILOT_GENERIC,
        base_mode: apm::MavModeFlag::from_bits_retain(0x81),
        system_status: apm::MavState::MAV_STATE_STANDBY,
        mavlink_version: 3,
    })
}

proptest::proptest! {
    /// The sliced CRC is the `mavlink` crate's, byte for byte, at every length.
    #[test]
    fn frame_crc_is_the_mavlink_crates(data in proptest::collection::vec(proptest::prelude::any::<u8>(), 0..300), extra: u8) {
        proptest::prop_assert_eq!(frame_crc(&data, extra), mavlink::calculate_crc(&data, extra));
    }
}

#[test]
fn heartbeat_bytes_match_protocol_probe() {
    // PROTOCOL.md D.1 [probe] bytes.
    let v2 = Frame::encode_v2(SystemId(1), ComponentId(1), 0, &heartbeat());
    assert_eq!(
        v2.as_bytes(),
        &[
            0xfd, 0x09, 0, 0, 0, 1, 1, 0, 0, 0, 0x11, 0, 0, 0, 0x13, 0, 0x81, 3, 3, 0xb8, 0xcf
        ]
    );
    let v1 = Frame::encode_v1(SystemId(1), ComponentId(1), 0, &heartbeat()).unwrap();
    assert_eq!(
        v1.as_bytes(),
        &[
            0xfe, 0x09, 0, 1, 1, 0, 0x11, 0, 0, 0, 0x13, 0, 0x81, 3, 3, 0x22, 0x0c
        ]
    );
    for f in [v1, v2] {
        assert!(f.is_verified());
        assert_eq!(f.decode().unwrap(), heartbeat());
        assert_eq!(f.target(), None);
        assert_eq!(f.message_name(), Some("HEARTBEAT"));
        assert_eq!(Frame::from_bytes(f.bytes().clone()).unwrap(), f);
    }
}

#[test]
fn from_bytes_rejects_bad_crc_and_lengths() {
    let f = Frame::encode_v2(SystemId(1), ComponentId(1), 0, &heartbeat());
    let mut b = f.as_bytes().to_vec();
    b[12] ^= 1;
    assert!(matches!(
        Frame::from_bytes(Bytes::from(b.clone())),
        Err(FrameError::BadCrc { message_id: 0 })
    ));
    b.pop();
    assert!(matches!(
        Frame::from_bytes(Bytes::from(b)),
        Err(FrameError::LengthMismatch { .. })
    ));
    let mut b = f.as_bytes().to_vec();
    b[2] = 0x02;
    assert!(matches!(
        Frame::from_bytes(Bytes::from(b)),
        Err(FrameError::BadIncompat(2))
    ));
}

#[test]
fn target_matches_typed_decoder_for_every_message() {
    let mut with_target = 0;
    for &id in dialect_table().keys() {
        let mut msg = MavMessage::default_message_from_id(id).unwrap();
        if let Some(t) = msg.target_system_id_mut() {
            *t = 0x12;
        }
        if let Some(t) = msg.target_component_id_mut() {
            *t = 0x34;
        }
        let f = Frame::encode_v2(SystemId(7), ComponentId(8), 9, &msg);
        let expected = msg
            .target_system_id()
            .map(|s| (s, msg.target_component_id().unwrap_or(0)));
        assert_eq!(f.target(), expected, "message {}", msg.message_name());
        with_target += usize::from(expected.is_some());
    }
    assert!(with_target > 50, "only {with_target} messages with targets");
}

#[test]
fn target_survives_unknown_enum_and_truncation() {
    // COMMAND_ACK for command 11 (SET_MODE is a message, not a MAV_CMD): typed decode fails.
    let ack = RawCommandAck {
        command: 11,
        result: 0,
        progress: 0,
        result_param2: 0,
        target_system: 255,
        target_component: 0,
    };
    let f = ack.to_frame(SystemId(1), ComponentId(1), 5);
    assert!(f.is_verified());
    assert!(matches!(f.decode(), Err(FrameError::Parse { .. })));
    assert_eq!(f.target(), Some((255, 0)));
    // Payload: 0b 00 00 00 00 00 00 00 ff -> 9 bytes (trailing zero stripped).
    assert_eq!(f.payload_len(), 9);
}

#[test]
fn raw_command_reads_long_and_int() {
    let long = MavMessage::COMMAND_LONG(apm::COMMAND_LONG_DATA {
        param1: 1.0,
        param2: 21196.0,
        command: apm::MavCmd::MAV_CMD_COMPONENT_ARM_DISARM,
        target_system: 1,
        target_component: 0,
        confirmation: 2,
        ..Default::default()
    });
    let f = Frame::encode_v2(SystemId(255), ComponentId(190), 0, &long);
    let c = f.raw_command().unwrap();
    assert_eq!(c.command, 400);
    assert_eq!((c.target_system, c.target_component), (1, 0));
    assert!(matches!(
        c.kind,
        RawCommandKind::Long { params, confirmation: 2 } if params[1] == 21196.0
    ));
    let int = MavMessage::COMMAND_INT(apm::COMMAND_INT_DATA {
        x: -5,
        command: apm::MavCmd::MAV_CMD_DO_REPOSITION,
        target_system: 3,
        target_component: 1,
        frame: apm::MavFrame::MAV_FRAME_GLOBAL_RELATIVE_ALT,
        ..Default::default()
    });
    let c = Frame::encode_v2(SystemId(255), ComponentId(190), 0, &int)
        .raw_command()
        .unwrap();
    assert_eq!(c.command, 192);
    assert_eq!((c.target_system, c.target_component), (3, 1));
    assert!(matches!(
        c.kind,
        RawCommandKind::Int {
            x: -5,
            frame: 3,
            ..
        }
    ));
    assert!(
        Frame::encode_v2(SystemId(1), ComponentId(1), 0, &heartbeat())
            .raw_command()
            .is_none()
    );
}

#[test]
fn payload_built_by_hand_is_trimmed_and_read_back_zero_filled() {
    // COMMAND_ACK (77): command 400, result 0, then zeros up to the targets (255, 190).
    let mut p = [0u8; 10];
    p[..2].copy_from_slice(&400u16.to_le_bytes());
    p[3] = 0xFF;
    let f = Frame::encode_payload_v2(
        SystemId(1),
        ComponentId(1),
        4,
        crate::protocol::id::COMMAND_ACK,
        &p,
    )
    .unwrap();
    assert!(f.is_verified());
    assert_eq!(f.payload(), &p[..4], "trailing zeros stripped");
    assert_eq!(f.payload_padded::<10>(), p);
    assert_eq!(f.payload_padded::<2>(), [0x90, 0x01]);
    // The same bytes as the dedicated builder's.
    let ack = RawCommandAck::new(400, 0, SystemId(0), ComponentId(0)).to_frame(
        SystemId(1),
        ComponentId(1),
        4,
    );
    assert_eq!(ack, f);
    assert!(matches!(
        Frame::encode_payload_v2(SystemId(1), ComponentId(1), 0, 60_000, &p),
        Err(FrameError::UnknownMessage(60_000))
    ));
}

#[test]
fn unsupported_ack_for_unknown_command_decodes_in_raw_form() {
    // COMMAND_LONG with a command the dialect rejects, built by hand.
    let mut p = [0u8; 33];
    p[28..30].copy_from_slice(&65000u16.to_le_bytes());
    p[30] = 1;
    p[31] = 1;
    let f = Frame::encode_raw_v2(
        SystemId(255),
        ComponentId(190),
        3,
        crate::protocol::id::COMMAND_LONG,
        &p[..32],
        152,
    )
    .unwrap();
    assert!(f.is_verified());
    assert!(f.decode().is_err());
    let cmd = f.raw_command().unwrap();
    assert_eq!(cmd.command, 65000);
    let ack =
        RawCommandAck::unsupported(&cmd, SystemId(f.system_id()), ComponentId(f.component_id()))
            .to_frame(SystemId(1), ComponentId(1), 0);
    assert_eq!(ack.target(), Some((255, 190)));
    assert_eq!(ack.payload(), &[0xe8, 0xfd, 3, 0xff, 0, 0, 0, 0, 255, 190]);
    assert_eq!(Frame::from_bytes(ack.bytes().clone()).unwrap(), ack);
}

/// A HEARTBEAT with a MAV_TYPE the dialect does not define (60) decodes, the type read as the
/// default and the wire value kept, as pymavlink keeps it.
#[test]
fn an_unknown_enum_value_decodes_leniently() {
    let mut p = [0u8; 9];
    p[..4].copy_from_slice(&5u32.to_le_bytes());
    p[4] = 60; // type
    p[5] = 3; // autopilot ARDUPILOTMEGA
    p[6] = 0x81;
    p[7] = 4; // ACTIVE
    p[8] = 3;
    let f = Frame::encode_payload_v2(SystemId(1), ComponentId(1), 0, 0, &p).unwrap();
    assert!(matches!(
        f.decode(),
        Err(FrameError::Parse { message_id: 0, .. })
    ));
    let l = f.decode_lenient().unwrap();
    let MavMessage::HEARTBEAT(hb) = &l.msg else {
        panic!("{l:?}")
    };
    assert_eq!(hb.custom_mode, 5);
    assert_eq!(hb.autopilot, apm::MavAutopilot::MAV_AUTOPILOT_ARDUPILOTMEGA);
    assert_eq!(hb.system_status, apm::MavState::MAV_STATE_ACTIVE);
    assert_eq!(l.raw("MavType"), Some(60));
    assert_eq!(l.replaced.len(), 1);
    assert_eq!(l.replaced[0].field.offset, 4);
    assert_eq!(f.payload()[4], 60);
    // Two bad fields at once: type and system_status.
    p[7] = 200;
    let f = Frame::encode_payload_v2(SystemId(1), ComponentId(1), 0, 0, &p).unwrap();
    let l = f.decode_lenient().unwrap();
    assert_eq!(l.raw("MavType"), Some(60));
    assert_eq!(l.raw("MavState"), Some(200));
    // A frame that decodes exactly has nothing replaced.
    let ok = Frame::encode_v2(SystemId(1), ComponentId(1), 0, &heartbeat());
    assert!(ok.decode_lenient().unwrap().replaced.is_empty());
}

/// A COMMAND_ACK of a command number the dialect lacks (a two-byte enum, with MAV_RESULT and
/// the extension fields after it) decodes with every other field intact.
#[test]
fn a_command_ack_of_an_unknown_command_decodes() {
    let ack = RawCommandAck {
        command: 31_337,
        result: 0,
        progress: 7,
        result_param2: -3,
        target_system: 255,
        target_component: 190,
    };
    let f = ack.to_frame(SystemId(1), ComponentId(1), 9);
    assert!(f.decode().is_err());
    let l = f.decode_lenient().unwrap();
    let MavMessage::COMMAND_ACK(a) = &l.msg else {
        panic!("{l:?}")
    };
    assert_eq!(l.raw("MavCmd"), Some(31_337));
    assert_eq!(l.replaced[0].field.width, 2);
    assert_eq!(a.result, apm::MavResult::MAV_RESULT_ACCEPTED);
    assert_eq!(
        (
            a.progress,
            a.result_param2,
            a.target_system,
            a.target_component
        ),
        (7, -3, 255, 190)
    );
}

/// Every enum field the dialect declares is found at its place: a field set to an undefined
/// value in any message decodes leniently, with that value reported.
#[test]
fn every_messages_enum_fields_are_learnt() {
    let hb = enum_fields(0);
    assert_eq!(
        hb.iter()
            .map(|f| (f.offset, f.width, f.enum_type))
            .collect::<Vec<_>>(),
        [
            (4, 1, "MavType"),
            (5, 1, "MavAutopilot"),
            (7, 1, "MavState")
        ]
    );
    let mut messages = 0;
    for id in known_message_ids() {
        for f in enum_fields(id) {
            let msg = MavMessage::default_message_from_id(id).unwrap();
            let mut p = [0u8; 255];
            msg.ser(MavlinkVersion::V2, &mut p);
            let at = usize::from(f.offset);
            let w = usize::from(f.width);
            p[at..at + w].fill(0xA5);
            let frame = Frame::encode_payload_v2(SystemId(1), ComponentId(1), 0, id, &p).unwrap();
            // 0xA5.. is a defined value of a few enums.
            if frame.decode().is_ok() {
                continue;
            }
            let l = frame
                .decode_lenient()
                .unwrap_or_else(|e| panic!("{id} {f:?}: {e}"));
            assert!(l.replaced.iter().any(|r| r.field == f), "{id} {f:?}");
            messages += 1;
        }
    }
    assert!(messages > 50, "{messages}");
}
