//! Telemetry log (`.tlog`) in the standard format pymavlink, MAVProxy and mavlogdump read:
//! records of an 8-byte big-endian timestamp (µs since the Unix epoch, low 2 bits = link
//! number) followed by one complete MAVLink frame, no file header, no padding.
//!
//! The writer runs on its own thread, so a slow disk never stalls routing. Producers encode
//! records into a shared, bounded buffer (a full buffer drops the record and counts it) and do
//! not wake the thread for each one: the thread sleeps until the oldest waiting record is
//! [`WRITE_DELAY`] old, then writes everything waiting in one write and flushes. So a record
//! reaches the file at most 100 ms ([`FLUSH_INTERVAL`]) after it arrives, a `kill -9` loses at
//! most the last 100 ms, and no torn record is left behind (each record is encoded whole into
//! the buffer, and the buffer is only ever written out whole). An idle log costs no wake-ups;
//! under load the thread writes once per [`WRITE_DELAY`], whatever the frame rate, waking on
//! its own timer: the producers only wake it after a quiet spell.
//! SETUP_SIGNING is never logged: it carries the signing key.

use std::fs::{File, OpenOptions};
use std::io::{self, BufWriter, Read, Seek, Write};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Arc, Mutex, MutexGuard, PoisonError};
use std::thread::JoinHandle;
use std::time::{Duration, Instant, SystemTime, UNIX_EPOCH};

use bytes::Bytes;
use vtol_link::Frame;

/// SETUP_SIGNING: never written to a log.
const SETUP_SIGNING_ID: u32 = 256;
/// How long a record may sit in the buffer before it reaches the file.
pub const FLUSH_INTERVAL: Duration = Duration::from_millis(100);
/// How long the writer thread lets records gather before it writes them: half the bound, so
/// the write itself has the other half.
pub const WRITE_DELAY: Duration = Duration::from_millis(50);
/// Good batch writes in a row (about a second of traffic) that end a failure streak.
const RECOVERED_AFTER_WRITES: u32 = 20;
/// Largest record: the timestamp and the largest frame.
const MAX_RECORD_LEN: usize = 8 + vtol_link::frame::MAX_FRAME_LEN;

/// Which way a frame travelled, as the low 2 bits of the timestamp (MAVProxy's convention).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Direction {
    /// Received from the vehicle link.
    FromVehicle,
    /// Sent towards the vehicle: from a client, or the daemon's own traffic.
    ToVehicle,
}

impl Direction {
    fn link_bits(self) -> u64 {
        match self {
            Self::FromVehicle => 0,
            Self::ToVehicle => 3,
        }
    }
}

/// One record to log.
#[derive(Debug, Clone)]
pub struct Record {
    /// Wall-clock time of the frame, µs since the Unix epoch.
    pub t_us: u64,
    /// Direction.
    pub direction: Direction,
    /// The frame, bytes as on the wire.
    pub frame: Frame,
}

impl Record {
    /// A record stamped now.
    #[must_use]
    pub fn now(direction: Direction, frame: Frame) -> Self {
        Self {
            t_us: unix_time_us(),
            direction,
            frame,
        }
    }
}

impl Record {
    /// The record's 8-byte timestamp: µs with the direction in the low 2 bits.
    fn stamp(&self) -> u64 {
        (self.t_us & !3) | self.direction.link_bits()
    }

    /// Appends the record as it goes into the file (stamp, then the frame); false, and nothing
    /// appended, for SETUP_SIGNING.
    fn encode_into(&self, out: &mut Vec<u8>) -> bool {
        if self.frame.message_id() == SETUP_SIGNING_ID {
            return false;
        }
        out.extend_from_slice(&self.stamp().to_be_bytes());
        out.extend_from_slice(self.frame.as_bytes());
        true
    }
}

/// µs since the Unix epoch.
#[must_use]
pub fn unix_time_us() -> u64 {
    SystemTime::now()
        .duration_since(UNIX_EPOCH)
        .map_or(0, |d| u64::try_from(d.as_micros()).unwrap_or(u64::MAX))
}

/// Counters the writer keeps; shown in the status line and the TUI.
#[derive(Debug, Default)]
pub struct TlogStats {
    /// Records written to the buffer.
    pub records: AtomicU64,
    /// Bytes written to the buffer.
    pub bytes: AtomicU64,
    /// Records dropped because the writer's buffer was full (the disk did not keep up).
    pub dropped_queue_full: AtomicU64,
    /// Records lost to write errors (full disk, I/O error), or logged after the log closed.
    pub write_errors: AtomicU64,
    /// SETUP_SIGNING frames withheld.
    pub withheld_signing: AtomicU64,
    /// The write error of the current failure streak (a full disk), `None` while writes
    /// succeed: the status line shows it until logging resumes.
    failing: Mutex<Option<String>>,
}

impl TlogStats {
    /// Why the log is not being written right now (e.g. "No space left on device"), or `None`
    /// while it is. Records that arrive meanwhile are lost and counted in
    /// [`write_errors`](Self::write_errors); the writer tries again with every batch, so logging
    /// resumes by itself once there is room.
    #[must_use]
    pub fn failing(&self) -> Option<String> {
        self.failing
            .lock()
            .unwrap_or_else(PoisonError::into_inner)
            .clone()
    }

    fn set_failing(&self, why: Option<String>) {
        *self.failing.lock().unwrap_or_else(PoisonError::into_inner) = why;
    }
}

/// Errors opening a log.
#[derive(Debug, thiserror::Error)]
pub enum TlogError {
    /// The log directory or file could not be created.
    #[error("cannot create tlog {path}: {source}")]
    Create {
        /// The path.
        path: PathBuf,
        /// The cause.
        source: io::Error,
    },
}

/// Synchronous writer of tlog records (used by the writer thread, and directly by tools).
#[derive(Debug)]
pub struct TlogWriter {
    out: BufWriter<File>,
}

impl TlogWriter {
    /// Creates `path`, which must not exist yet: a log is never overwritten.
    ///
    /// # Errors
    /// The file exists already, or cannot be created.
    pub fn create(path: &Path) -> Result<Self, TlogError> {
        // `create_new` is O_EXCL: of two processes racing for one name, exactly one wins.
        let file = match OpenOptions::new().create_new(true).write(true).open(path) {
            // A device or a pipe (/dev/full, a FIFO) holds no log to lose: write to it.
            Err(e) if e.kind() == io::ErrorKind::AlreadyExists && !is_regular_file(path) => {
                OpenOptions::new().write(true).open(path)
            }
            other => other,
        }
        .map_err(|source| TlogError::Create {
            path: path.to_owned(),
            source,
        })?;
        Ok(Self {
            out: BufWriter::with_capacity(64 * 1024, file),
        })
    }

    /// Appends one record. Returns false if the record was withheld (SETUP_SIGNING).
    ///
    /// # Errors
    /// A write error from the file.
    pub fn write(&mut self, record: &Record) -> io::Result<bool> {
        if record.frame.message_id() == SETUP_SIGNING_ID {
            return Ok(false);
        }
        // One contiguous record, so the buffer never holds half of one when it is written out.
        let frame = record.frame.as_bytes();
        let mut buf = [0u8; MAX_RECORD_LEN];
        buf[..8].copy_from_slice(&record.stamp().to_be_bytes());
        buf[8..8 + frame.len()].copy_from_slice(frame);
        self.out.write_all(&buf[..8 + frame.len()])?;
        Ok(true)
    }

    /// Writes the buffer out to the file.
    ///
    /// # Errors
    /// A write error from the file.
    pub fn flush(&mut self) -> io::Result<()> {
        self.out.flush()
    }

    /// The file, for the writer thread, which writes whole batches itself (nothing is buffered
    /// yet when it takes over).
    fn into_file(self) -> File {
        self.out.into_parts().0
    }
}

/// Records waiting for the writer thread, encoded as they go into the file.
#[derive(Debug, Default)]
struct Pending {
    bytes: Vec<u8>,
    records: u64,
    /// When the oldest waiting record arrived; `None` while nothing waits.
    oldest: Option<Instant>,
    /// The writer sleeps with no deadline (nothing was waiting): the next record must wake it.
    writer_idle: bool,
    /// No more records: the writer writes what waits, flushes and ends.
    closed: bool,
}

#[derive(Debug)]
struct Shared {
    pending: Mutex<Pending>,
    /// Most records waiting at once; more are dropped and counted.
    capacity: u64,
}

impl Shared {
    fn lock(&self) -> MutexGuard<'_, Pending> {
        // A panic elsewhere while holding the lock leaves consistent bytes (records are
        // appended whole), so the log goes on.
        self.pending.lock().unwrap_or_else(PoisonError::into_inner)
    }
}

/// Handle to a running writer thread.
#[derive(Debug)]
pub struct TlogHandle {
    shared: Arc<Shared>,
    /// Where the log is written.
    pub path: PathBuf,
    /// Live counters.
    pub stats: Arc<TlogStats>,
    thread: Option<JoinHandle<()>>,
}

impl TlogHandle {
    /// Creates a new `dir/<start time>.tlog` and starts the writer thread with room for
    /// `queue_len` waiting records. A name already taken (a restart within the same second, or
    /// another daemon logging to the same directory) gets a `-2`, `-3` … suffix: no log is ever
    /// overwritten or shared.
    ///
    /// # Errors
    /// The directory or the file cannot be created.
    pub fn start(dir: &Path, queue_len: usize) -> Result<Self, TlogError> {
        let (path, writer) = create_unique(dir, SystemTime::now())?;
        Self::spawn(path, writer, queue_len)
    }

    /// Starts the writer on an explicit file path, which must not exist yet.
    ///
    /// # Errors
    /// The file exists already, or cannot be created.
    pub fn start_at(path: &Path, queue_len: usize) -> Result<Self, TlogError> {
        let writer = TlogWriter::create(path)?;
        Self::spawn(path.to_owned(), writer, queue_len)
    }

    fn spawn(path: PathBuf, writer: TlogWriter, queue_len: usize) -> Result<Self, TlogError> {
        let shared = Arc::new(Shared {
            pending: Mutex::new(Pending::default()),
            capacity: queue_len.max(1) as u64,
        });
        let stats = Arc::new(TlogStats::default());
        let (thread_shared, thread_stats) = (Arc::clone(&shared), Arc::clone(&stats));
        let thread = std::thread::Builder::new()
            .name("tlog-writer".into())
            .spawn(move || writer_loop(writer, &thread_shared, &thread_stats))
            .map_err(|source| TlogError::Create {
                path: path.clone(),
                source,
            })?;
        Ok(Self {
            shared,
            path,
            stats,
            thread: Some(thread),
        })
    }

    /// Hands a record to the writer without blocking; a full buffer drops it and counts the
    /// drop.
    pub fn log(&self, record: Record) {
        self.log_many(std::iter::once(record));
    }

    /// Hands a run of records to the writer under one lock, waking the writer thread only if
    /// it sleeps with nothing to do.
    pub fn log_many(&self, records: impl IntoIterator<Item = Record>) {
        let mut wake = false;
        {
            let mut p = self.shared.lock();
            for record in records {
                if p.closed {
                    self.stats.write_errors.fetch_add(1, Ordering::Relaxed);
                } else if p.records >= self.shared.capacity {
                    self.stats
                        .dropped_queue_full
                        .fetch_add(1, Ordering::Relaxed);
                } else if record.encode_into(&mut p.bytes) {
                    p.records += 1;
                    if p.oldest.is_none() {
                        p.oldest = Some(Instant::now());
                    }
                } else {
                    self.stats.withheld_signing.fetch_add(1, Ordering::Relaxed);
                }
            }
            if p.writer_idle && p.oldest.is_some() {
                p.writer_idle = false;
                wake = true;
            }
        }
        if wake && let Some(t) = &self.thread {
            t.thread().unpark();
        }
    }

    /// Closes the log: the writer writes and flushes everything waiting, and ends.
    pub fn close(mut self) {
        self.finish();
    }

    fn finish(&mut self) {
        self.shared.lock().closed = true;
        if let Some(t) = self.thread.take() {
            t.thread().unpark();
            let _ = t.join();
        }
    }
}

impl Drop for TlogHandle {
    fn drop(&mut self) {
        self.finish();
    }
}

/// The writer thread: sleeps until the oldest waiting record is [`WRITE_DELAY`] old, or under
/// traffic until [`WRITE_DELAY`] after its last write (or the log closes), then writes
/// everything waiting at once and flushes.
///
/// A batch that fails (a full disk) is cut off the file again, so the file keeps only whole
/// records, and counted as lost; the error is logged once per failure streak and shown through
/// [`TlogStats::failing`]. The next batch is tried as usual, so logging resumes as soon as the
/// disk has room again. Routing never waits for any of this.
fn writer_loop(writer: TlogWriter, shared: &Shared, stats: &TlogStats) {
    let mut out = writer.into_file();
    let mut batch: Vec<u8> = Vec::new();
    let mut reported_error = false;
    let mut lost_in_streak: u64 = 0;
    let mut ok_in_row: u32 = 0;
    // Bytes of whole records in the file: where a failed batch is cut back to.
    let mut good_len = out.stream_position().unwrap_or(0);
    // While records keep coming: when the next write is due, one WRITE_DELAY after the last.
    let mut next_write: Option<Instant> = None;
    loop {
        let (records, closed) = {
            let mut p = shared.lock();
            let now = Instant::now();
            let Some(oldest) = p.oldest else {
                if p.closed {
                    return;
                }
                if let Some(next) = next_write
                    && now < next
                {
                    // Traffic was flowing at the last write: look again when the next is due,
                    // without asking the producers to wake this thread.
                    drop(p);
                    std::thread::park_timeout(next - now);
                    continue;
                }
                next_write = None;
                p.writer_idle = true;
                drop(p);
                // Woken by the next record (or spuriously: the loop looks again).
                std::thread::park();
                continue;
            };
            // Under traffic a write every WRITE_DELAY, each taking whatever waits (none of it
            // older than that); after a quiet spell, WRITE_DELAY after the first record.
            let due =
                next_write.map_or(oldest + WRITE_DELAY, |next| next.min(oldest + WRITE_DELAY));
            if now < due && !p.closed {
                drop(p);
                std::thread::park_timeout(due - now);
                continue;
            }
            std::mem::swap(&mut batch, &mut p.bytes);
            let records = std::mem::take(&mut p.records);
            p.oldest = None;
            next_write = Some(now + WRITE_DELAY);
            (records, p.closed)
        };
        let written = out.write_all(&batch).and_then(|()| out.flush());
        match written {
            Ok(()) => {
                stats.records.fetch_add(records, Ordering::Relaxed);
                stats.bytes.fetch_add(batch.len() as u64, Ordering::Relaxed);
                good_len += batch.len() as u64;
                ok_in_row += 1;
                // A nearly full disk takes a small batch and refuses the next big one: only a
                // run of good writes ends the failure, so the error is not reported again and
                // again while the disk stays full.
                if reported_error && ok_in_row >= RECOVERED_AFTER_WRITES {
                    tracing::warn!(
                        "tlog writing again; {lost_in_streak} records were lost while it failed"
                    );
                    stats.set_failing(None);
                    reported_error = false;
                    lost_in_streak = 0;
                }
            }
            Err(e) => {
                stats.write_errors.fetch_add(records, Ordering::Relaxed);
                lost_in_streak += records;
                ok_in_row = 0;
                // Part of the batch may have reached the file: cut it off, so the file holds
                // whole records only and the next batch follows the last whole one. (A device
                // such as /dev/full has no length to cut: nothing to do there.)
                if out.set_len(good_len).is_ok() {
                    let _ = out.seek(io::SeekFrom::Start(good_len));
                }
                if !reported_error {
                    tracing::error!(
                        "tlog write failed, records are lost until it succeeds again (routing continues): {e}"
                    );
                    stats.set_failing(Some(e.to_string()));
                    reported_error = true;
                }
            }
        }
        batch.clear();
        if closed {
            // Records may not arrive after the close; the loop ends once nothing waits.
            continue;
        }
    }
}

fn is_regular_file(path: &Path) -> bool {
    std::fs::metadata(path).is_ok_and(|m| m.is_file())
}

/// How many suffixed names are tried before giving up on a directory.
const MAX_NAME_TRIES: u32 = 1000;

/// Creates the first free name of `<start time>.tlog`, `<start time>-2.tlog`, … in `dir`.
fn create_unique(dir: &Path, t: SystemTime) -> Result<(PathBuf, TlogWriter), TlogError> {
    std::fs::create_dir_all(dir).map_err(|source| TlogError::Create {
        path: dir.to_owned(),
        source,
    })?;
    let base = log_file_name(t);
    let stem = base.trim_end_matches(".tlog");
    let mut last_err = None;
    for n in 1..=MAX_NAME_TRIES {
        let name = if n == 1 {
            base.clone()
        } else {
            format!("{stem}-{n}.tlog")
        };
        let path = dir.join(name);
        match TlogWriter::create(&path) {
            Ok(w) => return Ok((path, w)),
            Err(TlogError::Create { source, .. })
                if source.kind() == io::ErrorKind::AlreadyExists =>
            {
                last_err = Some(source);
            }
            Err(e) => return Err(e),
        }
    }
    Err(TlogError::Create {
        path: dir.join(base),
        source: last_err.unwrap_or_else(|| io::Error::other("no free log name")),
    })
}

/// `YYYY-MM-DD_HH-MM-SS.tlog` (UTC) for a start time.
#[must_use]
pub fn log_file_name(t: SystemTime) -> String {
    let secs = t.duration_since(UNIX_EPOCH).map_or(0, |d| d.as_secs());
    let (days, rem) = (secs / 86_400, secs % 86_400);
    let (y, m, d) = civil_from_days(i64::try_from(days).unwrap_or(0));
    format!(
        "{y:04}-{m:02}-{d:02}_{:02}-{:02}-{:02}.tlog",
        rem / 3600,
        (rem % 3600) / 60,
        rem % 60
    )
}

/// Gregorian date from days since 1970-01-01 (H. Hinnant's algorithm).
fn civil_from_days(z: i64) -> (i64, u32, u32) {
    let z = z + 719_468;
    let era = z.div_euclid(146_097);
    let doe = z.rem_euclid(146_097);
    let yoe = (doe - doe / 1460 + doe / 36_524 - doe / 146_096) / 365;
    let doy = doe - (365 * yoe + yoe / 4 - yoe / 100);
    let mp = (5 * doy + 2) / 153;
    let d = u32::try_from(doy - (153 * mp + 2) / 5 + 1).unwrap_or(1);
    let m = u32::try_from(if mp < 10 { mp + 3 } else { mp - 9 }).unwrap_or(1);
    (era * 400 + yoe + i64::from(m <= 2), m, d)
}

/// Bytes read from the file at a time by [`TlogReader`].
const READ_CHUNK: usize = 256 * 1024;
/// While resynchronising, a candidate record's timestamp must lie this close to the last good
/// one (µs): a CRC-valid frame inside garbage is rare, one with a plausible time rarer still.
const RESYNC_MAX_JUMP_US: u64 = 24 * 3600 * 1_000_000;
/// 2000-01-01 to 2100-01-01 in Unix µs: where a logger's timestamp can be.
const PLAUSIBLE_UNIX_US: std::ops::Range<u64> = 946_684_800_000_000..4_102_444_800_000_000;

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
fn whole_record_within(bytes: &[u8]) -> bool {
    (0..bytes.len()).any(|i| checked_record_at(&bytes[i..]))
}

/// Whether `bytes` starts with a whole record whose frame's CRC checks.
fn checked_record_at(bytes: &[u8]) -> bool {
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

#[cfg(test)]
mod tests {
    use super::*;
    use vtol_link::dialect::{self, MavMessage};

    fn heartbeat(seq: u8) -> Frame {
        Frame::encode_v2(
            vtol_link::SystemId(255),
            vtol_link::ComponentId(190),
            seq,
            &vtol_link::gcs_heartbeat(),
        )
    }

    #[test]
    fn file_name_is_utc_date() {
        let t = UNIX_EPOCH + Duration::from_secs(1_795_346_880);
        assert_eq!(log_file_name(t), "2026-11-22_11-28-00.tlog");
    }

    #[test]
    fn round_trip_with_direction_bits_and_signing_withheld() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("a.tlog");
        let mut w = TlogWriter::create(&path).unwrap();
        let t = 1_795_346_880_485_324;
        assert!(
            w.write(&Record {
                t_us: t,
                direction: Direction::FromVehicle,
                frame: heartbeat(1)
            })
            .unwrap()
        );
        assert!(
            w.write(&Record {
                t_us: t + 10,
                direction: Direction::ToVehicle,
                frame: heartbeat(2)
            })
            .unwrap()
        );
        let signing = MavMessage::SETUP_SIGNING(dialect::SETUP_SIGNING_DATA::default());
        assert!(
            !w.write(&Record {
                t_us: t,
                direction: Direction::ToVehicle,
                frame: Frame::encode_v2(
                    vtol_link::SystemId(255),
                    vtol_link::ComponentId(0),
                    3,
                    &signing
                )
            })
            .unwrap()
        );
        w.flush().unwrap();
        let recs: Vec<_> = TlogReader::open(&path).unwrap().collect();
        assert_eq!(recs.len(), 2);
        assert_eq!(recs[0].0, t & !3);
        assert_eq!(recs[1].0 & 3, 3);
        assert_eq!(recs[1].1.seq(), 2);
    }

    #[test]
    fn torn_tail_and_garbage_are_survived() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("b.tlog");
        let mut w = TlogWriter::create(&path).unwrap();
        for seq in 0..3 {
            w.write(&Record {
                t_us: 8,
                direction: Direction::FromVehicle,
                frame: heartbeat(seq),
            })
            .unwrap();
        }
        w.flush().unwrap();
        let mut data = std::fs::read(&path).unwrap();
        let record_len = data.len() / 3;
        data.truncate(data.len() - 5);
        let mut r = TlogReader::from_bytes(data);
        assert_eq!(r.by_ref().count(), 2);
        assert_eq!(r.truncated_tail_bytes, record_len - 5);
        assert_eq!(r.skipped_bytes, 0);
    }

    fn records_with_garbage(garbage: &[Vec<u8>]) -> (Vec<u8>, Vec<Vec<u8>>) {
        let mut data = Vec::new();
        let mut frames = Vec::new();
        for (i, g) in garbage.iter().enumerate() {
            data.extend_from_slice(g);
            let f = Frame::encode_v2(
                vtol_link::SystemId(1),
                vtol_link::ComponentId(1),
                i as u8,
                &vtol_link::gcs_heartbeat(),
            );
            // Unix µs, as loggers stamp records (2026-11-22), 1 ms apart.
            data.extend_from_slice(&(1_795_346_880_000_000 + i as u64 * 1000).to_be_bytes());
            data.extend_from_slice(f.as_bytes());
            frames.push(f.as_bytes().to_vec());
        }
        (data, frames)
    }

    #[test]
    fn garbage_that_looks_like_a_frame_of_an_unknown_id_is_skipped() {
        // A stamp, then a v2 header of message id 0xABCDEF (not in the dialect, so no CRC to
        // check) with a short length. With a time far from the log's it is garbage, between
        // records and in step; with a time that fits, in step and with a whole checked record
        // behind it, the same frame is a record.
        let header = [0xFD, 1, 0, 0, 9, 9, 9, 0xEF, 0xCD, 0xAB, 0, 0, 0];
        let mut far = vec![0xFFu8; 8];
        far.extend_from_slice(&header);
        let mut near = 1_795_346_880_003_500u64.to_be_bytes().to_vec();
        near.extend_from_slice(&header);
        let mut after_garbage = vec![0x55];
        after_garbage.extend_from_slice(&far);
        let (data, frames) = records_with_garbage(&[
            vec![],
            vec![0x55, 0x13],
            after_garbage,
            far.clone(),
            near.clone(),
            vec![],
        ]);
        let mut r = TlogReader::from_bytes(data);
        let got: Vec<Vec<u8>> = r.by_ref().map(|(_, f)| f.as_bytes().to_vec()).collect();
        let mut want = frames.clone();
        want.insert(4, near[8..].to_vec());
        assert_eq!(got, want);
        assert_eq!(r.skipped_bytes, 2 + 1 + 21 + 21);
        assert_eq!(r.truncated_tail_bytes, 0);
    }

    #[test]
    fn a_whole_unchecked_frame_stamped_zero_at_the_start_is_garbage() {
        // Found by the property test below: garbage that forms a whole frame of an unknown id
        // (v1, id 52) right before the first record, stamped 0.
        let mut g = vec![0u8; 8];
        g.extend_from_slice(&[254, 12, 0, 0, 0, 52]);
        g.extend_from_slice(&[0; 14]);
        let (data, frames) = records_with_garbage(&[g]);
        let mut r = TlogReader::from_bytes(data);
        let got: Vec<Vec<u8>> = r.by_ref().map(|(_, f)| f.as_bytes().to_vec()).collect();
        assert_eq!(got, frames);
        assert_eq!(r.skipped_bytes, 28);
    }

    #[test]
    fn an_unchecked_header_in_garbage_does_not_swallow_the_record_behind_it() {
        // Found by the property test below: a v2 header of an unknown id (no CRC) whose length
        // reaches over the next record. The record's own CRC-checked frame must win.
        let (data, frames) =
            records_with_garbage(&[vec![0, 0, 0, 0, 0, 0, 0, 0, 253, 52], vec![0; 33]]);
        let mut r = TlogReader::from_bytes(data);
        let got: Vec<Vec<u8>> = r.by_ref().map(|(_, f)| f.as_bytes().to_vec()).collect();
        assert_eq!(got, frames);
        assert_eq!(r.skipped_bytes, 10 + 33);
    }

    proptest::proptest! {
        #[test]
        fn every_record_survives_garbage_between_records(
            garbage in proptest::collection::vec(proptest::collection::vec(proptest::num::u8::ANY, 0..40), 1..30),
        ) {
            let (data, frames) = records_with_garbage(&garbage);
            let total: usize = garbage.iter().map(Vec::len).sum();
            let mut r = TlogReader::new(Box::new(std::io::Cursor::new(data)));
            let got: Vec<Vec<u8>> = r.by_ref().map(|(_, f)| f.as_bytes().to_vec()).collect();
            proptest::prop_assert_eq!(got, frames);
            proptest::prop_assert_eq!(r.skipped_bytes, total);
        }
    }

    #[test]
    fn a_full_disk_is_counted_and_the_writer_keeps_taking_records() {
        let full = Path::new("/dev/full");
        if !full.exists() {
            return;
        }
        let h = TlogHandle::start_at(full, 16).unwrap();
        let deadline = Instant::now() + Duration::from_secs(10);
        // Keep logging until the failed flush shows up in the counters.
        while h.stats.write_errors.load(Ordering::Relaxed) == 0 {
            h.log(Record::now(Direction::FromVehicle, heartbeat(1)));
            assert!(Instant::now() < deadline, "write error never reported");
            std::thread::sleep(Duration::from_millis(5));
        }
        let why = h.stats.failing().expect("the failure is shown");
        assert!(why.contains("space"), "{why}");
        h.log(Record::now(Direction::FromVehicle, heartbeat(2)));
        h.close();
    }

    #[test]
    fn an_existing_log_is_never_overwritten() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("kept.tlog");
        std::fs::write(&path, b"earlier flight").unwrap();
        let err = TlogWriter::create(&path).unwrap_err().to_string();
        assert!(err.contains("kept.tlog"), "{err}");
        assert_eq!(std::fs::read(&path).unwrap(), b"earlier flight");
    }

    #[test]
    fn logs_started_in_the_same_second_get_their_own_files() {
        let dir = tempfile::tempdir().unwrap();
        let t = UNIX_EPOCH + Duration::from_secs(1_795_346_880);
        let (a, mut wa) = create_unique(dir.path(), t).unwrap();
        let (b, mut wb) = create_unique(dir.path(), t).unwrap();
        let (c, _) = create_unique(dir.path(), t).unwrap();
        assert_eq!(a.file_name().unwrap(), "2026-11-22_11-28-00.tlog");
        assert_eq!(b.file_name().unwrap(), "2026-11-22_11-28-00-2.tlog");
        assert_eq!(c.file_name().unwrap(), "2026-11-22_11-28-00-3.tlog");
        // Interleaved writes land in their own files, whole.
        for seq in 0..10 {
            for w in [&mut wa, &mut wb] {
                w.write(&Record {
                    t_us: 8,
                    direction: Direction::FromVehicle,
                    frame: heartbeat(seq),
                })
                .unwrap();
            }
        }
        wa.flush().unwrap();
        wb.flush().unwrap();
        for p in [&a, &b] {
            let seqs: Vec<u8> = TlogReader::open(p).unwrap().map(|r| r.1.seq()).collect();
            assert_eq!(seqs, (0..10).collect::<Vec<_>>());
        }
    }

    #[test]
    fn writer_thread_flushes_within_the_interval() {
        let dir = tempfile::tempdir().unwrap();
        let h = TlogHandle::start(dir.path(), 16).unwrap();
        h.log(Record::now(Direction::FromVehicle, heartbeat(7)));
        // Wait on the file's content (upper bound 5 s), not on a fixed sleep.
        let deadline = Instant::now() + Duration::from_secs(5);
        loop {
            let n = TlogReader::open(&h.path).unwrap().count();
            if n == 1 {
                break;
            }
            assert!(Instant::now() < deadline, "record never reached the file");
            std::thread::yield_now();
        }
        h.close();
    }
}
