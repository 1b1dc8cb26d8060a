//! The twin's own telemetry log (`firmware-sim serve --tlog FILE`): every frame it sends and
//! every frame it receives, in the standard tlog layout (an 8-byte big-endian µs timestamp, then
//! the raw frame). The low two bits of a timestamp say the direction, as in the daemon's and
//! MAVProxy's logs: 0 for frames the vehicle sent, 3 for frames it received.
//!
//! Timestamps are Unix time, or sim time under lockstep, so that the log of a lockstep run is
//! the same on every run. The file is only ever created, never overwritten. A thread does the
//! file I/O: the vehicle loop appends records to a buffer and hands whole buffers over, so it
//! never waits on the disk. A write error is reported once and the twin flies on without a log.

use std::io::Write as _;
use std::path::{Path, PathBuf};
use std::sync::mpsc;
use std::thread::JoinHandle;

use vtol_link::tlog::{Direction, encode_record_bytes};

/// A buffer handed to the writer thread once it holds this many bytes (or at a batch's end).
const HAND_OVER_BYTES: usize = 64 * 1024;

/// Why the log could not be opened.
#[derive(Debug, thiserror::Error)]
#[error("cannot create the tlog '{}': {source}", path.display())]
pub struct TlogError {
    /// The file asked for.
    pub path: PathBuf,
    /// The I/O error (an existing file is refused: logs are never overwritten).
    pub source: std::io::Error,
}

/// The writing end of a twin's tlog.
#[derive(Debug)]
pub struct TlogSink {
    buf: Vec<u8>,
    tx: Option<mpsc::Sender<Vec<u8>>>,
    thread: Option<JoinHandle<()>>,
}

impl TlogSink {
    /// Creates `path` (which must not exist) and starts the writer thread.
    ///
    /// # Errors
    /// [`TlogError`] when the file cannot be created.
    pub fn create(path: &Path) -> Result<Self, TlogError> {
        let file = std::fs::OpenOptions::new()
            .write(true)
            .create_new(true)
            .open(path)
            .map_err(|source| TlogError {
                path: path.to_owned(),
                source,
            })?;
        let (tx, rx) = mpsc::channel::<Vec<u8>>();
        let shown = path.display().to_string();
        let thread = std::thread::Builder::new()
            .name("twin-tlog".into())
            .spawn(move || {
                let mut file = std::io::BufWriter::new(file);
                let mut failed = false;
                for chunk in rx {
                    if failed {
                        continue;
                    }
                    if let Err(e) = file.write_all(&chunk).and_then(|()| file.flush()) {
                        tracing::warn!("tlog {shown}: {e}; the twin goes on without it");
                        failed = true;
                    }
                }
            })
            .map_err(|source| TlogError {
                path: path.to_owned(),
                source,
            })?;
        Ok(Self {
            buf: Vec::with_capacity(HAND_OVER_BYTES),
            tx: Some(tx),
            thread: Some(thread),
        })
    }

    /// Records a frame the vehicle sent (`sent`) or received, stamped `t_us`.
    pub fn record(&mut self, t_us: u64, sent: bool, frame: &[u8]) {
        // The vehicle's frames are the ones a ground station logs as from the vehicle.
        let direction = if sent {
            Direction::FromVehicle
        } else {
            Direction::ToVehicle
        };
        encode_record_bytes(&mut self.buf, t_us, direction, frame);
        if self.buf.len() >= HAND_OVER_BYTES {
            self.hand_over();
        }
    }

    /// Hands what is buffered to the writer thread.
    pub fn hand_over(&mut self) {
        if self.buf.is_empty() {
            return;
        }
        let chunk = std::mem::replace(&mut self.buf, Vec::with_capacity(HAND_OVER_BYTES));
        if let Some(tx) = &self.tx {
            // The thread is gone only after a panic; the log is then lost, the twin is not.
            let _ = tx.send(chunk);
        }
    }

    /// Writes everything out and waits for the thread (blocking: call it off the runtime).
    pub fn finish(mut self) {
        self.hand_over();
        self.tx = None;
        if let Some(t) = self.thread.take() {
            let _ = t.join();
        }
    }
}

/// The current Unix time, µs (a log's timestamp outside lockstep).
#[must_use]
pub fn unix_now_us() -> u64 {
    std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map_or(0, |d| d.as_micros() as u64)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn records_carry_the_direction_and_the_file_is_never_overwritten() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("t.tlog");
        let mut sink = TlogSink::create(&path).unwrap();
        sink.record(1_000, true, &[0xFD, 1, 2]);
        sink.record(2_000, false, &[0xFE, 9]);
        sink.finish();
        let bytes = std::fs::read(&path).unwrap();
        let mut want = 1_000u64.to_be_bytes().to_vec();
        want.extend([0xFD, 1, 2]);
        want.extend((2_000u64 | 3).to_be_bytes());
        want.extend([0xFE, 9]);
        assert_eq!(bytes, want);
        let e = TlogSink::create(&path).expect_err("exists");
        assert!(e.to_string().contains("t.tlog"), "{e}");
    }
}
