//! Commands and their acknowledgements read and built from raw bytes, for command numbers the
//! dialect's `MavCmd` does not know; a ground station's heartbeat.

use super::Frame;
use crate::dialect::MavMessage;
use crate::ids::{ComponentId, SystemId};
use crate::protocol::{CRC_EXTRA_COMMAND_ACK, id};

/// A COMMAND_LONG or COMMAND_INT read from raw bytes (see [`Frame::raw_command`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RawCommand {
    /// MAV_CMD value, even ones the dialect does not define.
    pub command: u16,
    /// Addressed system (0 = all).
    pub target_system: u8,
    /// Addressed component (0 = all).
    pub target_component: u8,
    /// The fields that differ between the two messages.
    pub kind: RawCommandKind,
}

/// The message-specific part of a [`RawCommand`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum RawCommandKind {
    /// COMMAND_LONG (76).
    Long {
        /// param1..param7.
        params: [f32; 7],
        /// 0 for the first transmission, incremented on retries.
        confirmation: u8,
    },
    /// COMMAND_INT (75).
    Int {
        /// param1..param4.
        params: [f32; 4],
        /// param5 (latitude in 1e-7 deg or local x).
        x: i32,
        /// param6.
        y: i32,
        /// param7.
        z: f32,
        /// MAV_FRAME value.
        frame: u8,
        /// Unused by MAVLink (kept for completeness).
        current: u8,
        /// Unused by MAVLink (kept for completeness).
        autocontinue: u8,
    },
}

/// A COMMAND_ACK built by hand, for command ids the typed `MavCmd` rejects (PROTOCOL.md E.6.1).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct RawCommandAck {
    /// The command being acknowledged (any u16).
    pub command: u16,
    /// MAV_RESULT value (3 = UNSUPPORTED).
    pub result: u8,
    /// Progress in percent, 255 if unknown.
    pub progress: u8,
    /// Additional result information.
    pub result_param2: i32,
    /// System that sent the command.
    pub target_system: u8,
    /// Component that sent the command.
    pub target_component: u8,
}

impl RawCommandAck {
    /// MAV_RESULT_UNSUPPORTED.
    pub const RESULT_UNSUPPORTED: u8 = 3;

    /// An ack with `result` for `command`, addressed back to its sender (progress 255 "not
    /// in progress", `result_param2` 0).
    pub fn new(
        command: u16,
        result: u8,
        sender_system: SystemId,
        sender_component: ComponentId,
    ) -> Self {
        RawCommandAck {
            command,
            result,
            progress: 0xFF,
            result_param2: 0,
            target_system: sender_system.0,
            target_component: sender_component.0,
        }
    }

    /// An UNSUPPORTED ack for `cmd`, addressed back to its sender.
    pub fn unsupported(
        cmd: &RawCommand,
        sender_system: SystemId,
        sender_component: ComponentId,
    ) -> Self {
        RawCommandAck {
            command: cmd.command,
            result: Self::RESULT_UNSUPPORTED,
            progress: 0xFF,
            result_param2: 0,
            target_system: sender_system.0,
            target_component: sender_component.0,
        }
    }

    /// Reads a COMMAND_ACK (77) without the typed decoder, so that acks of commands the
    /// dialect's `MavCmd` does not know are read too; `None` for any other message.
    #[must_use]
    pub fn from_frame(frame: &Frame) -> Option<Self> {
        if frame.message_id() != id::COMMAND_ACK {
            return None;
        }
        // Zero-fill the truncated v2 payload.
        let p: [u8; 10] = frame.payload_padded();
        Some(RawCommandAck {
            command: u16::from_le_bytes([p[0], p[1]]),
            result: p[2],
            progress: p[3],
            result_param2: i32::from_le_bytes([p[4], p[5], p[6], p[7]]),
            target_system: p[8],
            target_component: p[9],
        })
    }

    /// The ack as an unsigned MAVLink 2 frame (payload trailing zeros stripped).
    pub fn to_frame(&self, system_id: SystemId, component_id: ComponentId, seq: u8) -> Frame {
        let c = self.command.to_le_bytes();
        let r = self.result_param2.to_le_bytes();
        let payload = [
            c[0],
            c[1],
            self.result,
            self.progress,
            r[0],
            r[1],
            r[2],
            r[3],
            self.target_system,
            self.target_component,
        ];
        let len = mavlink::utils::remove_trailing_zeroes(&payload);
        Frame::encode_raw_v2(
            system_id,
            component_id,
            seq,
            id::COMMAND_ACK,
            &payload[..len],
            CRC_EXTRA_COMMAND_ACK,
        )
        .unwrap_or_else(|e| unreachable!("10-byte ack does not frame: {e}"))
    }
}

/// A ground station's HEARTBEAT (type GCS, autopilot INVALID, no mode, active), built field by
/// field: the dialect's `Default` would report ARMED. What the daemon sends as its identity, and
/// what tests use to speak as a ground station.
#[must_use]
pub fn gcs_heartbeat() -> MavMessage {
    use crate::dialect::{HEARTBEAT_DATA, MavAutopilot, MavModeFlag, MavState, MavType};
    MavMessage::HEARTBEAT(HEARTBEAT_DATA {
        custom_mode: 0,
        mavtype: MavType::MAV_TYPE_GCS,
        autopilot: MavAutopilot::MAV_AUTOPILOT_INVALID,
        base_mode: MavModeFlag::empty(),
        system_status: MavState::MAV_STATE_ACTIVE,
        mavlink_version: 3,
    })
}

/// A COMMAND_LONG of `command` with `params` (param1..param7) to `target` (system, component),
/// its `confirmation` the number of sends before it (0 for the first).
#[must_use]
pub fn command_long(
    target: (SystemId, ComponentId),
    command: crate::dialect::MavCmd,
    params: [f32; 7],
    confirmation: u8,
) -> MavMessage {
    let [param1, param2, param3, param4, param5, param6, param7] = params;
    MavMessage::COMMAND_LONG(crate::dialect::COMMAND_LONG_DATA {
        param1,
        param2,
        param3,
        param4,
        param5,
        param6,
        param7,
        command,
        target_system: target.0.0,
        target_component: target.1.0,
        confirmation,
    })
}
