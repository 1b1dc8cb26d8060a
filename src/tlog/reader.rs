//! Reading a log back, surviving a torn tail and garbage between records.

use std::fs::File;
use std::io::{self, Read};
use std::path::Path;

use bytes::Bytes;
use vtol_link::Frame;
use vtol_link::tlog::MAX_RECORD_LEN;

/// Bytes read from the file at a time by [`TlogReader`].
pub(super) const READ_CHUNK: usize = 256 * 1024;
/// While resynchronising, a candidate record's timestamp must lie this close to the last good
/// one (µs): a CRC-valid frame inside garbage is rare, one with a plausible time rarer still.
pub(super) const RESYNC_MAX_JUMP_US: u64 = 24 * 3600 * 1_000_000;
/// 2000-01-01 to 2100-01-01 in Unix µs: where a logger's timestamp can be.
pub(super) const PLAUSIBLE_UNIX_US: std::ops::Range<u64> =
    946_684_800_000_000..4_102_444_800_000_000;

/// Streaming reader of the records of a tlog written by this project, pymavlink or MAVProxy.
///
/// It reads the file in chunks (memory stays flat on long logs) and hands out frames that share
/// the chunk's buffer. A record whose frame does not check out is skipped by resynchronising on
/// the next timestamp-plus-frame that does; the bytes passed over are counted in
/// [`skipped_bytes`](Self::skipped_bytes). While resynchronising only frames whose CRC the
/// dialect can check, with a timestamp within a day of the last good one, are taken, so garbage
/// is not mistaken for a frame of an unknown message id. An incomplete record at the end of the
/// file (a crash mid-write, a cut copy) ends the iteration and is reported in
/// [`truncated_tail_bytes`](Self::truncated_tail_bytes), never as an error.
pub struct TlogReader {
    src: Box<dyn Read + Send>,
    /// Unconsumed bytes of the file; `buf[pos..]` is still to be parsed.
    buf: Bytes,
    pos: usize,
    eof: bool,
    /// True after a bad record until a record checks out again.
    resyncing: bool,
    last_stamp: Option<u64>,
    consumed: u64,
    /// Bytes skipped while resynchronising (garbage between records, damaged records).
    pub skipped_bytes: usize,
    /// Bytes of an incomplete last record, if the file ends inside one.
    pub truncated_tail_bytes: usize,
    /// A read error that ended the iteration early.
    pub io_error: Option<io::Error>,
}

impl std::fmt::Debug for TlogReader {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("TlogReader")
            .field("consumed", &self.consumed)
            .field("skipped_bytes", &self.skipped_bytes)
            .field("truncated_tail_bytes", &self.truncated_tail_bytes)
            .finish_non_exhaustive()
    }
}

impl TlogReader {
    /// Opens a file for streaming.
    ///
    /// # Errors
    /// The file cannot be opened.
    pub fn open(path: &Path) -> io::Result<Self> {
        Ok(Self::new(Box::new(File::open(path)?)))
    }

    /// Reads records from any byte source.
    #[must_use]
    pub fn new(src: Box<dyn Read + Send>) -> Self {
        Self {
            src,
            buf: Bytes::new(),
            pos: 0,
            eof: false,
            // The first record is found like one after garbage: a file may start with junk.
            resyncing: true,
            last_stamp: None,
            consumed: 0,
            skipped_bytes: 0,
            truncated_tail_bytes: 0,
            io_error: None,
        }
    }

    /// Reads records from bytes in memory.
    #[must_use]
    pub fn from_bytes(data: Vec<u8>) -> Self {
        Self::new(Box::new(io::Cursor::new(data)))
    }

    /// Bytes of the file parsed so far (records, skipped bytes and a torn tail): for progress.
    #[must_use]
    pub fn bytes_consumed(&self) -> u64 {
        self.consumed
    }

    /// Keeps two whole records buffered unless the file ends first (a resync candidate is checked
    /// against the record behind it).
    fn fill(&mut self) {
        if self.eof || self.buf.len() - self.pos >= 2 * MAX_RECORD_LEN {
            return;
        }
        let rest = &self.buf[self.pos..];
        let mut next = Vec::with_capacity(rest.len() + READ_CHUNK);
        next.extend_from_slice(rest);
        while next.len() < 2 * MAX_RECORD_LEN && !self.eof {
            let have = next.len();
            next.resize(have + READ_CHUNK, 0);
            match self.src.read(&mut next[have..]) {
                Ok(0) => {
                    next.truncate(have);
                    self.eof = true;
                }
                Ok(n) => next.truncate(have + n),
                Err(e) if e.kind() == io::ErrorKind::Interrupted => next.truncate(have),
                Err(e) => {
                    next.truncate(have);
                    self.io_error = Some(e);
                    self.eof = true;
                }
            }
        }
        self.buf = Bytes::from(next);
        self.pos = 0;
    }

    fn advance(&mut self, n: usize) {
        self.pos += n;
        self.consumed += n as u64;
    }
}

impl Iterator for TlogReader {
    type Item = (u64, Frame);

    fn next(&mut self) -> Option<Self::Item> {
        loop {
            self.fill();
            let avail = &self.buf[self.pos..];
            if avail.is_empty() {
                return None;
            }
            let Some(len) = avail.get(8..).and_then(vtol_link::frame_len_from_prefix) else {
                if avail.len() < 8 + 3 && self.eof {
                    // Too short to hold even a header: a torn record if we are in step,
                    // otherwise more garbage.
                    return self.end_with_tail(avail.len());
                }
                self.skip_one();
                continue;
            };
            if 8 + len > avail.len() {
                // Only possible at the end of the file (fill keeps whole records buffered). It
                // is a torn last record only if no whole record starts in the bytes left.
                if self.resyncing || whole_record_within(&avail[1..]) {
                    self.skip_one();
                    continue;
                }
                return self.end_with_tail(avail.len());
            }
            let stamp = u64::from_be_bytes(avail[..8].try_into().ok()?);
            let bytes = self.buf.slice(self.pos + 8..self.pos + 8 + len);
            match Frame::from_bytes(bytes) {
                Ok(frame) if self.acceptable(stamp, &frame, 8 + len) => {
                    self.resyncing = false;
                    // A damaged timestamp in a record that is otherwise whole must not become
                    // the reference that later candidates are judged by.
                    if self
                        .last_stamp
                        .is_none_or(|l| stamp.abs_diff(l) <= RESYNC_MAX_JUMP_US)
                    {
                        self.last_stamp = Some(stamp);
                    }
                    self.advance(8 + len);
                    return Some((stamp, frame));
                }
                _ => self.skip_one(),
            }
        }
    }
}

/// Whether a record with a CRC-checked frame starts anywhere in `bytes`.
pub(super) fn whole_record_within(bytes: &[u8]) -> bool {
    (0..bytes.len()).any(|i| checked_record_at(&bytes[i..]))
}

/// Whether `bytes` starts with a whole record whose frame's CRC checks.
pub(super) fn checked_record_at(bytes: &[u8]) -> bool {
    bytes
        .get(8..)
        .and_then(vtol_link::frame_len_from_prefix)
        .and_then(|len| bytes.get(8..8 + len))
        .and_then(|b| Frame::from_bytes(Bytes::copy_from_slice(b)).ok())
        .is_some_and(|f| f.is_verified())
}

impl TlogReader {
    fn skip_one(&mut self) {
        self.resyncing = true;
        self.skipped_bytes += 1;
        self.advance(1);
    }

    fn end_with_tail(&mut self, n: usize) -> Option<(u64, Frame)> {
        if self.resyncing {
            self.skipped_bytes += n;
        } else {
            self.truncated_tail_bytes += n;
        }
        self.advance(n);
        None
    }

    /// Whether a whole record at `pos` is taken.
    ///
    /// In step (right after a good record), a frame whose CRC checks is taken. A frame of an id
    /// the dialect does not know has no CRC to check, so it is taken only if its time is within
    /// a day of the last good one and another whole, CRC-checked record follows right behind
    /// it: otherwise garbage right after a record could pass as one. (So such a frame as the very last record is counted as skipped.)
    ///
    /// While resynchronising (and at the start of the file), two of three must hold: the CRC
    /// checks, the time is within a day of the last good one, a whole CRC-checked record
    /// follows. A frame of an unknown id needs both of the others (before any good record, a
    /// plausible Unix time stands in for the first), and never swallows the start of a checked
    /// record.
    fn acceptable(&self, stamp: u64, frame: &Frame, record_len: usize) -> bool {
        let followed = || checked_record_at(&self.buf[self.pos + record_len..]);
        // An unchecked frame that would swallow the start of a checked record is garbage that
        // happens to look like a header: the checked record wins.
        if !frame.is_verified()
            && (1..record_len).any(|i| checked_record_at(&self.buf[self.pos + i..]))
        {
            return false;
        }
        let near = match self.last_stamp {
            Some(last) => stamp.abs_diff(last) <= RESYNC_MAX_JUMP_US,
            // Nothing to compare with yet: a checked frame passes, but a frame nobody can check
            // must at least carry a plausible wall-clock time (loggers stamp Unix µs).
            None => frame.is_verified() || PLAUSIBLE_UNIX_US.contains(&stamp),
        };
        if !self.resyncing {
            // In step an unchecked frame also needs a time that fits: garbage right after a
            // record can form a whole frame of an unknown id, but rarely its time.
            return frame.is_verified() || (near && followed());
        }
        match (frame.is_verified(), near) {
            (true, true) => true,
            (true, false) | (false, true) => followed(),
            (false, false) => false,
        }
    }
}
