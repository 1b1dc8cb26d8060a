//! Streaming MAVLink parser: push bytes in, pull [`Frame`]s out.
//!
//! Used for every transport: byte streams (TCP, serial, in-memory pipes) and UDP datagrams
//! (one decoder per peer, so a frame split across datagrams by a serial-to-UDP bridge still
//! parses, as in pymavlink). Partial frames are kept across pushes.
//!
//! Rules, in order, for a candidate starting at a magic byte (0xFE or 0xFD):
//! 1. Wait until the whole candidate (header, payload, CRC, signature if flagged) is buffered.
//! 2. **Known message id** (the dialect has its CRC_EXTRA): the CRC must match, otherwise the
//!    candidate is counted in `bad_crc` and the parser resyncs from the *next byte* (so a frame
//!    embedded in a false candidate is not lost). A CRC-valid frame with incompat flags other
//!    than 0x01 (signed) is dropped whole and counted in `bad_incompat`.
//! 3. **Unknown message id** (no CRC_EXTRA, so the CRC cannot be checked): the frame is yielded
//!    as *unverified* (for forwarding as a broadcast) only if its framing is plausible:
//!    - v2 incompat flags are 0x00 or 0x01, and
//!    - the byte right after it is a magic byte, or it ends exactly at the end of the buffered
//!      data (a read or datagram boundary), and
//!    - no CRC-valid frame of a known id starts inside it (if one might, but is not complete
//!      yet, the decision waits for more bytes).
//!
//!    Otherwise the candidate is skipped like garbage (one byte, then resync).
//!
//! Every byte discarded outside a yielded or deliberately dropped frame counts as garbage.

use bytes::{Buf, Bytes, BytesMut};

use crate::frame::{
    CRC_LEN, Frame, HEADER_LEN_V1, HEADER_LEN_V2, INCOMPAT_SIGNED, MAGIC_V1, MAGIC_V2, crc_extra,
    frame_crc, frame_len_from_prefix,
};

/// Counters of what the decoder saw. Plain numbers: links add them into their atomic stats.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct DecodeStats {
    /// Frames yielded (verified and unverified).
    pub frames: u64,
    /// Candidates of known message ids whose CRC did not match.
    pub bad_crc: u64,
    /// Bytes skipped while looking for a frame.
    pub garbage_bytes: u64,
    /// Frames yielded with a message id the dialect does not know (unverified).
    pub unknown_id: u64,
    /// CRC-valid frames dropped for unknown incompat flags.
    pub bad_incompat: u64,
}

impl DecodeStats {
    /// Adds another set of counters to this one.
    pub fn add(&mut self, other: &DecodeStats) {
        self.frames += other.frames;
        self.bad_crc += other.bad_crc;
        self.garbage_bytes += other.garbage_bytes;
        self.unknown_id += other.unknown_id;
        self.bad_incompat += other.bad_incompat;
    }
}

fn is_magic(b: u8) -> bool {
    b == MAGIC_V1 || b == MAGIC_V2
}

/// Header length for a magic byte.
fn header_len(magic: u8) -> usize {
    if magic == MAGIC_V2 {
        HEADER_LEN_V2
    } else {
        HEADER_LEN_V1
    }
}

/// Message id from a complete header.
fn header_message_id(h: &[u8]) -> u32 {
    if h[0] == MAGIC_V2 {
        u32::from_le_bytes([h[7], h[8], h[9], 0])
    } else {
        u32::from(h[5])
    }
}

/// Whether a complete candidate's CRC matches the given CRC_EXTRA.
fn crc_ok(candidate: &[u8], extra: u8) -> bool {
    let end = header_len(candidate[0]) + usize::from(candidate[1]);
    let stored = u16::from_le_bytes([candidate[end], candidate[end + 1]]);
    frame_crc(&candidate[1..end], extra) == stored
}

/// What to do with the candidate at the start of the buffer.
enum Verdict {
    /// Need more bytes before deciding.
    Wait,
    /// Yield `len` bytes as a frame.
    Yield { len: usize, verified: bool },
    /// Drop `len` bytes: a real frame we must not deliver.
    DropFrame { len: usize },
    /// Not a frame: skip the magic byte and resync.
    Skip { bad_crc: bool },
}

/// Bytes of frame storage taken at a time for frames read straight from datagrams (about 100
/// ATTITUDE frames). A block is freed when the last frame in it is; a frame kept for long (the
/// tracker's last frame of a message) keeps its block, so blocks stay small.
const ARENA_BYTES: usize = 4096;

/// Streaming MAVLink v1/v2 frame parser. See the module documentation for the rules.
#[derive(Debug, Default)]
pub struct FrameDecoder {
    buf: BytesMut,
    /// Where [`FrameDecoder::push_final_with`] copies the frames it reads straight from a
    /// datagram: one allocation of [`ARENA_BYTES`] holds the next frames, each a [`Bytes`] view
    /// sharing its reference count, instead of an allocation per frame.
    arena: BytesMut,
    stats: DecodeStats,
    /// Set while [`FrameDecoder::finish`] drains: no more bytes will come.
    eof: bool,
}

impl FrameDecoder {
    /// An empty decoder.
    pub fn new() -> Self {
        Self::default()
    }

    /// Appends received bytes.
    pub fn push(&mut self, data: &[u8]) {
        self.buf.extend_from_slice(data);
    }

    /// The internal buffer, to read into directly (e.g. `AsyncReadExt::read_buf`). Only
    /// append to it.
    pub fn buffer_mut(&mut self) -> &mut BytesMut {
        &mut self.buf
    }

    /// Bytes buffered but not yet yielded or skipped.
    pub fn buffered_len(&self) -> usize {
        self.buf.len()
    }

    /// Counters since creation (or since the last [`FrameDecoder::take_stats`]).
    pub fn stats(&self) -> &DecodeStats {
        &self.stats
    }

    /// Returns the counters and resets them to zero.
    pub fn take_stats(&mut self) -> DecodeStats {
        std::mem::take(&mut self.stats)
    }

    /// Drains every complete frame currently buffered.
    pub fn frames(&mut self) -> impl Iterator<Item = Frame> + '_ {
        std::iter::from_fn(move || self.next_frame())
    }

    /// Declares the end of the input (stream EOF) and returns the frames still buffered.
    /// Candidates that can no longer complete are skipped, so a real frame hidden behind a
    /// false, long candidate is not lost. The decoder is empty and reusable afterwards.
    pub fn finish(&mut self) -> Vec<Frame> {
        let mut frames = Vec::new();
        self.finish_with(|f| frames.push(f));
        frames
    }

    /// Decodes one whole datagram (or any input known to end at its last byte): the bytes
    /// buffered so far, then `data`, as if followed by [`FrameDecoder::finish_with`]. With
    /// nothing buffered (always, for a decoder that only ever sees whole datagrams) the frames
    /// are read straight from `data` and each copied into the decoder's arena, instead of
    /// going through the stream buffer.
    pub fn push_final_with(&mut self, data: &[u8], mut each: impl FnMut(Frame)) {
        if !self.buf.is_empty() {
            self.push(data);
            self.finish_with(each);
            return;
        }
        let mut rest = data;
        loop {
            let Some(start) = rest.iter().position(|&b| is_magic(b)) else {
                self.stats.garbage_bytes += rest.len() as u64;
                return;
            };
            self.stats.garbage_bytes += start as u64;
            rest = &rest[start..];
            let advance = match judge(rest, true) {
                Verdict::Yield { len, verified } => {
                    self.stats.frames += 1;
                    if !verified {
                        self.stats.unknown_id += 1;
                    }
                    each(Frame::from_checked(self.copy_out(&rest[..len]), verified));
                    len
                }
                Verdict::DropFrame { len } => {
                    self.stats.bad_incompat += 1;
                    len
                }
                Verdict::Skip { bad_crc } => {
                    self.stats.bad_crc += u64::from(bad_crc);
                    self.stats.garbage_bytes += 1;
                    1
                }
                Verdict::Wait => {
                    self.stats.garbage_bytes += 1;
                    1
                }
            };
            rest = &rest[advance..];
        }
    }

    /// [`FrameDecoder::finish`] handing each frame to `each` instead of collecting them.
    pub fn finish_with(&mut self, mut each: impl FnMut(Frame)) {
        self.eof = true;
        while let Some(frame) = self.next_frame() {
            each(frame);
        }
        self.eof = false;
    }

    /// `frame`'s bytes in the arena.
    fn copy_out(&mut self, frame: &[u8]) -> Bytes {
        // The arena is empty between frames: everything written to it was split off.
        if self.arena.capacity() < frame.len() {
            self.arena = BytesMut::with_capacity(ARENA_BYTES.max(frame.len()));
        }
        self.arena.extend_from_slice(frame);
        self.arena.split().freeze()
    }

    /// The next complete frame, or `None` if more bytes are needed.
    pub fn next_frame(&mut self) -> Option<Frame> {
        loop {
            let Some(start) = self.buf.iter().position(|&b| is_magic(b)) else {
                self.stats.garbage_bytes += self.buf.len() as u64;
                self.buf.clear();
                return None;
            };
            self.stats.garbage_bytes += start as u64;
            self.buf.advance(start);
            match judge(&self.buf, self.eof) {
                Verdict::Wait if self.eof => {
                    self.stats.garbage_bytes += 1;
                    self.buf.advance(1);
                }
                Verdict::Wait => return None,
                Verdict::Yield { len, verified } => {
                    self.stats.frames += 1;
                    if !verified {
                        self.stats.unknown_id += 1;
                    }
                    let bytes = self.buf.split_to(len).freeze();
                    return Some(Frame::from_checked(bytes, verified));
                }
                Verdict::DropFrame { len } => {
                    self.stats.bad_incompat += 1;
                    self.buf.advance(len);
                }
                Verdict::Skip { bad_crc } => {
                    self.stats.bad_crc += u64::from(bad_crc);
                    self.stats.garbage_bytes += 1;
                    self.buf.advance(1);
                }
            }
        }
    }
}

/// Judges the candidate at `buf[0]` (a magic byte); `eof`: no more bytes will follow `buf`.
fn judge(buf: &[u8], eof: bool) -> Verdict {
    let Some(total) = frame_len_from_prefix(buf) else {
        return Verdict::Wait;
    };
    if buf.len() < total {
        return Verdict::Wait;
    }
    let candidate = &buf[..total];
    let incompat_ok = candidate[0] == MAGIC_V1 || candidate[2] & !INCOMPAT_SIGNED == 0;
    let id = header_message_id(candidate);
    if let Some(extra) = crc_extra(id) {
        return match (crc_ok(candidate, extra), incompat_ok) {
            (false, _) => Verdict::Skip { bad_crc: true },
            (true, false) => Verdict::DropFrame { len: total },
            (true, true) => Verdict::Yield {
                len: total,
                verified: true,
            },
        };
    }
    // Unknown id: only framing can vouch for it.
    if !incompat_ok {
        return Verdict::Skip { bad_crc: false };
    }
    let boundary_ok = buf.len() == total || is_magic(buf[total]);
    if !boundary_ok {
        return Verdict::Skip { bad_crc: false };
    }
    match known_frame_inside(buf, total) {
        Inside::Found => Verdict::Skip { bad_crc: false },
        // At EOF an incomplete inner candidate can never become a frame.
        Inside::Maybe if !eof => Verdict::Wait,
        Inside::Maybe | Inside::None => Verdict::Yield {
            len: total,
            verified: false,
        },
    }
}

enum Inside {
    Found,
    Maybe,
    None,
}

/// Looks for a CRC-valid frame of a known id starting inside `buf[1..span]`, so that an
/// unverified candidate never swallows a real frame.
fn known_frame_inside(buf: &[u8], span: usize) -> Inside {
    let mut result = Inside::None;
    for j in 1..span {
        if !is_magic(buf[j]) {
            continue;
        }
        let sub = &buf[j..];
        if sub.len() < header_len(sub[0]) {
            result = Inside::Maybe;
            continue;
        }
        let Some(extra) = crc_extra(header_message_id(sub)) else {
            continue;
        };
        // Header complete, so the length is known.
        let len = frame_len_from_prefix(sub).unwrap_or(usize::MAX);
        if sub.len() < len {
            // The signature is not needed for the CRC; check it if the CRC bytes are here.
            let crc_end = header_len(sub[0]) + usize::from(sub[1]) + CRC_LEN;
            if sub.len() >= crc_end && !crc_ok(sub, extra) {
                continue;
            }
            result = Inside::Maybe;
        } else if crc_ok(sub, extra) {
            return Inside::Found;
        }
    }
    result
}

#[cfg(test)]
mod tests {
    use super::*;

    fn hb(seq: u8) -> Frame {
        Frame::encode_v2(
            crate::SystemId(1),
            crate::ComponentId(1),
            seq,
            &crate::frame::gcs_heartbeat(),
        )
    }

    fn unknown_frame(seq: u8, payload: &[u8]) -> Frame {
        let id = 0x00_AB_CD;
        assert!(crc_extra(id).is_none());
        Frame::encode_raw_v2(
            crate::SystemId(1),
            crate::ComponentId(1),
            seq,
            id,
            payload,
            0x55,
        )
        .unwrap()
    }

    #[test]
    fn datagram_frames_stay_whole_while_the_decoder_moves_on_through_its_arena() {
        // Frames of 21 to 213 bytes over many datagrams: many arena blocks, frames kept
        // from the first blocks to the last.
        let mut d = FrameDecoder::new();
        let (mut sent, mut got) = (Vec::new(), Vec::new());
        for i in 0..2000u32 {
            let seq = (i % 256) as u8;
            let payload: Vec<u8> = (0..(i % 200) as u8).map(|b| b ^ seq).collect();
            let frames = [hb(seq), unknown_frame(seq, &payload)];
            let dgram: Vec<u8> = frames.iter().flat_map(|f| f.as_bytes().to_vec()).collect();
            d.push_final_with(&dgram, |f| got.push(f));
            sent.extend(frames);
        }
        assert_eq!(got.len(), sent.len());
        for (k, (a, b)) in sent.iter().zip(&got).enumerate() {
            assert_eq!(a.as_bytes(), b.as_bytes(), "frame {k}");
        }
        // Dropping most of them frees their blocks; the ones kept stay whole.
        let kept: Vec<Frame> = got.into_iter().step_by(997).collect();
        for (k, f) in kept.iter().enumerate() {
            assert_eq!(f.as_bytes(), sent[k * 997].as_bytes());
        }
    }

    fn decode_all(bytes: &[u8]) -> (Vec<Frame>, DecodeStats) {
        let mut d = FrameDecoder::new();
        d.push(bytes);
        let frames: Vec<_> = d.frames().collect();
        (frames, *d.stats())
    }

    #[test]
    fn garbage_and_bad_crc_are_counted_and_skipped() {
        let a = hb(1);
        let b = hb(2);
        let mut bad = hb(3).as_bytes().to_vec();
        bad[12] ^= 0xFF;
        let mut s = vec![1, 2, 3];
        s.extend_from_slice(a.as_bytes());
        s.extend_from_slice(&bad);
        s.extend_from_slice(&[0xFE, 0x01]); // truncated v1 candidate followed by a real frame
        s.extend_from_slice(b.as_bytes());
        let (frames, st) = decode_all(&s);
        assert_eq!(frames, vec![a, b]);
        assert_eq!(st.frames, 2);
        assert_eq!(
            st.bad_crc, 2,
            "the bad heartbeat and the truncated v1 candidate"
        );
        assert!(st.garbage_bytes >= 3 + bad.len() as u64);
    }

    #[test]
    fn frame_embedded_in_false_candidate_is_found() {
        let a = hb(7);
        // A v2 magic with a large length swallows the real frame; resync must find it.
        let mut s = vec![0xFD, 200, 0, 0, 0, 1, 1, 0, 0, 0];
        s.extend_from_slice(a.as_bytes());
        s.extend(std::iter::repeat_n(0u8, 250));
        let (frames, st) = decode_all(&s);
        assert_eq!(frames, vec![a]);
        assert_eq!(st.bad_crc, 1);
    }

    #[test]
    fn unknown_incompat_dropped_whole() {
        let mut b = hb(1).as_bytes().to_vec();
        b[2] = 0x04;
        // Fix the CRC so that only the flag is wrong.
        let end = b.len() - 2;
        let crc = frame_crc(&b[1..end], 50);
        b[end..].copy_from_slice(&crc.to_le_bytes());
        b.extend_from_slice(hb(2).as_bytes());
        let (frames, st) = decode_all(&b);
        assert_eq!(frames, vec![hb(2)]);
        assert_eq!(st.bad_incompat, 1);
        assert_eq!(st.garbage_bytes, 0);
    }

    #[test]
    fn unknown_ids_pass_when_plausible() {
        let u = unknown_frame(4, &[1, 2, 3, 4]);
        // Followed by a magic byte.
        let mut s = u.as_bytes().to_vec();
        s.extend_from_slice(hb(5).as_bytes());
        let (frames, st) = decode_all(&s);
        assert_eq!(frames.len(), 2);
        assert!(!frames[0].is_verified());
        assert_eq!(frames[0].as_bytes(), u.as_bytes());
        assert_eq!(frames[0].message_id(), 0xABCD);
        assert_eq!(st.unknown_id, 1);
        // Ending the buffer.
        let (frames, _) = decode_all(u.as_bytes());
        assert_eq!(frames.len(), 1);
        // Followed by garbage: not plausible, skipped.
        let mut s = u.as_bytes().to_vec();
        s.push(0x00);
        let (frames, st) = decode_all(&s);
        assert!(frames.is_empty());
        assert_eq!(st.garbage_bytes, s.len() as u64);
    }

    #[test]
    fn unknown_candidate_never_swallows_a_known_frame() {
        let a = hb(9);
        // Fake unknown-id v2 header whose length covers the real frame exactly, and the
        // buffer ends with it: plausible by boundary, but the real frame inside wins.
        let len = a.len() as u8 - 2; // header + len + CRC == header + a: ends the buffer
        let mut s = vec![0xFD, len, 0, 0, 0, 1, 1, 0xCD, 0xAB, 0];
        s.extend_from_slice(a.as_bytes());
        let (frames, _) = decode_all(&s);
        assert_eq!(frames, vec![a]);
    }

    #[test]
    fn unknown_candidate_waits_for_possible_known_frame() {
        let a = hb(9);
        let mut d = FrameDecoder::new();
        // Unknown-id frame whose payload contains the first half of a heartbeat header.
        let u = unknown_frame(1, &a.as_bytes()[..12]);
        d.push(u.as_bytes());
        // The inner candidate (a heartbeat with 9-byte payload) is not complete: wait.
        assert!(d.next_frame().is_none());
        // More data completes the inner candidate as a false one; the unknown frame is then
        // followed by a magic byte and passes.
        d.push(hb(10).as_bytes());
        let frames: Vec<_> = d.frames().collect();
        assert_eq!(frames.len(), 2);
        assert_eq!(frames[0].as_bytes(), u.as_bytes());
        assert_eq!(frames[1], hb(10));
    }

    #[test]
    fn finish_releases_frame_behind_incomplete_candidate() {
        let a = hb(3);
        let mut s = vec![0xFD, 250, 0, 0, 0, 1, 1, 0, 0, 0];
        s.extend_from_slice(a.as_bytes());
        let mut d = FrameDecoder::new();
        d.push(&s);
        assert!(d.next_frame().is_none(), "waits for the long candidate");
        assert_eq!(d.finish(), vec![a]);
        assert_eq!(d.buffered_len(), 0);
        assert_eq!(d.stats().garbage_bytes, 10);
    }

    #[test]
    fn partial_frames_survive_pushes_byte_by_byte() {
        let mut s = hb(1).as_bytes().to_vec();
        s.extend_from_slice(hb(2).as_bytes());
        let mut d = FrameDecoder::new();
        let mut out = Vec::new();
        for b in s {
            d.push(&[b]);
            out.extend(d.frames());
        }
        assert_eq!(out, vec![hb(1), hb(2)]);
        assert_eq!(d.buffered_len(), 0);
    }
}
