//! Signing timestamps: 10 µs units since 2015, never going back.

use super::{MAX_TIMESTAMP, SIGNING_EPOCH_UNIX_S, SignError};
use std::time::{Duration, SystemTime, UNIX_EPOCH};

/// The signing timestamp of a wall-clock time: 10 µs units since 2015-01-01 00:00 UTC, 0 for
/// earlier times, [`MAX_TIMESTAMP`] past the 48-bit range (year 2104).
#[must_use]
pub fn timestamp_at(now: SystemTime) -> u64 {
    let since_unix = now.duration_since(UNIX_EPOCH).unwrap_or(Duration::ZERO);
    let Some(since_epoch) = since_unix.checked_sub(Duration::from_secs(SIGNING_EPOCH_UNIX_S))
    else {
        return 0;
    };
    let units = since_epoch.as_micros() / 10;
    u64::try_from(units).map_or(MAX_TIMESTAMP, |u| u.min(MAX_TIMESTAMP))
}

/// The timestamps we sign with: never back, +1 at least per frame, and never behind the wall
/// clock (see the module docs).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct TimestampSource {
    last: u64,
}

impl TimestampSource {
    /// A source whose next timestamp is above `initial` (a persisted value, or 0).
    #[must_use]
    pub fn new(initial: u64) -> TimestampSource {
        TimestampSource {
            last: initial.min(MAX_TIMESTAMP),
        }
    }

    /// The last timestamp used or accepted (what to persist).
    #[must_use]
    pub fn last(&self) -> u64 {
        self.last
    }

    /// Our timestamp at `now` without using one: `max(last, wall clock)`.
    #[must_use]
    pub fn current(&self, now: SystemTime) -> u64 {
        self.last.max(timestamp_at(now))
    }

    /// The timestamp for the next signed frame: `max(last + 1, wall clock)`.
    pub fn next(&mut self, now: SystemTime) -> Result<u64, SignError> {
        let after = self
            .last
            .checked_add(1)
            .filter(|&t| t <= MAX_TIMESTAMP)
            .ok_or(SignError::TimestampExhausted)?;
        self.last = after.max(timestamp_at(now));
        Ok(self.last)
    }

    /// Raises the source to a timestamp accepted from a peer (our next one will be above it).
    pub fn observe(&mut self, timestamp: u64) {
        self.last = self.last.max(timestamp.min(MAX_TIMESTAMP));
    }
}
