//! The load's frames: ATTITUDE carrying a sequence number, a phase and the send time.

use super::*;

/// Builds the frame in place: payload = seq u32, send time u64 ns, phase u32, non-zero filler
/// (so MAVLink 2 trailing-zero truncation never shortens it).
pub(crate) fn fill_frame(buf: &mut [u8; FRAME_LEN], seq: u32, phase: u32, t_ns: u64) {
    let crc_extra = vtol_link::frame::crc_extra(ATTITUDE_ID).expect("ATTITUDE is in the dialect");
    let id = ATTITUDE_ID.to_le_bytes();
    buf[..10].copy_from_slice(&[
        0xFD,
        PAYLOAD_LEN as u8,
        0,
        0,
        seq as u8,
        1,
        1,
        id[0],
        id[1],
        id[2],
    ]);
    let p = &mut buf[10..10 + PAYLOAD_LEN];
    p[0..4].copy_from_slice(&seq.to_le_bytes());
    p[4..12].copy_from_slice(&t_ns.to_le_bytes());
    p[12..16].copy_from_slice(&phase.to_le_bytes());
    p[16..].fill(0xA5);
    let crc = vtol_link::frame::frame_crc(&buf[1..10 + PAYLOAD_LEN], crc_extra);
    buf[10 + PAYLOAD_LEN..].copy_from_slice(&crc.to_le_bytes());
}

/// (phase, send time) of a generator frame, by header; anything else (the daemon's own
/// heartbeat) is `None`.
pub(crate) fn parse_frame(d: &[u8]) -> Option<(u32, u64)> {
    if d.len() < 10 || d[0] != 0xFD || d[5] != 1 || d[7..10] != ATTITUDE_ID.to_le_bytes()[..3] {
        return None;
    }
    let len = usize::from(d[1]);
    let mut p = [0u8; PAYLOAD_LEN];
    let avail = len.min(PAYLOAD_LEN).min(d.len().saturating_sub(10));
    p[..avail].copy_from_slice(&d[10..10 + avail]);
    let t = u64::from_le_bytes(p[4..12].try_into().ok()?);
    let phase = u32::from_le_bytes(p[12..16].try_into().ok()?);
    Some((phase, t))
}
