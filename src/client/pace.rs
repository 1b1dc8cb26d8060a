//! Pacing of the client's own sends by the telemetry radio on its link.
//!
//! A SiK radio tells the ground station how full its transmit buffer is: RADIO_STATUS `txbuf`,
//! percent free, once a second, from the radio attached to the ground (system 51). What the
//! ground sends faster than the air carries waits in that buffer, and what does not fit is lost.
//! So the client, which writes every frame the daemon's own requests send (parameter pulls and
//! pushes, commands, the stream fit's SET_MESSAGE_INTERVAL bursts), paces itself by it:
//!
//! - [`TXBUF_SLOW`] % free or more, or no fresh report: frames go as they come;
//! - under [`TXBUF_SLOW`] %: one frame every [`SLOW_GAP`];
//! - under [`TXBUF_PAUSE`] %: nothing, until a report says the buffer has room again, the
//!   reports stop ([`REPORT_FRESH`]), or [`PAUSE_MAX`] has passed since the pause began (then
//!   one frame every [`SLOW_GAP`]), so that a radio that never recovers stalls nothing.
//!
//! The client's heartbeat is never held back (it is one small frame a second). Frames are held
//! in the client's queue, in order; a request's retries wait there like any frame.

use std::time::{Duration, Instant};

/// `txbuf` (percent free) under which frames go one every [`SLOW_GAP`].
pub const TXBUF_SLOW: u8 = 50;
/// `txbuf` under which frames wait for the buffer to drain.
pub const TXBUF_PAUSE: u8 = 20;
/// The gap between two frames while the radio's buffer is more than half full.
pub const SLOW_GAP: Duration = Duration::from_millis(50);
/// The longest pause: after it, frames go one every [`SLOW_GAP`] whatever the radio says.
pub const PAUSE_MAX: Duration = Duration::from_secs(2);
/// A report older than this says nothing about the radio now.
pub const REPORT_FRESH: Duration = Duration::from_secs(3);

/// When the client's next frame may go, from the radio's reports and the client's sends.
#[derive(Debug, Default, Clone)]
pub struct Pacer {
    /// The last report: `txbuf`, and when it came.
    report: Option<(u8, Instant)>,
    /// When the reports began saying the buffer is nearly full, while they still do.
    paused_since: Option<Instant>,
    /// When the last paced frame went.
    last_send: Option<Instant>,
}

impl Pacer {
    /// The radio reported `txbuf` percent of its transmit buffer free at `now`.
    pub fn on_radio_status(&mut self, txbuf: u8, now: Instant) {
        self.report = Some((txbuf, now));
        if txbuf < TXBUF_PAUSE {
            self.paused_since.get_or_insert(now);
        } else {
            self.paused_since = None;
        }
    }

    /// When the next frame may go; `None`: now.
    #[must_use]
    pub fn next_send(&self, now: Instant) -> Option<Instant> {
        let (txbuf, at) = self.report?;
        if txbuf >= TXBUF_SLOW || now >= at + REPORT_FRESH {
            return None;
        }
        let gap = self.last_send.map(|t| t + SLOW_GAP);
        let pause = self
            .paused_since
            .map(|p| (p + PAUSE_MAX).min(at + REPORT_FRESH));
        gap.max(pause).filter(|t| *t > now)
    }

    /// A frame went at `now`.
    pub fn sent(&mut self, now: Instant) {
        self.last_send = Some(now);
    }
}

#[cfg(test)]
#[path = "pace_tests.rs"]
mod tests;
