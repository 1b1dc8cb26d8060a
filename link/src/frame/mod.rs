//! One complete MAVLink frame held as raw, cheaply clonable bytes.
//!
//! The daemon forwards frames unchanged (sequence numbers and signatures must survive the
//! bridge), so the wire bytes are the source of truth and every field is read from them on
//! demand. Typed decoding through the `mavlink` crate is optional and may fail (strict enums,
//! PROTOCOL.md E.6.1) without losing the frame. Routing data (`target()`) is read from byte
//! offsets learnt once from the dialect, so it works even when the typed decode would fail.

mod command;
mod dialect;
mod lenient;
mod source;
#[cfg(test)]
mod tests;

use std::fmt;

use bytes::Bytes;
use mavlink::{MavlinkVersion, Message};

use crate::dialect::MavMessage;
use crate::ids::{ComponentId, SystemId};
use crate::protocol::id;

pub use command::{RawCommand, RawCommandAck, RawCommandKind, command_long, gcs_heartbeat};
use dialect::dialect_table;
pub use dialect::{crc_extra, frame_crc, frame_len_from_prefix, known_message_ids, message_name};
pub use lenient::{EnumField, Lenient, Replaced, enum_fields};
pub use source::FrameSource;

/// First byte of a MAVLink 1 frame.
pub const MAGIC_V1: u8 = 0xFE;
/// First byte of a MAVLink 2 frame.
pub const MAGIC_V2: u8 = 0xFD;
/// Bytes before the payload in a v1 frame (magic included).
pub const HEADER_LEN_V1: usize = 6;
/// Bytes before the payload in a v2 frame (magic included).
pub const HEADER_LEN_V2: usize = 10;
/// Bytes of the checksum that follows the payload.
pub const CRC_LEN: usize = 2;
/// Bytes of a MAVLink 2 signature (link id, 6-byte timestamp, 6-byte signature).
pub const SIGNATURE_LEN: usize = 13;
/// The only incompat flag defined by MAVLink 2: the frame carries a signature.
pub const INCOMPAT_SIGNED: u8 = 0x01;
/// Largest possible frame: v2 header, 255-byte payload, CRC and signature.
pub const MAX_FRAME_LEN: usize = HEADER_LEN_V2 + 255 + CRC_LEN + SIGNATURE_LEN;

/// Why bytes are not a valid frame, or a frame does not decode.
#[derive(Debug, thiserror::Error)]
pub enum FrameError {
    /// Too few bytes for the header the magic announces.
    #[error("frame too short: {len_bytes} bytes")]
    TooShort {
        /// Bytes available.
        len_bytes: usize,
    },
    /// The first byte is neither 0xFE nor 0xFD.
    #[error("bad magic byte 0x{0:02x}")]
    BadMagic(u8),
    /// The header's length field disagrees with the number of bytes.
    #[error("frame length mismatch: header says {expected_bytes} bytes, got {actual_bytes}")]
    LengthMismatch {
        /// Length computed from the header.
        expected_bytes: usize,
        /// Length of the buffer.
        actual_bytes: usize,
    },
    /// A message the dialect knows, with a checksum that does not match.
    #[error("bad CRC for message id {message_id}")]
    BadCrc {
        /// The frame's message id.
        message_id: u32,
    },
    /// Incompat flags other than "signed": the frame must be dropped.
    #[error("unknown incompat flags 0x{0:02x}")]
    BadIncompat(u8),
    /// A payload longer than 255 bytes cannot be framed.
    #[error("payload of {0} bytes does not fit a frame (max 255)")]
    PayloadTooLong(usize),
    /// MAVLink 1 carries only message ids up to 255.
    #[error("message id {0} cannot be sent as MAVLink 1")]
    IdTooLargeForV1(u32),
    /// Message ids have 24 bits in MAVLink 2.
    #[error("message id {0} does not fit in 24 bits")]
    IdTooLarge(u32),
    /// The message id is not in the dialect (no CRC_EXTRA, no typed decoding).
    #[error("message id {0} is not in the dialect")]
    UnknownMessage(u32),
    /// The typed decoder rejected the payload (e.g. an enum value the XML does not define).
    #[error("cannot decode message id {message_id}: {source}")]
    Parse {
        /// The frame's message id.
        message_id: u32,
        /// The `mavlink` crate's error.
        source: mavlink::error::ParserError,
    },
}

/// One complete MAVLink v1 or v2 frame (signature included), as it was on the wire.
///
/// Cloning is cheap (reference-counted bytes), so one frame can be queued to many links.
/// Invariant: the length fields match the buffer, and if the dialect knows the message id the
/// CRC is correct ([`Frame::is_verified`]). Frames of unknown ids are kept for forwarding.
#[derive(Clone, PartialEq, Eq)]
pub struct Frame {
    bytes: Bytes,
    verified: bool,
    /// Read from `bytes` once: routing, logging and tracking ask for them many times a frame.
    message_id: u32,
    system_id: u8,
    component_id: u8,
}

impl fmt::Debug for Frame {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.debug_struct("Frame")
            .field("version", &self.version())
            .field("seq", &self.seq())
            .field("system_id", &self.system_id())
            .field("component_id", &self.component_id())
            .field("message_id", &self.message_id())
            .field("name", &self.message_name())
            .field("len_bytes", &self.bytes.len())
            .field("signed", &self.is_signed())
            .field("verified", &self.verified)
            .finish()
    }
}

impl Frame {
    /// Checks the framing of `bytes` (magic, lengths, incompat flags and, for ids the dialect
    /// knows, the CRC) and wraps them without copying.
    pub fn from_bytes(bytes: Bytes) -> Result<Frame, FrameError> {
        let first = *bytes.first().ok_or(FrameError::TooShort { len_bytes: 0 })?;
        if first != MAGIC_V1 && first != MAGIC_V2 {
            return Err(FrameError::BadMagic(first));
        }
        let expected = frame_len_from_prefix(&bytes).ok_or(FrameError::TooShort {
            len_bytes: bytes.len(),
        })?;
        if expected != bytes.len() {
            return Err(FrameError::LengthMismatch {
                expected_bytes: expected,
                actual_bytes: bytes.len(),
            });
        }
        if first == MAGIC_V2 && bytes[2] & !INCOMPAT_SIGNED != 0 {
            return Err(FrameError::BadIncompat(bytes[2]));
        }
        let mut frame = Frame::new(bytes, false);
        if let Some(extra) = crc_extra(frame.message_id()) {
            if frame.computed_crc(extra) != frame.crc() {
                return Err(FrameError::BadCrc {
                    message_id: frame.message_id(),
                });
            }
            frame.verified = true;
        }
        Ok(frame)
    }

    /// Wraps bytes whose framing the decoder already checked.
    pub(crate) fn from_checked(bytes: Bytes, verified: bool) -> Frame {
        Frame::new(bytes, verified)
    }

    /// Wraps bytes whose length fields match them (at least a whole header).
    fn new(bytes: Bytes, verified: bool) -> Frame {
        let (message_id, system_id, component_id) = if bytes[0] == MAGIC_V2 {
            (
                u32::from_le_bytes([bytes[7], bytes[8], bytes[9], 0]),
                bytes[5],
                bytes[6],
            )
        } else {
            (u32::from(bytes[5]), bytes[3], bytes[4])
        };
        Frame {
            bytes,
            verified,
            message_id,
            system_id,
            component_id,
        }
    }

    /// Builds a MAVLink 2 frame (unsigned) from a typed message. Trailing zero bytes of the
    /// payload are stripped, as the spec asks.
    pub fn encode_v2(
        system_id: SystemId,
        component_id: ComponentId,
        seq: u8,
        msg: &MavMessage,
    ) -> Frame {
        let mut payload = [0u8; 255];
        let len = msg.ser(MavlinkVersion::V2, &mut payload);
        let id = msg.message_id();
        // Cannot fail: the payload fits and the id is from the dialect itself.
        Self::encode_raw_v2(
            system_id,
            component_id,
            seq,
            id,
            &payload[..len],
            MavMessage::extra_crc(id),
        )
        .map(|mut f| {
            f.verified = true;
            f
        })
        .unwrap_or_else(|e| unreachable!("dialect message does not frame: {e}"))
    }

    /// Builds an unsigned MAVLink 2 frame from a hand-built payload of a message the dialect
    /// knows (its CRC_EXTRA is the dialect's), trailing zero bytes stripped as the spec asks:
    /// for payloads the typed encoder cannot express (enum values the dialect lacks).
    pub fn encode_payload_v2(
        system_id: SystemId,
        component_id: ComponentId,
        seq: u8,
        message_id: u32,
        payload: &[u8],
    ) -> Result<Frame, FrameError> {
        let extra = crc_extra(message_id).ok_or(FrameError::UnknownMessage(message_id))?;
        let len = mavlink::utils::remove_trailing_zeroes(payload);
        Self::encode_raw_v2(
            system_id,
            component_id,
            seq,
            message_id,
            &payload[..len],
            extra,
        )
    }

    /// Builds a MAVLink 1 frame from a typed message (no extension fields, as v1 requires).
    pub fn encode_v1(
        system_id: SystemId,
        component_id: ComponentId,
        seq: u8,
        msg: &MavMessage,
    ) -> Result<Frame, FrameError> {
        let mut payload = [0u8; 255];
        let len = msg.ser(MavlinkVersion::V1, &mut payload);
        let id = msg.message_id();
        let id_u8 = u8::try_from(id).map_err(|_| FrameError::IdTooLargeForV1(id))?;
        let mut buf = Vec::with_capacity(HEADER_LEN_V1 + len + CRC_LEN);
        buf.extend_from_slice(&[MAGIC_V1, len as u8, seq, system_id.0, component_id.0, id_u8]);
        buf.extend_from_slice(&payload[..len]);
        let crc = frame_crc(&buf[1..], MavMessage::extra_crc(id));
        buf.extend_from_slice(&crc.to_le_bytes());
        Ok(Frame::new(Bytes::from(buf), true))
    }

    /// Builds an unsigned MAVLink 2 frame from a raw payload with an explicit CRC_EXTRA, for
    /// messages the typed dialect cannot express (unknown ids, or enum values it rejects).
    /// The payload is sent as given (strip trailing zeros yourself if you care).
    pub fn encode_raw_v2(
        system_id: SystemId,
        component_id: ComponentId,
        seq: u8,
        message_id: u32,
        payload: &[u8],
        crc_extra: u8,
    ) -> Result<Frame, FrameError> {
        let len =
            u8::try_from(payload.len()).map_err(|_| FrameError::PayloadTooLong(payload.len()))?;
        let id = message_id.to_le_bytes();
        if id[3] != 0 {
            return Err(FrameError::IdTooLarge(message_id));
        }
        let mut buf = Vec::with_capacity(HEADER_LEN_V2 + payload.len() + CRC_LEN);
        buf.extend_from_slice(&[
            MAGIC_V2,
            len,
            0,
            0,
            seq,
            system_id.0,
            component_id.0,
            id[0],
            id[1],
            id[2],
        ]);
        buf.extend_from_slice(payload);
        let crc = frame_crc(&buf[1..], crc_extra);
        buf.extend_from_slice(&crc.to_le_bytes());
        let verified = crc_extra_matches(message_id, crc_extra);
        Ok(Frame::new(Bytes::from(buf), verified))
    }

    /// The protocol version (from the magic byte).
    pub fn version(&self) -> MavlinkVersion {
        if self.bytes[0] == MAGIC_V2 {
            MavlinkVersion::V2
        } else {
            MavlinkVersion::V1
        }
    }

    /// True for MAVLink 2 frames.
    pub fn is_v2(&self) -> bool {
        self.bytes[0] == MAGIC_V2
    }

    fn header_len(&self) -> usize {
        if self.is_v2() {
            HEADER_LEN_V2
        } else {
            HEADER_LEN_V1
        }
    }

    /// Payload length as on the wire (v2 may be truncated).
    pub fn payload_len(&self) -> usize {
        usize::from(self.bytes[1])
    }

    /// Packet sequence number of the sender.
    pub fn seq(&self) -> u8 {
        self.bytes[if self.is_v2() { 4 } else { 2 }]
    }

    /// Sender's system id.
    pub fn system_id(&self) -> u8 {
        self.system_id
    }

    /// Sender's component id.
    pub fn component_id(&self) -> u8 {
        self.component_id
    }

    /// Message id (24 bits in v2, 8 in v1).
    pub fn message_id(&self) -> u32 {
        self.message_id
    }

    /// Incompat flags (0 for v1).
    pub fn incompat_flags(&self) -> u8 {
        if self.is_v2() { self.bytes[2] } else { 0 }
    }

    /// True if the frame carries a MAVLink 2 signature.
    pub fn is_signed(&self) -> bool {
        self.incompat_flags() & INCOMPAT_SIGNED != 0
    }

    /// The 13 signature bytes (link id, timestamp, signature) of a signed frame.
    pub fn signature(&self) -> Option<&[u8]> {
        self.is_signed()
            .then(|| &self.bytes[self.bytes.len() - SIGNATURE_LEN..])
    }

    /// True if the dialect knows the message id and the CRC was checked against its
    /// CRC_EXTRA. False frames have only plausible framing: forward them, never trust them.
    pub fn is_verified(&self) -> bool {
        self.verified
    }

    /// The payload as on the wire (possibly truncated, not zero-filled).
    pub fn payload(&self) -> &[u8] {
        let start = self.header_len();
        &self.bytes[start..start + self.payload_len()]
    }

    /// The payload zero-filled (or cut) to `N` bytes: MAVLink 2 senders strip trailing zeros,
    /// so a reader of fixed offsets wants the full length back. Copies, never allocates.
    pub fn payload_padded<const N: usize>(&self) -> [u8; N] {
        let mut p = [0u8; N];
        let src = self.payload();
        let n = src.len().min(N);
        p[..n].copy_from_slice(&src[..n]);
        p
    }

    /// The checksum stored in the frame.
    pub fn crc(&self) -> u16 {
        let at = self.header_len() + self.payload_len();
        u16::from_le_bytes([self.bytes[at], self.bytes[at + 1]])
    }

    fn computed_crc(&self, crc_extra: u8) -> u16 {
        frame_crc(
            &self.bytes[1..self.header_len() + self.payload_len()],
            crc_extra,
        )
    }

    /// The complete frame, exactly as received (forward these bytes).
    pub fn as_bytes(&self) -> &[u8] {
        &self.bytes
    }

    /// The underlying shared buffer (cloning it does not copy).
    pub fn bytes(&self) -> &Bytes {
        &self.bytes
    }

    /// Total length in bytes, signature included.
    pub fn len(&self) -> usize {
        self.bytes.len()
    }

    /// Always false: a frame has at least a header. Present for API symmetry with `len`.
    pub fn is_empty(&self) -> bool {
        self.bytes.is_empty()
    }

    /// The dialect's name for the message id, if known.
    pub fn message_name(&self) -> Option<&'static str> {
        message_name(self.message_id())
    }

    /// Where the message is addressed: `Some((target_system, target_component))` for a
    /// message with a target field whose `target_system` is not 0; `None` means "deliver
    /// everywhere": no target field (or an id the dialect does not know), or
    /// `target_system == 0`. Messages with only a `target_system` report component 0 (all
    /// components). Truncated v2 payloads read as zero-filled. This reads byte offsets learnt
    /// from the dialect, so it works even when [`Frame::decode`] fails on an enum value.
    pub fn target(&self) -> Option<(u8, u8)> {
        let info = dialect_table().get(&self.message_id())?;
        let read = |off: Option<u8>| {
            off.map_or(0, |o| {
                self.payload().get(usize::from(o)).copied().unwrap_or(0)
            })
        };
        info.target_system_offset?;
        let system = read(info.target_system_offset);
        if system == 0 {
            return None;
        }
        Some((system, read(info.target_component_offset)))
    }

    /// The sender's (system, component), typed.
    #[must_use]
    pub fn sender(&self) -> (crate::SystemId, crate::ComponentId) {
        (SystemId(self.system_id()), ComponentId(self.component_id()))
    }

    /// [`Frame::target`], typed.
    #[must_use]
    pub fn target_ids(&self) -> Option<(crate::SystemId, crate::ComponentId)> {
        self.target().map(|(s, c)| (SystemId(s), ComponentId(c)))
    }

    /// Decodes the payload into a typed ardupilotmega message. Failure (unknown id, enum value
    /// the dialect rejects) leaves the frame intact for forwarding.
    pub fn decode(&self) -> Result<MavMessage, FrameError> {
        let id = self.message_id();
        if !self.verified {
            return Err(FrameError::UnknownMessage(id));
        }
        MavMessage::parse(self.version(), id, self.payload()).map_err(|source| FrameError::Parse {
            message_id: id,
            source,
        })
    }

    /// Decodes the payload as pymavlink does: an enum value the dialect does not define (a
    /// newer MAV_TYPE, a command number it lacks) does not fail the decode; the field holds
    /// its enum's default instead and [`Lenient::replaced`] gives the wire value. For
    /// showing, tracking and logging; code that acts on an enum's value uses
    /// [`Frame::decode`] or checks `replaced`. Fails only for an id the dialect does not know.
    pub fn decode_lenient(&self) -> Result<Lenient, FrameError> {
        let id = self.message_id();
        if !self.verified {
            return Err(FrameError::UnknownMessage(id));
        }
        lenient::parse(self.version(), id, self.payload()).map_err(|source| FrameError::Parse {
            message_id: id,
            source,
        })
    }

    /// A HEARTBEAT's `type` (MAV_TYPE) and `autopilot` (MAV_AUTOPILOT) as on the wire, values
    /// the dialect does not define included; `None` for other messages.
    pub fn heartbeat_kind(&self) -> Option<(u8, u8)> {
        (self.message_id() == id::HEARTBEAT && self.verified).then(|| {
            let p = self.payload_padded::<9>();
            (p[4], p[5])
        })
    }

    /// Reads a COMMAND_LONG (76) or COMMAND_INT (75) without the typed decoder, so that
    /// commands the dialect's `MavCmd` does not know can still be acknowledged.
    pub fn raw_command(&self) -> Option<RawCommand> {
        let id = self.message_id();
        if id != id::COMMAND_LONG && id != id::COMMAND_INT {
            return None;
        }
        // Zero-fill the truncated v2 payload; both layouts put command at 28..30 and the
        // targets at 30/31 (the f32/i32 fields come first).
        let mut p = [0u8; 35];
        let n = self.payload().len().min(p.len());
        p[..n].copy_from_slice(&self.payload()[..n]);
        let f = |i: usize| f32::from_le_bytes([p[i], p[i + 1], p[i + 2], p[i + 3]]);
        let i = |i: usize| i32::from_le_bytes([p[i], p[i + 1], p[i + 2], p[i + 3]]);
        let kind = if id == id::COMMAND_LONG {
            RawCommandKind::Long {
                params: [f(0), f(4), f(8), f(12), f(16), f(20), f(24)],
                confirmation: p[32],
            }
        } else {
            RawCommandKind::Int {
                params: [f(0), f(4), f(8), f(12)],
                x: i(16),
                y: i(20),
                z: f(24),
                frame: p[32],
                current: p[33],
                autocontinue: p[34],
            }
        };
        Some(RawCommand {
            command: u16::from_le_bytes([p[28], p[29]]),
            target_system: p[30],
            target_component: p[31],
            kind,
        })
    }
}

fn crc_extra_matches(message_id: u32, extra: u8) -> bool {
    crc_extra(message_id) == Some(extra)
}
