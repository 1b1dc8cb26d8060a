//! Replay: a tlog as the vehicle of `vtol-gcs run --vehicle replay:FILE[?speed=N]`.
//!
//! The frames the vehicle side sent are written, byte for byte, into the daemon's vehicle link
//! at their recorded times (divided by the speed factor), so every client, script and view sees
//! the flight again. Records sent towards the vehicle are left out: they were the ground side's
//! own traffic. Their direction is the timestamp's link bits in a log that follows that
//! convention (this project's logger, MAVProxy), otherwise their sender's (a ground station's
//! frames), as [`crate::tlog::Directions`] decides.
//! What clients send to the replayed vehicle is read and dropped.
//!
//! The file is read on a blocking thread (plain file I/O) that feeds the async pacer through a
//! bounded channel, so a long log never sits in memory and the runtime never waits on the disk.

use std::path::{Path, PathBuf};
use std::time::Duration;

use tokio::io::{AsyncReadExt, AsyncWriteExt};
use tokio::sync::mpsc;
use tokio::time::Instant;
use tokio_util::sync::CancellationToken;
use vtol_link::Frame;

use crate::tlog::TlogReader;

/// Records read ahead of the pacer.
const READ_AHEAD: usize = 4096;

/// A parsed `replay:FILE[?speed=N]`.
#[derive(Debug, Clone, PartialEq)]
pub struct ReplaySource {
    /// The tlog.
    pub path: PathBuf,
    /// Time factor: 2 plays twice as fast. Finite and positive.
    pub speed: f64,
}

/// A `replay:` URL that cannot be honoured.
#[derive(Debug, thiserror::Error, PartialEq)]
pub enum ReplayUrlError {
    /// No file after `replay:`.
    #[error("replay: needs a file, e.g. replay:flight.tlog?speed=2")]
    NoFile,
    /// A query key other than `speed`.
    #[error("replay: unknown option '{0}' (only speed=N)")]
    UnknownOption(String),
    /// A speed that is not a finite positive number.
    #[error("replay: speed must be a positive number, got '{0}'")]
    BadSpeed(String),
}

impl ReplaySource {
    /// Parses the part after `replay:`.
    ///
    /// # Errors
    /// [`ReplayUrlError`] for an empty file name, an unknown option or a bad speed.
    pub fn parse(rest: &str) -> Result<Self, ReplayUrlError> {
        let (file, query) = rest.split_once('?').unwrap_or((rest, ""));
        if file.is_empty() {
            return Err(ReplayUrlError::NoFile);
        }
        let mut speed = 1.0;
        for item in query.split('&').filter(|s| !s.is_empty()) {
            let (k, v) = item.split_once('=').unwrap_or((item, ""));
            if k != "speed" {
                return Err(ReplayUrlError::UnknownOption(k.to_owned()));
            }
            speed = v
                .parse::<f64>()
                .ok()
                .filter(|s| s.is_finite() && *s > 0.0)
                .ok_or_else(|| ReplayUrlError::BadSpeed(v.to_owned()))?;
        }
        Ok(Self {
            path: PathBuf::from(file),
            speed,
        })
    }

    /// Opens the file now, so a missing or unreadable log stops the daemon at start.
    ///
    /// # Errors
    /// The file cannot be opened.
    pub fn open(&self) -> std::io::Result<TlogReader> {
        TlogReader::open(&self.path)
    }
}

impl std::fmt::Display for ReplaySource {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "replay of {} at {}x", self.path.display(), self.speed)
    }
}

/// Plays `reader` into `stream` (the vehicle end of the daemon's in-memory vehicle link) until
/// the log ends or `cancel` fires. Frames towards the vehicle are read from `stream` and dropped.
pub async fn run<S>(
    reader: TlogReader,
    path: &Path,
    speed: f64,
    stream: S,
    cancel: CancellationToken,
) where
    S: tokio::io::AsyncRead + tokio::io::AsyncWrite + Send + 'static,
{
    let (mut rd, mut wr) = tokio::io::split(stream);
    let drain_cancel = cancel.clone();
    let drain = tokio::spawn(async move {
        let mut sink = vec![0u8; 4096];
        loop {
            tokio::select! {
                () = drain_cancel.cancelled() => return,
                n = rd.read(&mut sink) => if matches!(n, Ok(0) | Err(_)) { return },
            }
        }
    });
    let (tx, mut rx) = mpsc::channel::<(u64, Frame)>(READ_AHEAD);
    let feeder_cancel = cancel.clone();
    let detect_path = path.to_owned();
    let feeder = tokio::task::spawn_blocking(move || {
        let mut reader = reader;
        let mut left_out = 0u64;
        let mut directions = TlogReader::open(&detect_path).map_or(
            crate::tlog::Directions::with(crate::tlog::Convention::LinkBits),
            crate::tlog::Directions::detect,
        );
        for (stamp, frame) in reader.by_ref() {
            if feeder_cancel.is_cancelled() {
                break;
            }
            if directions.to_vehicle(stamp, &frame) {
                left_out += 1;
                continue;
            }
            if tx.blocking_send((stamp, frame)).is_err() {
                break;
            }
        }
        (reader, left_out)
    });
    let mut origin: Option<(u64, Instant)> = None;
    let mut sent = 0u64;
    loop {
        let next = tokio::select! {
            () = cancel.cancelled() => break,
            r = rx.recv() => r,
        };
        let Some((stamp, frame)) = next else { break };
        let (stamp0, t0) = *origin.get_or_insert((stamp, Instant::now()));
        // A timestamp before the first one (a clock step in the recording) plays at once.
        let offset_us = stamp.saturating_sub(stamp0) as f64 / speed;
        let due = t0 + Duration::from_secs_f64(offset_us * 1e-6);
        tokio::select! {
            () = cancel.cancelled() => break,
            () = tokio::time::sleep_until(due) => {}
        }
        if wr.write_all(frame.as_bytes()).await.is_err() {
            break;
        }
        sent += 1;
    }
    drop(rx);
    if let Ok((reader, left_out)) = feeder.await {
        tracing::info!(
            "replay of {} done: {sent} frames sent, {left_out} towards-the-vehicle records left out, {} bytes skipped, {} bytes of a torn tail",
            path.display(),
            reader.skipped_bytes,
            reader.truncated_tail_bytes
        );
    }
    // The daemon keeps running on a silent vehicle until it is stopped, like a vehicle that went
    // quiet; the link stays open so clients see the same daemon.
    cancel.cancelled().await;
    drain.abort();
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn urls_parse_and_bad_ones_are_refused() {
        let r = ReplaySource::parse("a.tlog?speed=2.5").unwrap();
        assert_eq!(r.path, PathBuf::from("a.tlog"));
        assert!((r.speed - 2.5).abs() < 1e-12);
        assert!((ReplaySource::parse("b.tlog").unwrap().speed - 1.0).abs() < 1e-12);
        assert_eq!(ReplaySource::parse(""), Err(ReplayUrlError::NoFile));
        assert_eq!(
            ReplaySource::parse("a.tlog?speed=0"),
            Err(ReplayUrlError::BadSpeed("0".into()))
        );
        assert_eq!(
            ReplaySource::parse("a.tlog?speed=nan"),
            Err(ReplayUrlError::BadSpeed("nan".into()))
        );
        assert_eq!(
            ReplaySource::parse("a.tlog?loop=1"),
            Err(ReplayUrlError::UnknownOption("loop".into()))
        );
    }
}
