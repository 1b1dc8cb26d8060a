//! GET_MESSAGE_INTERVAL as a state machine: the request sent again until the vehicle's
//! MESSAGE_INTERVAL for that message arrives, or given up (a vehicle that does not answer it
//! leaves the interval unknown).

use std::time::{Duration, Instant};

use vtol_link::dialect::{self as apm, MavCmd, MavMessage};
use vtol_link::{ComponentId, SystemId};

use super::machine::{Inbound, Machine, Retry, Step};

/// Sends before the interval is called unknown…
pub const INTERVAL_TRIES: u8 = 6;
/// …and at least this long: a full radio's queue holds the answer back for a while.
pub const INTERVAL_GIVE_UP: Duration = Duration::from_secs(2);

/// One message's interval, asked of `target`: `Some(µs)` as the vehicle reports it (0: not
/// sent or unknown, −1: disabled), `None` without an answer.
#[derive(Debug)]
pub struct IntervalMachine {
    target: (SystemId, ComponentId),
    msgid: u32,
    retry: Retry,
    done: Option<Option<i32>>,
}

impl IntervalMachine {
    /// Asks `target` for the interval of `msgid`, asking again every `rto` (then backing off).
    #[must_use]
    pub fn new(target: (SystemId, ComponentId), msgid: u32, rto: Duration) -> Self {
        Self {
            target,
            msgid,
            retry: Retry::new(rto, INTERVAL_TRIES, INTERVAL_GIVE_UP),
            done: None,
        }
    }

    // GET_MESSAGE_INTERVAL is deprecated for REQUEST_MESSAGE(MESSAGE_INTERVAL, id), which
    // neither ArduPilot nor the twin answers with the interval; both answer this.
    #[allow(deprecated)]
    fn request(&mut self, now: Instant) -> MavMessage {
        let send = self.retry.send(now);
        MavMessage::COMMAND_LONG(apm::COMMAND_LONG_DATA {
            param1: self.msgid as f32,
            param2: 0.0,
            param3: 0.0,
            param4: 0.0,
            param5: 0.0,
            param6: 0.0,
            param7: 0.0,
            command: MavCmd::MAV_CMD_GET_MESSAGE_INTERVAL,
            target_system: self.target.0.0,
            target_component: self.target.1.0,
            confirmation: send - 1,
        })
    }
}

impl Machine for IntervalMachine {
    type Output = Option<i32>;

    fn start(&mut self, now: Instant) -> Vec<MavMessage> {
        vec![self.request(now)]
    }

    fn on_message(&mut self, _now: Instant, m: &Inbound) -> Vec<MavMessage> {
        if let MavMessage::MESSAGE_INTERVAL(i) = &m.msg
            && (m.sys, m.comp) == self.target
            && u32::from(i.message_id) == self.msgid
        {
            self.done.get_or_insert(Some(i.interval_us));
        }
        Vec::new()
    }

    fn on_time(&mut self, now: Instant) -> Vec<MavMessage> {
        if self.done.is_some() {
            return Vec::new();
        }
        match self.retry.step(now) {
            Step::Wait => Vec::new(),
            Step::GiveUp => {
                self.done = Some(None);
                Vec::new()
            }
            Step::Send => vec![self.request(now)],
        }
    }

    fn deadline(&self) -> Instant {
        self.retry.deadline()
    }

    fn result(&mut self) -> Option<Self::Output> {
        self.done.take()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const V: (SystemId, ComponentId) = (SystemId(1), ComponentId(1));

    fn interval(msgid: u16, us: i32) -> Inbound {
        Inbound {
            sys: V.0,
            comp: V.1,
            msg: MavMessage::MESSAGE_INTERVAL(apm::MESSAGE_INTERVAL_DATA {
                interval_us: us,
                message_id: msgid,
            }),
        }
    }

    #[test]
    fn the_answer_for_that_message_ends_it_and_silence_gives_up() {
        let t0 = Instant::now();
        let mut m = IntervalMachine::new(V, 251, Duration::from_millis(20));
        assert_eq!(m.start(t0).len(), 1);
        m.on_message(t0, &interval(30, 20_000));
        assert!(m.result().is_none(), "another message's interval");
        assert_eq!(m.on_time(m.deadline()).len(), 1, "asked again");
        m.on_message(t0, &interval(251, 100_000));
        assert_eq!(m.result(), Some(Some(100_000)));

        let mut m = IntervalMachine::new(V, 251, Duration::from_millis(20));
        let mut sends = m.start(t0).len();
        while m.done.is_none() {
            sends += m.on_time(m.deadline()).len();
        }
        assert!(sends >= usize::from(INTERVAL_TRIES), "{sends}");
        assert!(m.deadline().duration_since(t0) >= INTERVAL_GIVE_UP);
        assert_eq!(m.result(), Some(None));
    }
}
