//! Telemetry log (`.tlog`) in the standard format pymavlink, MAVProxy and mavlogdump read:
//! records of an 8-byte big-endian timestamp (µs since the Unix epoch, low 2 bits = link
//! number) followed by one complete MAVLink frame, no file header, no padding.
//!
//! The writer runs on its own thread, fed through a bounded queue, so a slow disk never stalls
//! routing; it flushes at most 100 ms after a record arrives, so a `kill -9` loses at most the
//! last 100 ms and never leaves a torn record behind (each record is written whole into the
//! buffer, and the buffer is only ever written out whole). SETUP_SIGNING is never logged: it
//! carries the signing key.

use std::fs::{File, OpenOptions};
use std::io::{self, BufWriter, Read, Write};
use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::mpsc::{Receiver, RecvTimeoutError, SyncSender, TrySendError, sync_channel};
use std::thread::JoinHandle;
use std::time::{Duration, Instant, SystemTime, UNIX_EPOCH};

use bytes::Bytes;
use vtol_link::Frame;

/// SETUP_SIGNING: never written to a log.
const SETUP_SIGNING_ID: u32 = 256;
/// How long a record may sit in the buffer before it reaches the file.
pub const FLUSH_INTERVAL: Duration = Duration::from_millis(100);

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
    /// Records dropped because the writer's queue was full.
    pub dropped_queue_full: AtomicU64,
    /// Records lost to write errors (full disk, I/O error).
    pub write_errors: AtomicU64,
    /// SETUP_SIGNING frames withheld.
    pub withheld_signing: AtomicU64,
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
        let stamp = (record.t_us & !3) | record.direction.link_bits();
        // One contiguous record, so the buffer never holds half of one when it is written out.
        let frame = record.frame.as_bytes();
        let mut buf = [0u8; 8 + 300];
        buf[..8].copy_from_slice(&stamp.to_be_bytes());
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
}

/// Handle to a running writer thread.
#[derive(Debug)]
pub struct TlogHandle {
    tx: SyncSender<Record>,
    /// Where the log is written.
    pub path: PathBuf,
    /// Live counters.
    pub stats: Arc<TlogStats>,
    thread: Option<JoinHandle<()>>,
}

impl TlogHandle {
    /// Creates a new `dir/<start time>.tlog` and starts the writer thread with a queue of
    /// `queue_len` records. A name already taken (a restart within the same second, or another
    /// daemon logging to the same directory) gets a `-2`, `-3` … suffix: no log is ever
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
        let (tx, rx) = sync_channel(queue_len);
        let stats = Arc::new(TlogStats::default());
        let thread_stats = Arc::clone(&stats);
        let thread = std::thread::Builder::new()
            .name("tlog-writer".into())
            .spawn(move || writer_loop(writer, &rx, &thread_stats))
            .map_err(|source| TlogError::Create {
                path: path.clone(),
                source,
            })?;
        Ok(Self {
            tx,
            path,
            stats,
            thread: Some(thread),
        })
    }

    /// Queues a record without blocking; a full queue drops it and counts the drop.
    pub fn log(&self, record: Record) {
        match self.tx.try_send(record) {
            Ok(()) => {}
            Err(TrySendError::Full(_)) => {
                self.stats
                    .dropped_queue_full
                    .fetch_add(1, Ordering::Relaxed);
            }
            Err(TrySendError::Disconnected(_)) => {
                self.stats.write_errors.fetch_add(1, Ordering::Relaxed);
            }
        }
    }

    /// Closes the queue, waits for the writer to write and flush everything queued.
    pub fn close(mut self) {
        self.finish();
    }

    fn finish(&mut self) {
        // Dropping the only sender ends the writer loop after it drains the queue.
        let (dead_tx, _) = sync_channel(1);
        drop(std::mem::replace(&mut self.tx, dead_tx));
        if let Some(t) = self.thread.take() {
            let _ = t.join();
        }
    }
}

impl Drop for TlogHandle {
    fn drop(&mut self) {
        self.finish();
    }
}

fn writer_loop(mut writer: TlogWriter, rx: &Receiver<Record>, stats: &TlogStats) {
    let mut flush_by: Option<Instant> = None;
    let mut reported_error = false;
    loop {
        let received = match flush_by {
            Some(deadline) => rx.recv_timeout(deadline.saturating_duration_since(Instant::now())),
            None => rx.recv().map_err(|_| RecvTimeoutError::Disconnected),
        };
        match received {
            Ok(record) => {
                let len = record.frame.len() as u64 + 8;
                match writer.write(&record) {
                    Ok(true) => {
                        stats.records.fetch_add(1, Ordering::Relaxed);
                        stats.bytes.fetch_add(len, Ordering::Relaxed);
                        flush_by.get_or_insert_with(|| Instant::now() + FLUSH_INTERVAL);
                    }
                    Ok(false) => {
                        stats.withheld_signing.fetch_add(1, Ordering::Relaxed);
                    }
                    Err(e) => {
                        stats.write_errors.fetch_add(1, Ordering::Relaxed);
                        if !reported_error {
                            tracing::error!("tlog write failed (routing continues): {e}");
                            reported_error = true;
                        }
                    }
                }
            }
            Err(RecvTimeoutError::Timeout) => {}
            Err(RecvTimeoutError::Disconnected) => {
                if let Err(e) = writer.flush() {
                    tracing::error!("tlog final flush failed: {e}");
                }
                return;
            }
        }
        if flush_by.is_some_and(|d| Instant::now() >= d) {
            flush_by = None;
            if let Err(e) = writer.flush() {
                stats.write_errors.fetch_add(1, Ordering::Relaxed);
                if !reported_error {
                    tracing::error!("tlog flush failed (routing continues): {e}");
                    reported_error = true;
                }
            } else {
                reported_error = false;
            }
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

/// Reads the records of a tlog. A torn record at the end (a crash mid-write) ends the
/// iteration; a record whose frame does not check out is skipped by resynchronising on the
/// next timestamp-plus-frame that does, and counted.
#[derive(Debug)]
pub struct TlogReader {
    data: Vec<u8>,
    pos: usize,
    /// Bytes skipped while resynchronising.
    pub skipped_bytes: usize,
}

impl TlogReader {
    /// Reads a whole file into memory.
    ///
    /// # Errors
    /// The file cannot be read.
    pub fn open(path: &Path) -> io::Result<Self> {
        let mut data = Vec::new();
        File::open(path)?.read_to_end(&mut data)?;
        Ok(Self::from_bytes(data))
    }

    /// Reads records from bytes.
    #[must_use]
    pub fn from_bytes(data: Vec<u8>) -> Self {
        Self {
            data,
            pos: 0,
            skipped_bytes: 0,
        }
    }
}

impl Iterator for TlogReader {
    type Item = (u64, Frame);

    fn next(&mut self) -> Option<Self::Item> {
        while self.pos + 8 < self.data.len() {
            let stamp_bytes: [u8; 8] = self.data[self.pos..self.pos + 8].try_into().ok()?;
            let start = self.pos + 8;
            if let Some(len) = vtol_link::frame_len_from_prefix(&self.data[start..]) {
                if start + len <= self.data.len() {
                    let bytes = Bytes::copy_from_slice(&self.data[start..start + len]);
                    if let Ok(frame) = Frame::from_bytes(bytes) {
                        self.pos = start + len;
                        return Some((u64::from_be_bytes(stamp_bytes), frame));
                    }
                } else {
                    // A torn last record: nothing more to read.
                    return None;
                }
            }
            self.pos += 1;
            self.skipped_bytes += 1;
        }
        None
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use vtol_link::dialect::{self, MavMessage};

    fn heartbeat(seq: u8) -> Frame {
        Frame::encode_v2(255, 190, seq, &vtol_link::gcs_heartbeat())
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
                frame: Frame::encode_v2(255, 0, 3, &signing)
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
        data.truncate(data.len() - 5);
        let mut r = TlogReader::from_bytes(data);
        assert_eq!(r.by_ref().count(), 2);
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
