//! Simulation clocks: how far sim time may run at a given wall-clock instant.
//!
//! The twin steps at 1 kHz of sim time. The serve loop wakes every [`BATCH`] of wall time, asks
//! the clock for the sim time that is due and runs the steps up to it. The due time is computed
//! from the start instant (`elapsed × speed`), never accumulated, so rounding cannot make sim time
//! drift from wall time. After a stall longer than [`MAX_CATCH_UP`] the clock gives up the lost
//! time instead of running seconds of physics in one burst (a frozen laptop should not replay).
//!
//! Wall time is tokio's clock ([`tokio::time::Instant`]), so a test that pauses tokio's time and
//! advances it runs the twin without waiting. Under [`ClockMode::Lockstep`] wall time does not
//! move the simulation at all: sim time advances only when the harness asks
//! ([`crate::shell::harness`]).
//!
//! The clock also gives the *stream time* ([`SimClock::stream_us`]): the time telemetry rates are
//! counted in. It is wall time in the real-time and fast modes, so a twin at 1 000× still sends
//! ATTITUDE 20 times a wall second, and sim time under lockstep, so that the telemetry of a
//! lockstep run is the same on every run.

use std::time::Duration;

use tokio::time::Instant;

/// Wall-time period of the serve loop.
pub const BATCH: Duration = Duration::from_millis(5);

/// Longest stretch of sim time run in one batch before the clock drops the backlog.
pub const MAX_CATCH_UP: Duration = Duration::from_millis(500);

/// Sim time a batch advances when running as fast as possible, µs.
pub const FAST_BATCH_US: u64 = 10_000;

/// How sim time relates to wall time.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum ClockMode {
    /// Sim time = wall time × `speed` (1.0 = real time).
    Scaled {
        /// Speed-up factor, > 0.
        speed: f64,
    },
    /// As fast as the CPU allows; sim time advances [`FAST_BATCH_US`] per batch.
    AsFastAsPossible,
    /// Sim time stands still until the harness advances it (`firmware-sim serve --lockstep`).
    Lockstep,
}

impl ClockMode {
    /// Real time.
    pub const REAL_TIME: Self = Self::Scaled { speed: 1.0 };
}

/// A sim-time source for the serve loop.
#[derive(Debug, Clone)]
pub struct SimClock {
    mode: ClockMode,
    /// When the clock started (stream time counts from here).
    start: Instant,
    origin: Instant,
    /// Sim time at `origin`, µs (moves forward when a backlog is dropped).
    origin_sim_us: u64,
    last_sim_us: u64,
}

impl SimClock {
    /// A clock starting at sim time 0 now.
    #[must_use]
    pub fn new(mode: ClockMode, now: Instant) -> Self {
        Self {
            mode,
            start: now,
            origin: now,
            origin_sim_us: 0,
            last_sim_us: 0,
        }
    }

    /// The clock's mode.
    #[must_use]
    pub fn mode(&self) -> ClockMode {
        self.mode
    }

    /// The sim time (µs) that is due at wall instant `now`. Monotonic. Under lockstep this is
    /// the time the harness last advanced to ([`SimClock::advance_to`]).
    pub fn due_sim_us(&mut self, now: Instant) -> u64 {
        let due = match self.mode {
            ClockMode::Lockstep => self.last_sim_us,
            ClockMode::AsFastAsPossible => self.last_sim_us + FAST_BATCH_US,
            ClockMode::Scaled { speed } => {
                let elapsed_us = now.saturating_duration_since(self.origin).as_secs_f64() * 1e6;
                let due = self.origin_sim_us + (elapsed_us * speed) as u64;
                let max_step = (MAX_CATCH_UP.as_secs_f64() * 1e6 * speed.max(1.0)) as u64;
                if due > self.last_sim_us + max_step {
                    // Drop the backlog: re-anchor so that from here on wall and sim time agree.
                    self.origin = now;
                    self.origin_sim_us = self.last_sim_us + max_step;
                    self.origin_sim_us
                } else {
                    due
                }
            }
        };
        self.last_sim_us = self.last_sim_us.max(due);
        self.last_sim_us
    }

    /// Lockstep: the harness moves sim time forward to `sim_us` (never back).
    pub fn advance_to(&mut self, sim_us: u64) {
        self.last_sim_us = self.last_sim_us.max(sim_us);
    }

    /// The time stream rates count in at wall instant `now`, µs: wall time since the clock
    /// started, or sim time under lockstep.
    #[must_use]
    pub fn stream_us(&self, now: Instant) -> u64 {
        match self.mode {
            ClockMode::Lockstep => self.last_sim_us,
            _ => now.saturating_duration_since(self.start).as_micros() as u64,
        }
    }

    /// Wall time to wait before the next batch.
    #[must_use]
    pub fn pause(&self) -> Option<Duration> {
        match self.mode {
            ClockMode::AsFastAsPossible => None,
            // Lockstep still wakes: parameter lists drain at the sim time standing.
            ClockMode::Scaled { .. } | ClockMode::Lockstep => Some(BATCH),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn scaled_clock_does_not_drift() {
        let t0 = Instant::now();
        let mut c = SimClock::new(ClockMode::Scaled { speed: 2.0 }, t0);
        let mut last = 0;
        for k in 1..=1000u64 {
            let now = t0 + Duration::from_micros(k * 3_333);
            let due = c.due_sim_us(now);
            assert!(due >= last);
            last = due;
        }
        // 3.333 s of wall time at ×2 is 6.666 s of sim time, to the microsecond.
        assert_eq!(last, 6_666_000);
    }

    #[test]
    fn stall_drops_backlog() {
        let t0 = Instant::now();
        let mut c = SimClock::new(ClockMode::REAL_TIME, t0);
        assert_eq!(c.due_sim_us(t0 + Duration::from_millis(10)), 10_000);
        let after_stall = c.due_sim_us(t0 + Duration::from_secs(10));
        assert_eq!(after_stall, 10_000 + 500_000);
        assert_eq!(c.due_sim_us(t0 + Duration::from_millis(10_005)), 515_000);
    }

    #[test]
    fn lockstep_stands_still_until_advanced() {
        let t0 = Instant::now();
        let mut c = SimClock::new(ClockMode::Lockstep, t0);
        assert_eq!(c.due_sim_us(t0 + Duration::from_secs(10)), 0);
        c.advance_to(60_000_000);
        assert_eq!(c.due_sim_us(t0 + Duration::from_secs(11)), 60_000_000);
        c.advance_to(1_000);
        assert_eq!(c.due_sim_us(t0), 60_000_000, "never back");
        // Streams count sim time under lockstep, wall time otherwise.
        assert_eq!(c.stream_us(t0 + Duration::from_secs(99)), 60_000_000);
        let w = SimClock::new(ClockMode::AsFastAsPossible, t0);
        assert_eq!(w.stream_us(t0 + Duration::from_millis(250)), 250_000);
    }

    #[test]
    fn fast_clock_advances_per_batch() {
        let t0 = Instant::now();
        let mut c = SimClock::new(ClockMode::AsFastAsPossible, t0);
        assert_eq!(c.due_sim_us(t0), FAST_BATCH_US);
        assert_eq!(c.due_sim_us(t0), 2 * FAST_BATCH_US);
        assert!(c.pause().is_none());
    }
}
