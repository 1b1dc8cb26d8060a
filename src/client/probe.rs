//! A round-trip probe: TIMESYNC requests (tc1 = 0) until the vehicle answers one. Each probe
//! carries its own `ts1`, which the vehicle echoes, so every answer times exactly one send and
//! probes can go out quickly without Karn's ambiguity. A client that measures the round trip
//! first never waits a blind initial timeout on its first real request.

use std::collections::HashMap;
use std::time::{Duration, Instant};

use vtol_link::dialect::{self as apm, MavMessage};
use vtol_link::{ComponentId, SystemId};

use super::machine::{Inbound, Machine, Rtt};

/// Probes sent, one every [`Rtt::MIN_RTO`], before waiting for the last answers.
pub const PROBES: u32 = 8;
/// How long after the first probe an answer still counts.
pub const PROBE_WAIT: Duration = Duration::from_secs(1);

/// The probe exchange; the result is the first round trip measured, if any.
#[derive(Debug)]
pub struct ProbeMachine {
    target: (SystemId, ComponentId),
    base: i64,
    sent: HashMap<i64, Instant>,
    started: Instant,
    deadline: Instant,
    done: Option<Option<Duration>>,
    sample: Option<Duration>,
}

impl ProbeMachine {
    /// A probe of `target`.
    #[must_use]
    pub fn new(target: (SystemId, ComponentId)) -> Self {
        let now = Instant::now();
        // Distinct from other clients' requests that may echo on the same link.
        let base = i64::from(std::process::id()) << 32;
        Self {
            target,
            base,
            sent: HashMap::new(),
            started: now,
            deadline: now,
            done: None,
            sample: None,
        }
    }

    fn probe(&mut self, now: Instant) -> MavMessage {
        let ts1 = self.base + self.sent.len() as i64 + 1;
        self.sent.insert(ts1, now);
        self.deadline = if self.sent.len() < PROBES as usize {
            now + Rtt::MIN_RTO
        } else {
            self.started + PROBE_WAIT
        };
        MavMessage::TIMESYNC(apm::TIMESYNC_DATA {
            tc1: 0,
            ts1,
            target_system: self.target.0.0,
            target_component: self.target.1.0,
        })
    }
}

impl Machine for ProbeMachine {
    type Output = Option<Duration>;

    fn start(&mut self, now: Instant) -> Vec<MavMessage> {
        self.started = now;
        vec![self.probe(now)]
    }

    fn on_message(&mut self, now: Instant, m: &Inbound) -> Vec<MavMessage> {
        if self.done.is_some() || (m.sys, m.comp) != self.target {
            return Vec::new();
        }
        if let MavMessage::TIMESYNC(t) = &m.msg
            && t.tc1 != 0
            && let Some(sent) = self.sent.get(&t.ts1)
        {
            let rtt = now.duration_since(*sent);
            self.sample = Some(rtt);
            self.done = Some(Some(rtt));
        }
        Vec::new()
    }

    fn on_time(&mut self, now: Instant) -> Vec<MavMessage> {
        if self.done.is_some() || now < self.deadline {
            return Vec::new();
        }
        if self.sent.len() < PROBES as usize {
            return vec![self.probe(now)];
        }
        self.done = Some(None);
        Vec::new()
    }

    fn deadline(&self) -> Instant {
        self.deadline
    }

    fn result(&mut self) -> Option<Self::Output> {
        self.done.take()
    }

    fn take_rtt_samples(&mut self) -> Vec<Duration> {
        self.sample.take().into_iter().collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn reply(ts1: i64) -> Inbound {
        Inbound {
            sys: SystemId(1),
            comp: ComponentId(1),
            msg: MavMessage::TIMESYNC(apm::TIMESYNC_DATA {
                tc1: 42,
                ts1,
                target_system: 255,
                target_component: 190,
            }),
        }
    }

    fn ts1(m: &[MavMessage]) -> i64 {
        match &m[0] {
            MavMessage::TIMESYNC(t) => t.ts1,
            other => panic!("{other:?}"),
        }
    }

    #[test]
    fn an_answer_to_any_probe_times_that_probe() {
        let t0 = Instant::now();
        let mut m = ProbeMachine::new((SystemId(1), ComponentId(1)));
        let first = ts1(&m.start(t0));
        let second = ts1(&m.on_time(m.deadline()));
        assert_ne!(first, second);
        let t_second = t0 + Rtt::MIN_RTO;
        // The answer to the first probe arrives late: it is timed from the first send.
        m.on_message(t_second + Duration::from_millis(5), &reply(first));
        assert_eq!(
            m.result(),
            Some(Some(Rtt::MIN_RTO + Duration::from_millis(5)))
        );
    }

    #[test]
    fn gives_up_after_the_probes_and_the_wait() {
        let t0 = Instant::now();
        let mut m = ProbeMachine::new((SystemId(1), ComponentId(1)));
        let mut sent = m.start(t0).len();
        while m.done.is_none() {
            let d = m.deadline();
            sent += m.on_time(d).len();
        }
        assert_eq!(sent, PROBES as usize);
        assert_eq!(m.result(), Some(None));
        // A reply to a request that is not ours is ignored.
        let mut other = ProbeMachine::new((SystemId(1), ComponentId(1)));
        other.start(t0);
        other.on_message(t0, &reply(7));
        assert_eq!(other.result(), None);
    }
}
