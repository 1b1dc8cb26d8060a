//! Frame-level helpers: parse one complete v1/v2 frame, encode v2 frames, and the raw payload
//! paths for what the `mavlink` 0.21 typed decoder cannot handle (command ids and param types
//! outside the dialect's enums, `PROTOCOL.md` E.6).
//!
//! Byte streams are split into frames by `vtol_link::FrameDecoder` before they get here.

use mavlink::dialects::ardupilotmega::MavMessage;
use mavlink::{MAVLinkV2MessageRaw, MavHeader, MavlinkVersion, Message};

/// One received frame, header fields decoded, payload zero-filled to the message's full length
/// when the v2 sender truncated trailing zeros.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct InFrame {
    /// Framing the sender used.
    pub version: MavlinkVersion,
    /// Sender system id.
    pub sysid: u8,
    /// Sender component id.
    pub compid: u8,
    /// Message id.
    pub msgid: u32,
    /// Payload bytes as received (not zero-filled).
    pub payload: Vec<u8>,
}

/// Why bytes are not a usable frame.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum WireError {
    /// Too short, wrong magic, or the length byte disagrees with the slice.
    #[error("malformed frame")]
    Malformed,
    /// The message id is not in the dialect, so its CRC cannot be checked.
    #[error("message id {0} not in the dialect")]
    UnknownMessage(u32),
    /// Checksum mismatch.
    #[error("bad CRC on message {0}")]
    BadCrc(u32),
    /// An incompatibility flag other than signing is set.
    #[error("unsupported incompat flags {0:#04x}")]
    Incompatible(u8),
}

/// Whether the dialect knows a message id (and so its CRC_EXTRA).
#[must_use]
pub fn known_message(msgid: u32) -> bool {
    MavMessage::default_message_from_id(msgid).is_some()
}

/// Total frame length implied by a buffer starting at a magic byte, if the header is complete.
#[must_use]
pub fn frame_len(buf: &[u8]) -> Option<usize> {
    match *buf.first()? {
        0xFE => Some(6 + usize::from(*buf.get(1)?) + 2),
        0xFD => {
            let len = usize::from(*buf.get(1)?);
            let signed = buf.get(2)? & 0x01 != 0;
            Some(10 + len + 2 + if signed { 13 } else { 0 })
        }
        _ => None,
    }
}

/// Parses and CRC-checks exactly one frame.
///
/// # Errors
/// See [`WireError`].
pub fn parse_frame(bytes: &[u8]) -> Result<InFrame, WireError> {
    let total = frame_len(bytes).ok_or(WireError::Malformed)?;
    if bytes.len() != total {
        return Err(WireError::Malformed);
    }
    let len = usize::from(bytes[1]);
    let (version, header_len, sysid, compid, msgid) = if bytes[0] == 0xFE {
        (
            MavlinkVersion::V1,
            6,
            bytes[3],
            bytes[4],
            u32::from(bytes[5]),
        )
    } else {
        let incompat = bytes[2];
        if incompat & !0x01 != 0 {
            return Err(WireError::Incompatible(incompat));
        }
        let msgid = u32::from_le_bytes([bytes[7], bytes[8], bytes[9], 0]);
        (MavlinkVersion::V2, 10, bytes[5], bytes[6], msgid)
    };
    if !known_message(msgid) {
        return Err(WireError::UnknownMessage(msgid));
    }
    let crc_at = header_len + len;
    let crc = mavlink::calculate_crc(&bytes[1..crc_at], MavMessage::extra_crc(msgid));
    if crc.to_le_bytes() != bytes[crc_at..crc_at + 2] {
        return Err(WireError::BadCrc(msgid));
    }
    Ok(InFrame {
        version,
        sysid,
        compid,
        msgid,
        payload: bytes[header_len..crc_at].to_vec(),
    })
}

impl InFrame {
    /// The payload zero-filled to at least `n` bytes (MAVLink 2 truncation, extensions absent).
    #[must_use]
    pub fn padded(&self, n: usize) -> Vec<u8> {
        let mut p = self.payload.clone();
        if p.len() < n {
            p.resize(n, 0);
        }
        p
    }

    /// Typed decode with the dialect.
    ///
    /// # Errors
    /// The crate's parser error (e.g. an enum value the XML does not define).
    pub fn decode(&self) -> Result<MavMessage, mavlink::error::ParserError> {
        MavMessage::parse(self.version, self.msgid, &self.payload)
    }
}

/// Encodes a typed message as a MAVLink 2 frame.
#[must_use]
pub fn encode_v2(seq: u8, sysid: u8, compid: u8, msg: &MavMessage) -> Vec<u8> {
    let mut raw = MAVLinkV2MessageRaw::new();
    let header = MavHeader {
        system_id: u32::from(sysid),
        component_id: compid,
        sequence: seq,
    };
    raw.serialize_message(header, msg);
    raw.raw_bytes().to_vec()
}

/// Encodes a hand-built payload as a MAVLink 2 frame (trailing zeros trimmed as the spec says).
#[must_use]
pub fn encode_v2_raw(seq: u8, sysid: u8, compid: u8, msgid: u32, payload: &[u8]) -> Vec<u8> {
    let mut len = payload.len();
    while len > 1 && payload[len - 1] == 0 {
        len -= 1;
    }
    let id = msgid.to_le_bytes();
    let mut f = vec![
        0xFD, len as u8, 0, 0, seq, sysid, compid, id[0], id[1], id[2],
    ];
    f.extend_from_slice(&payload[..len]);
    let crc = mavlink::calculate_crc(&f[1..], MavMessage::extra_crc(msgid));
    f.extend_from_slice(&crc.to_le_bytes());
    f
}

/// COMMAND_ACK payload for any command number, including ones the dialect's `MavCmd` lacks:
/// `command u16, result u8, progress u8, result_param2 i32, target_system u8, target_component u8`.
#[must_use]
pub fn command_ack_payload(command: u16, result: u8, target: (u8, u8)) -> [u8; 10] {
    let c = command.to_le_bytes();
    // progress 255 = "not in progress"; result_param2 0.
    [c[0], c[1], result, 255, 0, 0, 0, 0, target.0, target.1]
}

/// A COMMAND_LONG or COMMAND_INT read from raw payload bytes, so unknown command ids still get
/// their ACK.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RawCommand {
    /// Command number.
    pub command: u16,
    /// param1..param7 (COMMAND_INT: x, y as f32 of the integer, z).
    pub params: [f32; 7],
    /// Addressed system.
    pub target_system: u8,
    /// Addressed component.
    pub target_component: u8,
    /// Retransmission counter (COMMAND_LONG only; 0 for COMMAND_INT).
    pub confirmation: u8,
    /// Came as COMMAND_INT.
    pub is_int: bool,
    /// COMMAND_INT's x as sent (latitude in 1e-7 degree in global frames); 0 for COMMAND_LONG.
    pub x: i32,
    /// COMMAND_INT's y as sent (longitude in 1e-7 degree); 0 for COMMAND_LONG.
    pub y: i32,
    /// COMMAND_INT's `MAV_FRAME`; 0 for COMMAND_LONG.
    pub frame: u8,
}

/// COMMAND_LONG id.
pub const COMMAND_LONG_ID: u32 = 76;
/// COMMAND_INT id.
pub const COMMAND_INT_ID: u32 = 75;

/// Reads a command from a COMMAND_LONG (76) or COMMAND_INT (75) frame without the typed decoder.
#[must_use]
pub fn raw_command(frame: &InFrame) -> Option<RawCommand> {
    let f32_at = |p: &[u8], i: usize| f32::from_le_bytes([p[i], p[i + 1], p[i + 2], p[i + 3]]);
    let i32_at = |p: &[u8], i: usize| i32::from_le_bytes([p[i], p[i + 1], p[i + 2], p[i + 3]]);
    match frame.msgid {
        COMMAND_LONG_ID => {
            let p = frame.padded(33);
            let mut params = [0.0; 7];
            for (k, v) in params.iter_mut().enumerate() {
                *v = f32_at(&p, 4 * k);
            }
            Some(RawCommand {
                command: u16::from_le_bytes([p[28], p[29]]),
                params,
                target_system: p[30],
                target_component: p[31],
                confirmation: p[32],
                is_int: false,
                x: 0,
                y: 0,
                frame: 0,
            })
        }
        COMMAND_INT_ID => {
            // param1..4 f32, x i32, y i32, z f32, command u16, tsys, tcomp, frame, current, autocontinue.
            let p = frame.padded(35);
            let params = [
                f32_at(&p, 0),
                f32_at(&p, 4),
                f32_at(&p, 8),
                f32_at(&p, 12),
                i32_at(&p, 16) as f32,
                i32_at(&p, 20) as f32,
                f32_at(&p, 24),
            ];
            Some(RawCommand {
                command: u16::from_le_bytes([p[28], p[29]]),
                params,
                target_system: p[30],
                target_component: p[31],
                confirmation: 0,
                is_int: true,
                x: i32_at(&p, 16),
                y: i32_at(&p, 20),
                frame: p[32],
            })
        }
        _ => None,
    }
}

/// PARAM_SET read from raw bytes: the typed decoder refuses `param_type` values outside the enum
/// (pymavlink may send 0), and the contract says to ignore the type anyway.
#[must_use]
pub fn raw_param_set(frame: &InFrame) -> Option<(f32, u8, u8, String)> {
    if frame.msgid != 23 {
        return None;
    }
    let p = frame.padded(23);
    let value = f32::from_le_bytes([p[0], p[1], p[2], p[3]]);
    Some((value, p[4], p[5], param_id_from(&p[6..22])))
}

/// A `char[16]` parameter id: up to the first NUL, all 16 bytes when full.
#[must_use]
pub fn param_id_from(bytes: &[u8]) -> String {
    let end = bytes.iter().position(|&b| b == 0).unwrap_or(bytes.len());
    String::from_utf8_lossy(&bytes[..end]).into_owned()
}
