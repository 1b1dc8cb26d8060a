//! The log's writer: producers encode records into a shared buffer, a thread writes it out.

use super::{
    RECOVERED_AFTER_WRITES, Record, TlogError, WRITE_DELAY, create_unique, is_regular_file,
};
use std::fs::{File, OpenOptions};
use std::io::{self, BufWriter, Seek, Write};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Arc, Mutex, MutexGuard, PoisonError};
use std::thread::JoinHandle;
use std::time::{Instant, SystemTime};
use vtol_link::tlog::MAX_RECORD_LEN;

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

/// Synchronous writer of tlog records (used by the writer thread, and directly by tools).
#[derive(Debug)]
pub struct TlogWriter {
    out: BufWriter<File>,
    /// The record being written, encoded whole.
    record: Vec<u8>,
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
            record: Vec::with_capacity(MAX_RECORD_LEN),
        })
    }

    /// Appends one record. Returns false if the record was withheld (SETUP_SIGNING).
    ///
    /// # Errors
    /// A write error from the file.
    pub fn write(&mut self, record: &Record) -> io::Result<bool> {
        // One contiguous record, so the buffer never holds half of one when it is written out.
        self.record.clear();
        if !record.encode_into(&mut self.record) {
            return Ok(false);
        }
        self.out.write_all(&self.record)?;
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
pub(super) struct Pending {
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
pub(super) struct Shared {
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
// Long: the writer thread's one loop (wait, take a batch, write it or cut a failed one back,
// report); its state (the failure streak, the last good length) lives across all of it.
pub(super) fn writer_loop(writer: TlogWriter, shared: &Shared, stats: &TlogStats) {
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
                // Why first, then the count: whoever sees records lost sees why.
                if !reported_error {
                    tracing::error!(
                        "tlog write failed, records are lost until it succeeds again (routing continues): {e}"
                    );
                    stats.set_failing(Some(e.to_string()));
                    reported_error = true;
                }
                stats.write_errors.fetch_add(records, Ordering::Release);
                lost_in_streak += records;
                ok_in_row = 0;
                // Part of the batch may have reached the file: cut it off, so the file holds
                // whole records only and the next batch follows the last whole one. (A device
                // such as /dev/full has no length to cut: nothing to do there.)
                if out.set_len(good_len).is_ok() {
                    let _ = out.seek(io::SeekFrom::Start(good_len));
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
