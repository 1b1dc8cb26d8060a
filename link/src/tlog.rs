//! The telemetry log record (`.tlog`), as pymavlink, MAVProxy and mavlogdump read it: an 8-byte
//! big-endian timestamp (µs since the Unix epoch, the low 2 bits the direction) followed by one
//! complete MAVLink frame, no file header, no padding. The daemon's log and the twin's log both
//! write records with [`encode_record`].

use crate::frame::{Frame, MAX_FRAME_LEN};
use crate::protocol::id;

/// Bytes of a record's timestamp.
pub const STAMP_LEN: usize = 8;
/// Longest record: a timestamp and the longest frame.
pub const MAX_RECORD_LEN: usize = STAMP_LEN + MAX_FRAME_LEN;

/// Which way a frame travelled, as the low 2 bits of the timestamp (MAVProxy's convention).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Direction {
    /// Sent by the vehicle: received from the vehicle link.
    FromVehicle,
    /// Sent towards the vehicle: from a client, or the daemon's own traffic.
    ToVehicle,
}

impl Direction {
    /// The direction's bits in a record's timestamp.
    #[must_use]
    #[inline]
    pub fn link_bits(self) -> u64 {
        match self {
            Self::FromVehicle => 0,
            Self::ToVehicle => 3,
        }
    }
}

/// A record's 8-byte timestamp: `t_us` with the direction in the low 2 bits.
#[must_use]
#[inline]
pub fn stamp(t_us: u64, direction: Direction) -> u64 {
    (t_us & !3) | direction.link_bits()
}

/// Appends a record as it goes into the file (timestamp, then the frame's bytes). SETUP_SIGNING
/// carries a key and is never logged: false, and nothing appended, for it.
#[inline]
pub fn encode_record(out: &mut Vec<u8>, t_us: u64, direction: Direction, frame: &Frame) -> bool {
    if frame.message_id() == id::SETUP_SIGNING {
        return false;
    }
    encode_record_bytes(out, t_us, direction, frame.as_bytes());
    true
}

/// Appends a record of a frame's raw bytes, for a writer that has already kept SETUP_SIGNING
/// out (the twin's, whose signing layer takes it before anything is logged).
#[inline]
pub fn encode_record_bytes(out: &mut Vec<u8>, t_us: u64, direction: Direction, frame: &[u8]) {
    out.extend_from_slice(&stamp(t_us, direction).to_be_bytes());
    out.extend_from_slice(frame);
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::{ComponentId, SystemId};

    #[test]
    fn a_record_is_the_stamp_with_its_direction_then_the_frame() {
        let f = Frame::encode_v2(SystemId(1), ComponentId(1), 0, &crate::gcs_heartbeat());
        let mut out = Vec::new();
        assert!(encode_record(
            &mut out,
            0x1234_5678,
            Direction::ToVehicle,
            &f
        ));
        assert_eq!(out[..STAMP_LEN], (0x1234_567B_u64).to_be_bytes());
        assert_eq!(&out[STAMP_LEN..], f.as_bytes());
    }
}
