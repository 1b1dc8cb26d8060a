//! Waiting between reconnects.

use std::time::Duration;

use super::LinkOptions;
use tokio_util::sync::CancellationToken;

/// Sleeps unless cancelled; false if cancelled.
pub(crate) async fn sleep_or_cancel(d: Duration, cancel: &CancellationToken) -> bool {
    tokio::select! {
        _ = cancel.cancelled() => false,
        _ = tokio::time::sleep(d) => true,
    }
}

/// Capped exponential back-off for reconnects.
#[derive(Debug)]
pub(crate) struct Backoff {
    next: Duration,
    min: Duration,
    max: Duration,
}

impl Backoff {
    pub(crate) fn new(opts: &LinkOptions) -> Self {
        let min = opts.reconnect_min.max(Duration::from_millis(1));
        Backoff {
            next: min,
            min,
            max: opts.reconnect_max.max(min),
        }
    }

    /// The delay to wait now; doubles the following one up to the cap.
    pub(crate) fn next_delay(&mut self) -> Duration {
        let d = self.next;
        self.next = (self.next * 2).min(self.max);
        d
    }

    /// After a connection that lasted, start again from the minimum.
    pub(crate) fn reset(&mut self) {
        self.next = self.min;
    }

    pub(crate) fn max(&self) -> Duration {
        self.max
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn backoff_doubles_to_cap_and_resets() {
        let mut b = Backoff::new(&LinkOptions::default());
        let seq: Vec<_> = (0..7).map(|_| b.next_delay().as_millis()).collect();
        assert_eq!(seq, vec![100, 200, 400, 800, 1600, 2000, 2000]);
        b.reset();
        assert_eq!(b.next_delay().as_millis(), 100);
    }
}
