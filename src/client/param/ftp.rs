//! The whole table as one file, over MAVLink FTP: ArduPilot serves its parameters as
//! `@PARAM/param.pck` (AP_Filesystem_Param.cpp), which MAVProxy and QGroundControl read in a
//! fraction of the parameter protocol's time. Used only when the vehicle's AUTOPILOT_VERSION
//! offers FTP; any failure (a NAK on open, a file that does not decode, silence) hands over to
//! the parameter protocol ([`super::PullMachine`]).
//!
//! The exchange: OpenFileRO, then the file in 239-byte chunks until its end (a short chunk, or a
//! NAK EndOfFile), then TerminateSession, which frees the vehicle's one FTP session. The file is
//! complete when its bytes from the start decode to as many parameters as its header announces.
//! - On a fast link (the open answered within 30 ms) the chunks are asked for by ReadFile, four
//!   at once and then one every 3 ms: ArduPilot answers those as they come
//!   (one every 2–3 ms on SITL), where it paces a burst to a third of what it believes the port
//!   carries (one chunk every 5.8 ms on SITL's TCP port).
//! - On a slower link, one BurstReadFile from the start: the vehicle's pace suits the link. The
//!   chunks lost on the way are then asked for by ReadFile, one chunk (in all its copies) per
//!   burst interval.
//! - A request unanswered for a round trip and a quarter (and the time the requests queued
//!   before it take to leave) is sent again. Each goes in one, two or three copies as the loss
//!   seen so far (the gaps a burst left, then the reads' timeouts) makes a lost round likely,
//!   and a chunk asked for again in one copy more (four at most).
//! - The open goes in three copies and the TerminateSession in two, each copy and retry of the
//!   open with one sequence number, so that ArduPilot answers a repeat from its last answer.
//!   The open and the burst are retried after half as long again as the link's round trip.
//! - An open refused with Fail means this session already has a file open (an earlier reader
//!   with this session number did not close it): TerminateSession, then the open again.
//!
//! The packed format: a header `u16 magic (0x671b, or 0x671c with defaults) | u16 count |
//! u16 total`, then per parameter `u8 type (low 4 bits: 1 int8, 2 int16, 3 int32, 4 float;
//! bit 4: a default follows) | u8 (shared name bytes with the previous name, 0-15) | (new name
//! bytes - 1) << 4 | new name bytes | value [| default]`, little-endian; zero bytes before an
//! entry are padding (they keep a value from straddling two chunks).

use std::collections::{BTreeMap, BTreeSet};
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
const ERR_FAIL: u8 = 1;
const ERR_EOF: u8 = 6;
/// Resets of a session the vehicle says already has a file open, before FTP is given up.
const RESETS: u8 = 2;

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
    /// The open was refused because this session already has a file open (the answer to an
    /// earlier open was lost, or an earlier reader with this session number never closed it):
    /// TerminateSession, then the open again.
    Reset,
    /// One BurstReadFile: the vehicle sends chunk after chunk at its own pace.
    Burst,
    /// ReadFile requests, several in flight: the whole file on a fast link, the gaps a burst
    /// left on a slow one.
    Window,
    /// The table is in; TerminateSession waits for its ACK (a few tries at most), so that the
    /// vehicle's one session is free for the next reader even when this process ends at once.
    Close,
}

/// An open round trip at most this long makes the link a fast one: the file is read with
/// requests in flight from the start. ArduPilot paces a burst to a third of what it believes
/// the port carries (one chunk every 5.8 ms on SITL's TCP port); several ReadFile requests in
/// flight are answered as fast as they come, one every 2–3 ms.
const FAST_LINK: Duration = Duration::from_millis(30);
/// Requests sent back to back. ArduPilot queues five FTP requests and drops what comes while
/// the queue is full, so at most four arrive together.
const READ_BURST: u32 = 4;
/// Then one request per this long at most (or per chunk interval of the burst, if longer: the
/// pace the vehicle chose for the link).
const READ_PACE: Duration = Duration::from_millis(3);
/// Requests in flight at most: what the vehicle takes is bounded by the pace, not by this
/// (on loopback four or five are in flight); a slow link with gaps to fill holds more, in
/// copies.
const READ_WINDOW: usize = 96;
/// Copies of a read at most (a chunk asked for again goes in one more than the loss calls for):
/// four, back to back, are what the vehicle's queue of five takes beside the next chunk's.
const MAX_READ_COPIES: usize = 4;
/// A request unanswered this long at least is sent again.
const READ_TIMEOUT_MIN: Duration = Duration::from_millis(40);

/// A ReadFile request in flight.
#[derive(Debug, Clone, Copy)]
struct Read {
    offset: u32,
    sent: Instant,
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
    /// When the first open was sent: the link's round trip is measured from it, so an answer to
    /// an earlier send that comes after a retry never makes a slow link look fast (it may
    /// make a fast one look slow, which only means a burst).
    open_sent: Option<Instant>,
    /// When the last open was sent.
    open_last: Option<Instant>,
    /// The open as sent: its copies and retries repeat it, sequence number and all.
    open_request: Option<MavMessage>,
    /// The link's smoothed round trip, as the client measured it before the read.
    link_rtt: Option<Duration>,
    /// Chunks whose reads timed out at least once.
    asked_again: BTreeSet<u32>,
    /// ReadFile requests in flight, by their sequence number (the vehicle answers with it
    /// plus one, and leaves a NAK's offset stale).
    reads: BTreeMap<u16, Read>,
    /// Requests that may leave now (a token bucket of `READ_BURST`), and when the next accrues.
    tokens: u32,
    next_token: Instant,
    pace: Duration,
    read_timeout: Duration,
    /// The open's round trip.
    rtt: Duration,
    resets: u8,
    /// The chance that a request or its answer is lost: from the gaps a burst left, then
    /// from the reads' answers and timeouts. Each request goes in as many copies as make a
    /// round without its chunk unlikely.
    loss: f64,
    reads_answered: usize,
    /// The burst's first chunk and chunks, for its pace.
    burst_first: Option<Instant>,
    burst_chunks: u32,
    /// The table, read, while the session closes.
    table: Option<ParamSet>,
    done: Option<Result<ParamSet, String>>,
    /// Chunks received (duplicates included), for the benchmark's report.
    pub chunks_received: usize,
    /// Requests sent (opens, bursts, reads, terminates), and reads sent again after a timeout.
    sent: usize,
    reads_timed_out: usize,
    started: Instant,
    /// When the open was answered and the burst ended, for the summary.
    opened_at: Option<Instant>,
    burst_end: Option<Instant>,
    /// How the burst's end was seen: its last chunk, the end-of-file NAK, or a pause.
    burst_end_by: &'static str,
}

impl FtpPullMachine {
    /// Reads `@PARAM/param.pck` from `target` in FTP session `session`.
    #[must_use]
    pub fn new(target: (SystemId, ComponentId), session: u8, rto: Duration) -> Self {
        let now = Instant::now();
        Self {
            target,
            session,
            seq: 0,
            phase: Phase::Open,
            rto,
            retry: Retry::new(rto, FTP_TRIES, Duration::ZERO),
            chunks: BTreeMap::new(),
            end: None,
            last_rx: now,
            open_sent: None,
            open_last: None,
            open_request: None,
            asked_again: BTreeSet::new(),
            link_rtt: None,
            reads: BTreeMap::new(),
            tokens: READ_BURST,
            next_token: now,
            pace: READ_PACE,
            read_timeout: READ_TIMEOUT_MIN,
            rtt: Duration::ZERO,
            resets: 0,
            loss: 0.0,
            reads_answered: 0,
            burst_first: None,
            burst_chunks: 0,
            table: None,
            done: None,
            chunks_received: 0,
            sent: 0,
            reads_timed_out: 0,
            started: now,
            opened_at: None,
            burst_end: None,
            burst_end_by: "-",
        }
    }

    fn request(&mut self, opcode: u8, offset: u32, data: &[u8]) -> MavMessage {
        self.seq = self.seq.wrapping_add(1);
        self.sent += 1;
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

    /// A request for `CHUNK` bytes from `offset` (a burst's or a read's).
    fn chunk_request(&mut self, opcode: u8, offset: u32) -> MavMessage {
        let mut m = self.request(opcode, offset, &[]);
        // The size of each chunk asked for: a whole payload (the vehicle pads its values
        // to chunks of this size).
        if let MavMessage::FILE_TRANSFER_PROTOCOL(f) = &mut m {
            f.payload[4] = CHUNK as u8;
        }
        m
    }

    /// OpenFileRO, in three copies: on a lossy link a lost open costs a retry timeout (at 30 %
    /// loss each way two copies left one open in four unanswered, three leave one in eight). The
    /// copies and the retries carry one sequence number: ArduPilot answers a request that
    /// repeats the one it last answered with that answer again, so the copy or retry that
    /// comes after an open whose answer was lost is acknowledged, not refused because the
    /// file is open.
    fn open(&mut self, now: Instant) -> Vec<MavMessage> {
        self.retry.send(now);
        self.open_sent.get_or_insert(now);
        self.open_last = Some(now);
        let m = match &self.open_request {
            Some(m) => {
                self.sent += 1;
                m.clone()
            }
            None => {
                let mut path = PARAM_FILE.as_bytes().to_vec();
                path.push(0);
                let m = self.request(OP_OPEN_RO, 0, &path);
                self.open_request = Some(m.clone());
                m
            }
        };
        self.sent += 2;
        vec![m.clone(), m.clone(), m]
    }

    /// The round trip of the link as the client measured it before this read, if it did:
    /// the open's and the burst's retries wait from it, and the reads' timeouts start from it
    /// when the open's own round trip is in doubt.
    #[must_use]
    pub fn with_link_rtt(mut self, srtt: Option<Duration>) -> Self {
        self.link_rtt = srtt;
        self.retry = Retry::new(self.request_rto(), FTP_TRIES, Duration::ZERO);
        self
    }

    /// How long the open, the reset and the burst wait for their answer before they go again:
    /// half as long again as the link's measured round trip (at least 50 ms more), else the
    /// client's timeout. A timeout from one sample is three round trips, which at 30 % loss
    /// made one open in three cost 0.6 s on a 0.2 s link; going early costs little, since a
    /// repeated request is answered again from the vehicle's last answer.
    fn request_rto(&self) -> Duration {
        self.link_rtt
            .map_or(self.rto, |r| (r * 3 / 2).max(r + Duration::from_millis(50)))
    }

    /// A burst from the first byte.
    fn burst(&mut self, now: Instant) -> MavMessage {
        self.phase = Phase::Burst;
        self.retry = Retry::new(self.request_rto(), FTP_TRIES, Duration::ZERO);
        self.retry.send(now);
        self.chunk_request(OP_BURST, 0)
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
            self.reads.clear();
            // Once the open's round trip is known, a retry waits little longer than it.
            let wait = if self.rtt > Duration::ZERO {
                self.read_timeout
            } else {
                self.rto
            };
            self.retry = Retry::new(wait, CLOSE_TRIES, Duration::ZERO);
        }
        self.retry.send(now);
        // In two copies: a lost one costs a retry timeout.
        vec![
            self.request(OP_TERMINATE, 0, &[]),
            self.request(OP_TERMINATE, 0, &[]),
        ]
    }

    /// Whether every byte up to the end is in.
    fn complete(&self) -> bool {
        self.end.is_some_and(|e| self.contiguous() >= e)
    }

    /// Done, or the gaps asked for by ReadFile.
    fn settle(&mut self, now: Instant) -> Vec<MavMessage> {
        match decode_pck(&self.assembled()) {
            Ok(set) => {
                self.table = Some(set);
                self.close(now)
            }
            Err(PckError::Incomplete { .. } | PckError::Truncated(_) | PckError::Short)
                if !self.complete() =>
            {
                if self.phase == Phase::Burst {
                    self.burst_end = Some(now);
                    // Read the gaps at the pace the vehicle chose for its burst.
                    if let Some(first) = self.burst_first
                        && self.burst_chunks > 1
                    {
                        let interval = self.last_rx.duration_since(first) / (self.burst_chunks - 1);
                        self.pace = interval.clamp(READ_PACE, Duration::from_millis(100));
                        self.set_read_timeout();
                    }
                    self.phase = Phase::Window;
                    self.tokens = READ_BURST;
                    // The burst lost chunks, each one way: a read and its answer go both ways.
                    let want = self.end.map_or_else(
                        || {
                            self.chunks
                                .keys()
                                .next_back()
                                .map_or(1, |o| o / CHUNK as u32 + 1)
                        },
                        |e| e.div_ceil(CHUNK as u32),
                    );
                    let got = self.chunks.len() as f64 / f64::from(want.max(1));
                    self.loss = 1.0 - got.min(1.0).powi(2);
                }
                self.fill(now)
            }
            Err(e) => self.fail(format!("{PARAM_FILE}: {e}")),
        }
    }

    fn fail(&mut self, why: String) -> Vec<MavMessage> {
        self.done = Some(Err(why));
        vec![self.request(OP_TERMINATE, 0, &[])]
    }

    /// The chunks to ask for next, in file order: not received, not in flight, before the end
    /// (or past everything received while the end is unknown).
    fn wanted(&self, n: usize) -> Vec<u32> {
        let in_flight: Vec<u32> = self.reads.values().map(|r| r.offset).collect();
        let mut out = Vec::with_capacity(n);
        let mut ofs = 0u32;
        while out.len() < n && self.end.is_none_or(|e| ofs < e) {
            if !self.chunks.contains_key(&ofs) && !in_flight.contains(&ofs) {
                out.push(ofs);
            }
            ofs = ofs.saturating_add(CHUNK as u32);
            if ofs == u32::MAX {
                break;
            }
        }
        out
    }

    /// How long the reads may go without a new chunk: [`FTP_STALL`], or four read timeouts
    /// on a link so slow that a lost read could not be asked again within it.
    fn stall(&self) -> Duration {
        FTP_STALL.max(self.read_timeout * 4)
    }

    /// A round trip and a quarter, and the time the requests queued before one take to leave:
    /// a lost request costs little more than its round trip, a queued one is not sent twice.
    /// On a fast link sixteen may be queued; on a slow one the bucket lets at most
    /// [`READ_BURST`] go together.
    fn set_read_timeout(&mut self) {
        let queued = if self.rtt <= FAST_LINK {
            16
        } else {
            READ_BURST
        };
        self.read_timeout = (self.rtt * 5 / 4 + self.pace * queued).max(READ_TIMEOUT_MIN);
    }

    /// What the read took, for the log: requests, chunks, timeouts and when each step ended.
    #[must_use]
    pub fn summary(&self) -> String {
        let ms = |t: Option<Instant>| {
            t.map_or_else(
                || "-".to_owned(),
                |t| format!("{} ms", t.duration_since(self.started).as_millis()),
            )
        };
        format!(
            "{} requests ({} resets), {} chunks in, {} reads timed out, open answered at {}, \
             burst ended at {} ({}, {} chunks), last chunk at {}, pace {:?}, read timeout {:?}",
            self.sent,
            self.resets,
            self.chunks_received,
            self.reads_timed_out,
            ms(self.opened_at),
            ms(self.burst_end),
            self.burst_end_by,
            self.burst_chunks,
            ms(Some(self.last_rx)),
            self.pace,
            self.read_timeout,
        )
    }

    /// Copies of each request: one on a clean link, two when one in fifty is lost, three
    /// when one in five is (at 30 % loss each way, half the round trips fail; three copies
    /// leave one chunk in eight to the next round).
    fn copies(&self) -> usize {
        match self.loss {
            l if l < 0.02 => 1,
            l if l < 0.2 => 2,
            _ => 3,
        }
    }

    /// The loss estimate from the reads, once there are enough of them.
    fn update_loss(&mut self) {
        let n = self.reads_answered + self.reads_timed_out;
        if n >= 8 {
            self.loss = self.reads_timed_out as f64 / n as f64;
        }
    }

    /// Chunks that may be asked for now, as far as the window goes.
    fn room(&self) -> usize {
        READ_WINDOW.saturating_sub(self.reads.len()) / self.copies()
    }

    /// Requests timed out go again; new ones leave as the window and the pace allow.
    fn fill(&mut self, now: Instant) -> Vec<MavMessage> {
        let timeout = self.read_timeout;
        let before = self.reads.len();
        let mut again = Vec::new();
        self.reads.retain(|_, r| {
            let live = now.duration_since(r.sent) < timeout;
            if !live {
                again.push(r.offset);
            }
            live
        });
        self.asked_again.extend(again);
        if self.reads.len() < before {
            self.reads_timed_out += before - self.reads.len();
            self.update_loss();
        }
        // A token is one chunk asked for, in all its copies: on a link that loses a request
        // or its answer one time in five or more, the copies' answers are what gets one
        // chunk through per burst interval, and three of them use what the vehicle's burst
        // leaves of the link (it paces itself to a third). The bucket holds no more requests
        // than the vehicle's queue takes at once.
        let copies = self.copies();
        let cap = (READ_BURST / u32::try_from(copies).unwrap_or(1)).max(1);
        self.tokens = self.tokens.min(cap);
        while self.tokens < cap && self.next_token <= now {
            self.tokens += 1;
            self.next_token += self.pace;
        }
        if self.tokens == cap {
            self.next_token = now + self.pace;
        }
        let mut out = Vec::new();
        for offset in self.wanted(self.room()) {
            if self.tokens == 0 {
                break;
            }
            self.tokens -= 1;
            // A chunk asked for again goes in one copy more: the few left after a round are
            // what the read waits for.
            let copies = if self.asked_again.contains(&offset) {
                (copies + 1).min(MAX_READ_COPIES)
            } else {
                copies
            };
            for _ in 0..copies {
                out.push(self.chunk_request(OP_READ, offset));
                self.reads.insert(self.seq, Read { offset, sent: now });
            }
        }
        out
    }

    /// A read's answer (`offset` from its request), or the end of the file there.
    fn on_read(&mut self, now: Instant, offset: u32, data: Option<Vec<u8>>) -> Vec<MavMessage> {
        match data {
            Some(data) => {
                if data.len() < CHUNK {
                    let end = offset + u32::try_from(data.len()).unwrap_or(0);
                    self.end = Some(self.end.map_or(end, |e| e.min(end)));
                }
                self.chunks.entry(offset).or_insert(data);
                self.reads_answered += 1;
                self.update_loss();
                // The other copy's answer, if it comes, is not waited for.
                self.reads.retain(|_, r| r.offset != offset);
            }
            None => self.end = Some(self.end.map_or(offset, |e| e.min(offset))),
        }
        if let Some(end) = self.end {
            self.reads.retain(|_, r| r.offset < end);
        }
        if self.complete() {
            self.settle(now)
        } else {
            self.fill(now)
        }
    }
}

impl Machine for FtpPullMachine {
    type Output = Result<ParamSet, String>;

    fn start(&mut self, now: Instant) -> Vec<MavMessage> {
        self.last_rx = now;
        self.open(now)
    }

    fn on_message(&mut self, now: Instant, m: &Inbound) -> Vec<MavMessage> {
        if self.done.is_some() || (m.sys, m.comp) != self.target {
            return Vec::new();
        }
        let MavMessage::FILE_TRANSFER_PROTOCOL(f) = &m.msg else {
            return Vec::new();
        };
        let p = &f.payload;
        let seq = u16::from_le_bytes([p[0], p[1]]);
        let (session, opcode, size, req) = (p[2], p[3], usize::from(p[4]), p[5]);
        let burst_complete = p[6] != 0;
        let offset = u32::from_le_bytes([p[8], p[9], p[10], p[11]]);
        if session != self.session || !matches!(opcode, OP_ACK | OP_NAK) {
            return Vec::new();
        }
        self.last_rx = now;
        match (self.phase, opcode, req) {
            (Phase::Close, _, OP_TERMINATE) => {
                self.done = self.table.take().map(Ok);
                Vec::new()
            }
            (Phase::Open, OP_ACK, OP_OPEN_RO) => {
                self.last_rx = now;
                self.opened_at = Some(now);
                let rtt = now.duration_since(self.open_sent.unwrap_or(now));
                // Timed from the first open, the round trip is too long by the retries' waits
                // when earlier opens were lost (1.8 s where the link's is 0.2 s): the reads'
                // timeout takes no more than the link's own estimate, or the last open's
                // round trip if that is longer.
                let since_last = now.duration_since(self.open_last.unwrap_or(now));
                self.rtt = rtt.min(self.link_rtt.unwrap_or(self.rto).max(since_last));
                self.set_read_timeout();
                if rtt <= FAST_LINK {
                    self.phase = Phase::Window;
                    self.fill(now)
                } else {
                    vec![self.burst(now)]
                }
            }
            (Phase::Open, OP_NAK, OP_OPEN_RO) if p[12] == ERR_FAIL && self.resets < RESETS => {
                self.resets += 1;
                self.phase = Phase::Reset;
                self.retry = Retry::new(self.request_rto(), FTP_TRIES, Duration::ZERO);
                self.retry.send(now);
                vec![self.request(OP_TERMINATE, 0, &[])]
            }
            (Phase::Reset, OP_ACK, OP_TERMINATE) => {
                self.phase = Phase::Open;
                self.open_request = None;
                self.retry = Retry::new(self.request_rto(), FTP_TRIES, Duration::ZERO);
                self.open(now)
            }
            (Phase::Open, OP_NAK, OP_OPEN_RO) => {
                self.done = Some(Err(format!(
                    "{PARAM_FILE}: open refused (FTP error {})",
                    p[12]
                )));
                Vec::new()
            }
            (Phase::Burst, OP_ACK, OP_BURST) => {
                self.last_rx = now;
                self.chunks_received += 1;
                self.burst_first.get_or_insert(now);
                self.burst_chunks += 1;
                let data = p[12..12 + size.min(CHUNK)].to_vec();
                if size < CHUNK {
                    self.end = Some(offset + u32::try_from(size).unwrap_or(0));
                }
                self.chunks.entry(offset).or_insert(data);
                // The next chunk is due at once: the retry waits for a pause in the burst.
                self.retry
                    .wait_until(now + self.request_rto().max(BURST_PAUSE));
                if burst_complete || self.complete() {
                    self.burst_end_by = "last chunk";
                    self.settle(now)
                } else {
                    Vec::new()
                }
            }
            (Phase::Burst, OP_NAK, OP_BURST) if p[12] == ERR_EOF => {
                self.last_rx = now;
                // The end is at most where the vehicle ran out.
                let received = self
                    .chunks
                    .iter()
                    .next_back()
                    .map_or(0, |(o, d)| o + u32::try_from(d.len()).unwrap_or(0));
                self.end = Some(self.end.unwrap_or(u32::MAX).min(received.max(offset)));
                self.burst_end_by = "end of file";
                self.settle(now)
            }
            (Phase::Window, OP_ACK, OP_READ) => {
                self.last_rx = now;
                self.chunks_received += 1;
                self.reads.remove(&seq.wrapping_sub(1));
                let data = p[12..12 + size.min(CHUNK)].to_vec();
                self.on_read(now, offset, Some(data))
            }
            (Phase::Window, OP_NAK, OP_READ) if p[12] == ERR_EOF => {
                self.last_rx = now;
                // A NAK's offset is whatever the vehicle's last reply had: the request's is
                // the one that ran out.
                match self.reads.remove(&seq.wrapping_sub(1)) {
                    Some(r) => self.on_read(now, r.offset, None),
                    None => Vec::new(),
                }
            }
            // The burst's last answers, come after its pause ended it: chunks are kept, its end
            // of file is left to the reads.
            (Phase::Window, OP_ACK, OP_BURST) => {
                self.chunks_received += 1;
                let data = p[12..12 + size.min(CHUNK)].to_vec();
                self.on_read(now, offset, Some(data))
            }
            (Phase::Window, OP_NAK, OP_BURST | OP_READ) if p[12] == ERR_EOF => Vec::new(),
            (Phase::Burst | Phase::Window, OP_NAK, OP_BURST | OP_READ) => {
                self.fail(format!("{PARAM_FILE}: read refused (FTP error {})", p[12]))
            }
            _ => Vec::new(),
        }
    }

    fn on_time(&mut self, now: Instant) -> Vec<MavMessage> {
        if self.done.is_some() {
            return Vec::new();
        }
        // The open and the reset have their tries; a read stalls.
        if matches!(self.phase, Phase::Burst | Phase::Window)
            && now.duration_since(self.last_rx) > self.stall()
        {
            self.done = Some(Err(format!("{PARAM_FILE}: no answer")));
            return Vec::new();
        }
        if self.phase == Phase::Window {
            return self.fill(now);
        }
        match (self.retry.step(now), self.phase) {
            (Step::Wait, _) => Vec::new(),
            (Step::GiveUp, Phase::Open) => {
                self.done = Some(Err(format!("{PARAM_FILE}: no answer to open")));
                Vec::new()
            }
            (Step::Send, Phase::Open) => self.open(now),
            (Step::Send, Phase::Reset) => {
                self.retry.send(now);
                vec![self.request(OP_TERMINATE, 0, &[])]
            }
            (Step::GiveUp, Phase::Reset) => {
                self.done = Some(Err(format!(
                    "{PARAM_FILE}: no answer to the session's reset"
                )));
                Vec::new()
            }
            // The burst paused, or its request was lost: what came may already be all of it,
            // or the gaps are read.
            // A burst of which nothing came was lost on its way: asked again.
            (Step::Send, Phase::Burst) if self.burst_chunks == 0 => {
                self.retry.send(now);
                vec![self.chunk_request(OP_BURST, 0)]
            }
            (Step::Send | Step::GiveUp, Phase::Burst) => {
                self.burst_end_by = "pause";
                self.settle(now)
            }
            (Step::Send, Phase::Close) => self.close(now),
            (Step::GiveUp, Phase::Close) => {
                self.done = self.table.take().map(Ok);
                Vec::new()
            }
            (_, Phase::Window) => Vec::new(),
        }
    }

    fn deadline(&self) -> Instant {
        let stall = self.last_rx + self.stall() + Duration::from_millis(1);
        if self.phase == Phase::Window {
            let oldest = self
                .reads
                .values()
                .map(|r| r.sent + self.read_timeout)
                .min();
            let token = (self.room() > 0 && !self.wanted(1).is_empty()).then_some(self.next_token);
            return [Some(stall), oldest, token]
                .into_iter()
                .flatten()
                .min()
                .unwrap_or(stall);
        }
        if self.phase == Phase::Burst {
            self.retry.deadline().min(stall)
        } else {
            self.retry.deadline()
        }
    }

    fn result(&mut self) -> Option<Self::Output> {
        self.done.take()
    }
}

#[cfg(test)]
#[path = "ftp_tests.rs"]
mod tests;
