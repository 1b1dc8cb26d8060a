//! Counts over a recent window of time, in fixed buckets, so rates and loss describe the last
//! seconds rather than the whole life of a link: a loss burst from before a vehicle restart
//! ages out, and a silent link reads 0 Hz instead of its last rate.

use std::time::{Duration, Instant};

/// Width of one bucket.
pub const BUCKET: Duration = Duration::from_millis(BUCKET_MS);
const BUCKET_MS: u64 = 250;
/// Buckets kept: 10 s of history.
const BUCKETS: usize = 40;
/// Rates are taken over this many newest buckets (2 s): long enough to be steady at 1 Hz
/// heartbeats, short enough that a lost link reads 0 within 2 s.
const RATE_BUCKETS: u64 = 8;

/// Received and lost counts over the last 10 s, bucketed by 250 ms from an epoch.
#[derive(Debug, Clone, PartialEq)]
pub struct Window {
    epoch: Instant,
    /// Bucket number (since `epoch`) of `counts[newest % BUCKETS]`.
    newest: u64,
    /// When the first count arrived, so a young window is not diluted by empty history.
    first: Option<u64>,
    counts: [(u32, u32); BUCKETS],
}

/// A time with its bucket number from an epoch, worked out once for every window counting
/// from that epoch: the tracker counts each frame in two or three windows at the same time.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Stamp {
    epoch: Instant,
    at: Instant,
    /// `at - epoch` (zero for a time before the epoch).
    since: Duration,
    bucket: u64,
}

impl Stamp {
    /// `at`, for windows counting from `epoch`.
    #[must_use]
    pub fn new(epoch: Instant, at: Instant) -> Self {
        let since = at.saturating_duration_since(epoch);
        Self {
            epoch,
            at,
            since,
            bucket: bucket_since(since),
        }
    }

    /// The time.
    #[must_use]
    pub fn at(&self) -> Instant {
        self.at
    }

    /// The epoch the stamp counts from.
    #[must_use]
    pub fn epoch(&self) -> Instant {
        self.epoch
    }

    /// Seconds from the epoch to the time (0 for a time before the epoch).
    #[must_use]
    pub fn since_epoch_s(&self) -> f64 {
        self.since.as_secs_f64()
    }
}

fn bucket_of(epoch: Instant, t: Instant) -> u64 {
    bucket_since(t.saturating_duration_since(epoch))
}

fn bucket_since(d: Duration) -> u64 {
    // In whole milliseconds and u64: the tracker calls this for every frame, and a u128
    // division of nanoseconds is a library call.
    (d.as_secs() * 1000 + u64::from(d.subsec_millis())) / BUCKET_MS
}

impl Window {
    /// An empty window whose buckets count from `epoch`.
    #[must_use]
    pub fn new(epoch: Instant) -> Self {
        Self {
            epoch,
            newest: 0,
            first: None,
            counts: [(0, 0); BUCKETS],
        }
    }

    fn bucket_of(&self, t: Instant) -> u64 {
        bucket_of(self.epoch, t)
    }

    /// Moves the window so that `bucket` is the newest, clearing what falls out.
    fn advance(&mut self, bucket: u64) {
        if bucket <= self.newest {
            return;
        }
        let steps = (bucket - self.newest).min(BUCKETS as u64);
        for k in 1..=steps {
            self.counts[((self.newest + k) % BUCKETS as u64) as usize] = (0, 0);
        }
        self.newest = bucket;
    }

    /// Counts `received` frames and `lost` missing ones at `t`.
    pub fn add(&mut self, t: Instant, received: u32, lost: u32) {
        self.add_stamped(&Stamp::new(self.epoch, t), received, lost);
    }

    /// [`Window::add`] at a time whose bucket is already worked out.
    pub fn add_stamped(&mut self, t: &Stamp, received: u32, lost: u32) {
        let b = if t.epoch == self.epoch {
            t.bucket
        } else {
            self.bucket_of(t.at)
        };
        self.advance(b);
        // A time older than the window (clock skew in a test) counts in the newest bucket.
        let slot = &mut self.counts[(self.newest % BUCKETS as u64) as usize];
        slot.0 = slot.0.saturating_add(received);
        slot.1 = slot.1.saturating_add(lost);
        self.first.get_or_insert(b);
    }

    /// Takes back one lost frame (a late frame arrived): from the newest bucket that counts one.
    pub fn take_back_lost(&mut self) {
        for k in 0..BUCKETS as u64 {
            let Some(b) = self.newest.checked_sub(k) else {
                break;
            };
            let slot = &mut self.counts[(b % BUCKETS as u64) as usize];
            if slot.1 > 0 {
                slot.1 -= 1;
                return;
            }
        }
    }

    /// Sums over the newest `n` buckets as seen at `now`, and the span they cover in seconds.
    fn sum(&self, now: Instant, n: u64) -> (u64, u64, f64) {
        let now_b = self.bucket_of(now).max(self.newest);
        let Some(first) = self.first else {
            return (0, 0, 0.0);
        };
        let oldest = now_b.saturating_sub(n - 1).max(first);
        let (mut rx, mut lost) = (0u64, 0u64);
        for b in oldest..=now_b {
            if b + (BUCKETS as u64) <= self.newest || b > self.newest {
                continue;
            }
            let (r, l) = self.counts[(b % BUCKETS as u64) as usize];
            rx += u64::from(r);
            lost += u64::from(l);
        }
        // The current bucket is partly elapsed: count the span up to `now`.
        let span = now.saturating_duration_since(self.epoch).as_secs_f64()
            - oldest as f64 * BUCKET.as_secs_f64();
        (rx, lost, span.max(BUCKET.as_secs_f64()))
    }

    /// Frames per second over the last 2 s; 0 when nothing arrived in them.
    #[must_use]
    pub fn rate_hz(&self, now: Instant) -> f64 {
        let (rx, _, span) = self.sum(now, RATE_BUCKETS);
        if rx == 0 { 0.0 } else { rx as f64 / span }
    }

    /// Lost frames in percent of those sent over the last 2 s (the rate's span): what a change
    /// of the traffic did, seconds after it; 0 when nothing arrived.
    #[must_use]
    pub fn recent_loss_pct(&self, now: Instant) -> f64 {
        let (rx, lost, _) = self.sum(now, RATE_BUCKETS);
        if rx + lost == 0 {
            0.0
        } else {
            100.0 * lost as f64 / (rx + lost) as f64
        }
    }

    /// Lost frames in percent of those sent over the last 10 s; 0 when nothing arrived.
    #[must_use]
    pub fn loss_pct(&self, now: Instant) -> f64 {
        let (rx, lost, _) = self.sum(now, BUCKETS as u64);
        if rx + lost == 0 {
            0.0
        } else {
            100.0 * lost as f64 / (rx + lost) as f64
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn steady_rate_then_silence_reads_zero() {
        let t0 = Instant::now();
        let mut w = Window::new(t0);
        // 50 Hz for 4 s.
        for i in 0..200u64 {
            w.add(t0 + Duration::from_millis(i * 20), 1, 0);
        }
        let now = t0 + Duration::from_millis(4000);
        let r = w.rate_hz(now);
        assert!((r - 50.0).abs() < 3.0, "rate {r}");
        assert!(w.rate_hz(now + Duration::from_secs(3)) == 0.0);
    }

    #[test]
    fn loss_ages_out_after_ten_seconds() {
        let t0 = Instant::now();
        let mut w = Window::new(t0);
        w.add(t0, 10, 10);
        assert!((w.loss_pct(t0) - 50.0).abs() < 1e-9);
        for i in 1..=120u64 {
            w.add(t0 + Duration::from_millis(i * 100), 1, 0);
        }
        let now = t0 + Duration::from_millis(12_000);
        assert_eq!(w.loss_pct(now), 0.0);
        assert!(w.rate_hz(now) > 9.0);
    }

    #[test]
    fn a_stamp_counts_in_its_bucket_whatever_epoch_it_was_made_for() {
        let t0 = Instant::now();
        let at = t0 + Duration::from_millis(1_100);
        let mut own = Window::new(t0);
        own.add_stamped(&Stamp::new(t0, at), 3, 1);
        // A stamp made for another epoch is worked out again from its time.
        let mut foreign = Window::new(t0);
        foreign.add_stamped(&Stamp::new(t0 + Duration::from_millis(600), at), 3, 1);
        let mut plain = Window::new(t0);
        plain.add(at, 3, 1);
        assert_eq!(own, plain);
        assert_eq!(foreign, plain);
        assert_eq!(plain.newest, 4, "1.1 s is bucket 4 of 250 ms");
    }

    #[test]
    fn a_late_frame_takes_back_a_loss_counted_earlier() {
        let t0 = Instant::now();
        let mut w = Window::new(t0);
        w.add(t0, 9, 1);
        w.add(t0 + Duration::from_millis(600), 1, 0);
        w.take_back_lost();
        w.take_back_lost();
        assert_eq!(w.loss_pct(t0 + Duration::from_secs(1)), 0.0);
    }

    #[test]
    fn young_window_is_not_diluted() {
        let t0 = Instant::now();
        let mut w = Window::new(t0);
        let start = t0 + Duration::from_secs(100);
        for i in 0..10u64 {
            w.add(start + Duration::from_millis(i * 100), 1, 0);
        }
        let r = w.rate_hz(start + Duration::from_millis(1000));
        assert!((r - 10.0).abs() < 1.5, "rate {r}");
    }
}
