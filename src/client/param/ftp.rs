//! The whole table as one file, over MAVLink FTP: ArduPilot serves its parameters as
//! `@PARAM/param.pck` (AP_Filesystem_Param.cpp), which MAVProxy and QGroundControl read in a
//! fraction of the parameter protocol's time. Used only when the vehicle's AUTOPILOT_VERSION
//! offers FTP; any failure (a NAK on open, a file that does not decode, silence) hands over to
//! the parameter protocol ([`super::PullMachine`]).
//!
//! The exchange: OpenFileRO, then BurstReadFile from offset 0: the vehicle sends the file in
//! 239-byte chunks until its end (a short chunk, or a NAK EndOfFile). Chunks lost on the way
//! leave gaps, asked for again by a burst from the first one; the file is complete when its
//! bytes from the start decode to as many parameters as its header announces. Then
//! TerminateSession frees the vehicle's one FTP session.
//!
//! The packed format: a header `u16 magic (0x671b, or 0x671c with defaults) | u16 count |
//! u16 total`, then per parameter `u8 type (low 4 bits: 1 int8, 2 int16, 3 int32, 4 float;
//! bit 4: a default follows) | u8 (shared name bytes with the previous name, 0-15) | (new name
//! bytes - 1) << 4 | new name bytes | value [| default]`, little-endian; zero bytes before an
//! entry are padding (they keep a value from straddling two chunks).

use std::collections::BTreeMap;
use std::time::{Duration, Instant};

use vtol_link::dialect::{self as apm, MavMessage, MavParamType};
use vtol_link::{ComponentId, SystemId};

use crate::client::machine::{Inbound, Machine, Retry, Step};
use crate::params::{Param, ParamSet};

/// The file.
pub const PARAM_FILE: &str = "@PARAM/param.pck";
/// Data bytes in one FTP payload.
pub const CHUNK: usize = 239;
/// Sends of one request (open, or a burst from a gap) before FTP is given up for the
/// parameter protocol.
pub const FTP_TRIES: u8 = 4;
/// A read is given up after this long without a new chunk.
pub const FTP_STALL: Duration = Duration::from_secs(2);

/// A pause in a burst this long (or a round-trip timeout, if longer) ends it: the vehicle
/// sends its chunks back to back.
const BURST_PAUSE: Duration = Duration::from_millis(50);

/// Sends of TerminateSession before the table is returned without its ACK.
const CLOSE_TRIES: u8 = 2;

const OP_TERMINATE: u8 = 1;
const OP_OPEN_RO: u8 = 4;
const OP_READ: u8 = 5;
const OP_BURST: u8 = 15;
const OP_ACK: u8 = 128;
const OP_NAK: u8 = 129;
const ERR_EOF: u8 = 6;

const MAGIC: u16 = 0x671b;
const MAGIC_DEFAULTS: u16 = 0x671c;

/// Why a packed parameter file does not decode.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum PckError {
    /// Shorter than its header.
    #[error("shorter than its header")]
    Short,
    /// Not a packed parameter file.
    #[error("bad magic 0x{0:04x}")]
    Magic(u16),
    /// An entry with an unknown type.
    #[error("unknown type {0} at byte {1}")]
    Type(u8, usize),
    /// An entry cut off by the end of the data.
    #[error("entry cut off at byte {0}")]
    Truncated(usize),
    /// Fewer entries than the header announces.
    #[error("{got} of {want} parameters")]
    Incomplete {
        /// Entries decoded.
        got: usize,
        /// Entries announced.
        want: usize,
    },
}

/// Decodes `@PARAM/param.pck` into the table, values as the parameter protocol sends them
/// (float32, integers converted).
///
/// # Errors
/// [`PckError`] when the bytes are not a whole packed parameter file.
pub fn decode_pck(data: &[u8]) -> Result<ParamSet, PckError> {
    if data.len() < 6 {
        return Err(PckError::Short);
    }
    let u16_at = |i: usize| u16::from_le_bytes([data[i], data[i + 1]]);
    let magic = u16_at(0);
    if magic != MAGIC && magic != MAGIC_DEFAULTS {
        return Err(PckError::Magic(magic));
    }
    let want = usize::from(u16_at(2));
    let mut set = ParamSet::new();
    let mut last: Vec<u8> = Vec::new();
    let mut i = 6;
    let mut got = 0;
    while got < want {
        while data.get(i) == Some(&0) {
            i += 1;
        }
        let (Some(&ty), Some(&lens)) = (data.get(i), data.get(i + 1)) else {
            break;
        };
        let has_default = magic == MAGIC_DEFAULTS && ty & 0x10 != 0;
        let (size, mav) = match ty & 0x0f {
            1 => (1, MavParamType::MAV_PARAM_TYPE_INT8),
            2 => (2, MavParamType::MAV_PARAM_TYPE_INT16),
            3 => (4, MavParamType::MAV_PARAM_TYPE_INT32),
            4 => (4, MavParamType::MAV_PARAM_TYPE_REAL32),
            other => return Err(PckError::Type(other, i)),
        };
        let common = usize::from(lens & 0x0f);
        let new = usize::from(lens >> 4) + 1;
        let end = i + 2 + new + size * if has_default { 2 } else { 1 };
        if end > data.len() || common > last.len() {
            return Err(PckError::Truncated(i));
        }
        last.truncate(common);
        last.extend_from_slice(&data[i + 2..i + 2 + new]);
        let v = &data[i + 2 + new..i + 2 + new + size];
        let value = match ty & 0x0f {
            1 => f32::from(v[0] as i8),
            2 => f32::from(i16::from_le_bytes([v[0], v[1]])),
            // An int32 beyond 2^24 loses its low bits in a float32, as on the wire.
            3 => i32::from_le_bytes([v[0], v[1], v[2], v[3]]) as f32,
            _ => f32::from_le_bytes([v[0], v[1], v[2], v[3]]),
        };
        let name = String::from_utf8_lossy(&last).into_owned();
        set.insert(name, Param { value, ty: mav });
        got += 1;
        i = end;
    }
    if got < want {
        return Err(PckError::Incomplete { got, want });
    }
    Ok(set)
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Phase {
    Open,
    Read,
    /// The table is in; TerminateSession waits for its ACK (a few tries at most), so that the
    /// vehicle's one session is free for the next reader even when this process ends at once.
    Close,
}

/// The table over FTP: `Ok(table)`, or `Err(why)` when the parameter protocol should be used.
#[derive(Debug)]
pub struct FtpPullMachine {
    target: (SystemId, ComponentId),
    session: u8,
    seq: u16,
    phase: Phase,
    rto: Duration,
    retry: Retry,
    chunks: BTreeMap<u32, Vec<u8>>,
    /// The end of the file, once a short chunk or an end-of-file NAK has shown it.
    end: Option<u32>,
    last_rx: Instant,
    /// The table, read, while the session closes.
    table: Option<ParamSet>,
    done: Option<Result<ParamSet, String>>,
    /// Chunks received (duplicates included), for the benchmark's report.
    pub chunks_received: usize,
}

impl FtpPullMachine {
    /// Reads `@PARAM/param.pck` from `target` in FTP session `session`.
    #[must_use]
    pub fn new(target: (SystemId, ComponentId), session: u8, rto: Duration) -> Self {
        Self {
            target,
            session,
            seq: 0,
            phase: Phase::Open,
            rto,
            retry: Retry::new(rto, FTP_TRIES, Duration::ZERO),
            chunks: BTreeMap::new(),
            end: None,
            last_rx: Instant::now(),
            table: None,
            done: None,
            chunks_received: 0,
        }
    }

    fn request(&mut self, opcode: u8, offset: u32, data: &[u8]) -> MavMessage {
        self.seq = self.seq.wrapping_add(1);
        let mut payload = [0u8; 251];
        payload[..2].copy_from_slice(&self.seq.to_le_bytes());
        payload[2] = self.session;
        payload[3] = opcode;
        payload[4] = u8::try_from(data.len()).unwrap_or(u8::MAX);
        payload[8..12].copy_from_slice(&offset.to_le_bytes());
        payload[12..12 + data.len()].copy_from_slice(data);
        MavMessage::FILE_TRANSFER_PROTOCOL(apm::FILE_TRANSFER_PROTOCOL_DATA {
            target_network: 0,
            target_system: self.target.0.0,
            target_component: self.target.1.0,
            payload,
        })
    }

    fn open(&mut self, now: Instant) -> MavMessage {
        self.retry.send(now);
        let mut path = PARAM_FILE.as_bytes().to_vec();
        path.push(0);
        self.request(OP_OPEN_RO, 0, &path)
    }

    /// A burst from the first byte not received.
    fn burst(&mut self, now: Instant) -> MavMessage {
        self.retry.send(now);
        let from = self.contiguous();
        let mut m = self.request(OP_BURST, from, &[]);
        // The size of each chunk asked for: a whole payload (the vehicle pads its values
        // to chunks of this size).
        if let MavMessage::FILE_TRANSFER_PROTOCOL(f) = &mut m {
            f.payload[4] = CHUNK as u8;
        }
        m
    }

    /// Bytes received without a gap from the start.
    fn contiguous(&self) -> u32 {
        let mut at = 0u32;
        for (&ofs, data) in &self.chunks {
            if ofs > at {
                break;
            }
            at = at.max(ofs + u32::try_from(data.len()).unwrap_or(0));
        }
        at
    }

    fn assembled(&self) -> Vec<u8> {
        let mut out = Vec::new();
        for (&ofs, data) in &self.chunks {
            let ofs = ofs as usize;
            if ofs > out.len() {
                break;
            }
            let skip = out.len() - ofs;
            if skip < data.len() {
                out.extend_from_slice(&data[skip..]);
            }
        }
        out
    }

    /// TerminateSession, to be acknowledged.
    fn close(&mut self, now: Instant) -> Vec<MavMessage> {
        if self.phase != Phase::Close {
            self.phase = Phase::Close;
            self.retry = Retry::new(self.rto, CLOSE_TRIES, Duration::ZERO);
        }
        self.retry.send(now);
        vec![self.request(OP_TERMINATE, 0, &[])]
    }

    /// After a burst ends, or the stream of chunks stops: done, or a burst from the gap.
    fn settle(&mut self, now: Instant) -> Vec<MavMessage> {
        match decode_pck(&self.assembled()) {
            Ok(set) => {
                self.table = Some(set);
                self.close(now)
            }
            Err(PckError::Incomplete { .. } | PckError::Truncated(_) | PckError::Short)
                if self.end.is_none_or(|e| self.contiguous() < e) =>
            {
                self.retry = Retry::new(self.rto, FTP_TRIES, Duration::ZERO);
                vec![self.burst(now)]
            }
            Err(e) => {
                self.done = Some(Err(format!("{PARAM_FILE}: {e}")));
                vec![self.request(OP_TERMINATE, 0, &[])]
            }
        }
    }
}

impl Machine for FtpPullMachine {
    type Output = Result<ParamSet, String>;

    fn start(&mut self, now: Instant) -> Vec<MavMessage> {
        self.last_rx = now;
        vec![self.open(now)]
    }

    fn on_message(&mut self, now: Instant, m: &Inbound) -> Vec<MavMessage> {
        if self.done.is_some() || (m.sys, m.comp) != self.target {
            return Vec::new();
        }
        let MavMessage::FILE_TRANSFER_PROTOCOL(f) = &m.msg else {
            return Vec::new();
        };
        let p = &f.payload;
        let (session, opcode, size, req) = (p[2], p[3], usize::from(p[4]), p[5]);
        let burst_complete = p[6] != 0;
        let offset = u32::from_le_bytes([p[8], p[9], p[10], p[11]]);
        if session != self.session || !matches!(opcode, OP_ACK | OP_NAK) {
            return Vec::new();
        }
        match (self.phase, opcode, req) {
            (Phase::Close, _, OP_TERMINATE) => {
                self.done = self.table.take().map(Ok);
                Vec::new()
            }
            (Phase::Open, OP_ACK, OP_OPEN_RO) => {
                self.phase = Phase::Read;
                self.last_rx = now;
                self.retry = Retry::new(self.rto, FTP_TRIES, Duration::ZERO);
                vec![self.burst(now)]
            }
            (Phase::Open, OP_NAK, OP_OPEN_RO) => {
                self.done = Some(Err(format!(
                    "{PARAM_FILE}: open refused (FTP error {})",
                    p[12]
                )));
                Vec::new()
            }
            (Phase::Read, OP_ACK, OP_BURST | OP_READ) => {
                self.last_rx = now;
                self.chunks_received += 1;
                let data = p[12..12 + size.min(CHUNK)].to_vec();
                if size < CHUNK {
                    self.end = Some(offset + u32::try_from(size).unwrap_or(0));
                }
                self.chunks.entry(offset).or_insert(data);
                // The next chunk is due at once: the retry waits for a pause in the burst.
                self.retry.wait_until(now + self.rto.max(BURST_PAUSE));
                if burst_complete || self.end.is_some_and(|e| self.contiguous() >= e) {
                    self.settle(now)
                } else {
                    Vec::new()
                }
            }
            (Phase::Read, OP_NAK, OP_BURST | OP_READ) => {
                self.last_rx = now;
                if p[12] == ERR_EOF {
                    // The end is at most where the vehicle ran out.
                    let received = self
                        .chunks
                        .iter()
                        .next_back()
                        .map_or(0, |(o, d)| o + u32::try_from(d.len()).unwrap_or(0));
                    self.end = Some(self.end.unwrap_or(u32::MAX).min(received.max(offset)));
                    self.settle(now)
                } else {
                    self.done = Some(Err(format!(
                        "{PARAM_FILE}: read refused (FTP error {})",
                        p[12]
                    )));
                    Vec::new()
                }
            }
            _ => Vec::new(),
        }
    }

    fn on_time(&mut self, now: Instant) -> Vec<MavMessage> {
        if self.done.is_some() {
            return Vec::new();
        }
        if self.phase != Phase::Close && now.duration_since(self.last_rx) > FTP_STALL {
            self.done = Some(Err(format!("{PARAM_FILE}: no answer")));
            return Vec::new();
        }
        match (self.retry.step(now), self.phase) {
            (Step::Wait, _) => Vec::new(),
            (Step::GiveUp, Phase::Open) => {
                self.done = Some(Err(format!("{PARAM_FILE}: no answer to open")));
                Vec::new()
            }
            (Step::Send, Phase::Open) => vec![self.open(now)],
            (Step::GiveUp, Phase::Read) => {
                self.done = Some(Err(format!("{PARAM_FILE}: read stalled")));
                vec![self.request(OP_TERMINATE, 0, &[])]
            }
            // The burst paused: what came may already be all of it, or a burst from the gap.
            (Step::Send, Phase::Read) => self.settle(now),
            (Step::Send, Phase::Close) => self.close(now),
            (Step::GiveUp, Phase::Close) => {
                self.done = self.table.take().map(Ok);
                Vec::new()
            }
        }
    }

    fn deadline(&self) -> Instant {
        self.retry
            .deadline()
            .min(self.last_rx + FTP_STALL + Duration::from_millis(1))
    }

    fn result(&mut self) -> Option<Self::Output> {
        self.done.take()
    }
}

#[cfg(test)]
#[path = "ftp_tests.rs"]
mod tests;
