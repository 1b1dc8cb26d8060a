//! What every protocol state machine of the client shares: the inbound message, the machine
//! trait the async shell drives, and the round-trip estimate that scales every timeout.

use std::time::{Duration, Instant};

use vtol_link::dialect::MavMessage;

/// A decoded message from the link, with its sender.
#[derive(Debug, Clone)]
pub struct Inbound {
    /// Sender system id.
    pub sys: vtol_link::SystemId,
    /// Sender component id.
    pub comp: vtol_link::ComponentId,
    /// The message.
    pub msg: MavMessage,
}

/// A protocol exchange as a pure state machine: frames and time in, frames out, one result.
/// The shell calls `start` once, then `on_message` for every inbound message and `on_time`
/// when `deadline` passes, sending what each returns, until `result` is `Some`.
pub trait Machine {
    /// What the exchange produces.
    type Output;
    /// The first messages to send.
    fn start(&mut self, now: Instant) -> Vec<MavMessage>;
    /// A message arrived.
    fn on_message(&mut self, now: Instant, m: &Inbound) -> Vec<MavMessage>;
    /// The deadline passed.
    fn on_time(&mut self, now: Instant) -> Vec<MavMessage>;
    /// When `on_time` is due next.
    fn deadline(&self) -> Instant;
    /// The result, once finished (taken once).
    fn result(&mut self) -> Option<Self::Output>;
    /// Round trips measured since the last call, from exchanges answered on their first send
    /// only (Karn's rule).
    fn take_rtt_samples(&mut self) -> Vec<Duration> {
        Vec::new()
    }
}

/// Smoothed round-trip time and its variation (RFC 6298), from exchanges answered on their
/// first try only (Karn's rule: a retried exchange's answer may belong to either send).
#[derive(Debug, Clone, Copy)]
pub struct Rtt {
    srtt: Option<Duration>,
    rttvar: Duration,
}

impl Default for Rtt {
    fn default() -> Self {
        Self {
            srtt: None,
            rttvar: Duration::ZERO,
        }
    }
}

impl Rtt {
    /// Before any sample: generous for a radio, short enough that a lost first frame costs little.
    pub const INITIAL_RTO: Duration = Duration::from_millis(200);
    /// Floor: below this a loopback retry only duplicates work the vehicle is already doing.
    pub const MIN_RTO: Duration = Duration::from_millis(10);
    /// Ceiling.
    pub const MAX_RTO: Duration = Duration::from_secs(3);

    /// Adds a sample.
    pub fn sample(&mut self, rtt: Duration) {
        match self.srtt {
            None => {
                self.srtt = Some(rtt);
                self.rttvar = rtt / 2;
            }
            Some(s) => {
                let err = s.abs_diff(rtt);
                self.rttvar = (self.rttvar * 3 + err) / 4;
                self.srtt = Some((s * 7 + rtt) / 8);
            }
        }
    }

    /// The retransmission timeout: srtt + 4·rttvar, clamped.
    #[must_use]
    pub fn rto(&self) -> Duration {
        match self.srtt {
            None => Self::INITIAL_RTO,
            Some(s) => (s + self.rttvar * 4).clamp(Self::MIN_RTO, Self::MAX_RTO),
        }
    }

    /// The smoothed round trip, if measured.
    #[must_use]
    pub fn srtt(&self) -> Option<Duration> {
        self.srtt
    }
}

/// Sends at the plain timeout before the wait between retries starts doubling.
pub const STEADY_TRIES: u8 = 4;
/// A request is called unanswered only after this long as well as after its tries: a loaded
/// machine or a radio fade can silence a link for seconds.
pub const GIVE_UP_AFTER: Duration = Duration::from_secs(5);
/// Longest wait between two sends of one request.
pub const MAX_RETRY_WAIT: Duration = Duration::from_secs(1);

/// The wait after send number `tries` (1-based): the timeout for the first few sends, then
/// doubling up to [`MAX_RETRY_WAIT`]. Random loss needs quick retries; a stalled peer (a busy
/// machine, a radio fade) needs the requester to keep asking for seconds, not milliseconds,
/// before it calls the request unanswered.
#[must_use]
pub fn retry_wait(rto: Duration, tries: u8) -> Duration {
    let doublings = u32::from(tries.saturating_sub(STEADY_TRIES)).min(16);
    (rto * 2u32.pow(doublings)).min(MAX_RETRY_WAIT.max(rto))
}

/// What a [`Retry`] calls for when the machine's time comes.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Step {
    /// The deadline has not passed.
    Wait,
    /// Send the request again.
    Send,
    /// The request is unanswered.
    GiveUp,
}

/// The retry bookkeeping of a request that waits for one answer: the sends made, when the
/// first went, when the next is due ([`retry_wait`] after each send, or a later time the
/// machine sets) and when the request is called unanswered (after its tries *and* a least
/// time, whichever comes later).
#[derive(Debug, Clone)]
pub struct Retry {
    rto: Duration,
    max_tries: u8,
    give_up_after: Duration,
    tries: u8,
    started: Option<Instant>,
    deadline: Instant,
}

impl Retry {
    /// Sends every `rto` (then backing off), unanswered after `max_tries` sends and
    /// `give_up_after` since the first.
    #[must_use]
    pub fn new(rto: Duration, max_tries: u8, give_up_after: Duration) -> Self {
        Self {
            rto,
            max_tries,
            give_up_after,
            tries: 0,
            started: None,
            deadline: Instant::now(),
        }
    }

    /// Counts a send at `now` and sets the deadline for the next; returns the send's number
    /// (1 for the first).
    pub fn send(&mut self, now: Instant) -> u8 {
        self.started.get_or_insert(now);
        self.tries += 1;
        self.deadline = now + retry_wait(self.rto, self.tries);
        self.tries
    }

    /// Sends made.
    #[must_use]
    pub fn tries(&self) -> u8 {
        self.tries
    }

    /// When the machine wants `on_time` next.
    #[must_use]
    pub fn deadline(&self) -> Instant {
        self.deadline
    }

    /// Moves the next deadline (a grace for a reason, a longer wait for a command in
    /// progress).
    pub fn wait_until(&mut self, deadline: Instant) {
        self.deadline = deadline;
    }

    /// Time since the first send (zero before it).
    #[must_use]
    pub fn elapsed(&self, now: Instant) -> Duration {
        self.started
            .map_or(Duration::ZERO, |s| now.duration_since(s))
    }

    /// What is due at `now`: nothing before the deadline; after it, another send, or giving
    /// up once every try is spent and the least time has passed.
    #[must_use]
    pub fn step(&self, now: Instant) -> Step {
        if now < self.deadline {
            Step::Wait
        } else if self.tries >= self.max_tries && self.elapsed(now) >= self.give_up_after {
            Step::GiveUp
        } else {
            Step::Send
        }
    }

    /// The round trip of an answer arriving at `now`, if only one send was made (Karn's rule:
    /// after a retry the answer may belong to either send).
    #[must_use]
    pub fn first_try_rtt(&self, now: Instant) -> Option<Duration> {
        if self.tries == 1 {
            self.started.map(|s| now.duration_since(s))
        } else {
            None
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn retries_back_off_after_a_few_quick_ones() {
        let rto = Duration::from_millis(25);
        let waits: Vec<u128> = (1..=12).map(|t| retry_wait(rto, t).as_millis()).collect();
        assert_eq!(
            waits,
            [25, 25, 25, 25, 50, 100, 200, 400, 800, 1000, 1000, 1000]
        );
        let total: u128 = waits.iter().sum();
        assert!(total > 3000, "twelve tries span {total} ms");
    }

    #[test]
    fn a_request_is_unanswered_only_after_its_tries_and_its_least_time() {
        let rto = Duration::from_millis(10);
        let mut r = Retry::new(rto, 2, Duration::from_millis(500));
        let t0 = Instant::now();
        assert_eq!(r.send(t0), 1);
        assert_eq!(r.deadline(), t0 + rto);
        assert_eq!((r.step(t0), r.step(r.deadline())), (Step::Wait, Step::Send));
        assert_eq!(r.first_try_rtt(t0 + rto), Some(rto));
        assert_eq!(r.send(t0 + rto), 2);
        assert_eq!(r.first_try_rtt(t0 + rto), None, "Karn's rule");
        let least = t0 + Duration::from_millis(500);
        assert_eq!(r.step(least - rto), Step::Send, "tries spent, time not");
        assert_eq!(r.step(least), Step::GiveUp);
        r.wait_until(t0 + Duration::from_secs(5));
        assert_eq!(r.deadline(), t0 + Duration::from_secs(5));
    }

    #[test]
    fn rto_follows_samples_within_bounds() {
        let mut r = Rtt::default();
        assert_eq!(r.rto(), Rtt::INITIAL_RTO);
        for _ in 0..20 {
            r.sample(Duration::from_millis(40));
        }
        let rto = r.rto();
        assert!(
            rto >= Duration::from_millis(40) && rto < Duration::from_millis(80),
            "{rto:?}"
        );
        r.sample(Duration::from_secs(30));
        assert_eq!(r.rto(), Rtt::MAX_RTO);
        let mut fast = Rtt::default();
        fast.sample(Duration::from_micros(300));
        assert_eq!(fast.rto(), Rtt::MIN_RTO);
    }
}
