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

mod direction;
mod naming;
mod reader;
#[cfg(test)]
mod tests;
mod writer;

use std::io;
use std::path::PathBuf;
use std::time::{Duration, SystemTime, UNIX_EPOCH};

use vtol_link::Frame;
pub use vtol_link::tlog::Direction;
use vtol_link::tlog::encode_record;

pub use direction::{Convention, DETECT_RECORDS, Directions};
pub use naming::log_file_name;
use naming::{create_unique, is_regular_file};
pub use reader::TlogReader;
pub use writer::{TlogHandle, TlogStats, TlogWriter};

/// How long a record may sit in the buffer before it reaches the file.
pub const FLUSH_INTERVAL: Duration = Duration::from_millis(100);
/// How long the writer thread lets records gather before it writes them: half the bound, so
/// the write itself has the other half.
pub const WRITE_DELAY: Duration = Duration::from_millis(50);
/// Good batch writes in a row (about a second of traffic) that end a failure streak.
const RECOVERED_AFTER_WRITES: u32 = 20;

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
    /// Appends the record as it goes into the file (stamp, then the frame); false, and nothing
    /// appended, for SETUP_SIGNING.
    fn encode_into(&self, out: &mut Vec<u8>) -> bool {
        encode_record(out, self.t_us, self.direction, &self.frame)
    }
}

/// µs since the Unix epoch.
#[must_use]
pub fn unix_time_us() -> u64 {
    SystemTime::now()
        .duration_since(UNIX_EPOCH)
        .map_or(0, |d| u64::try_from(d.as_micros()).unwrap_or(u64::MAX))
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
