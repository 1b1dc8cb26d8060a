//! What the vehicle offers: MAV_CMD_REQUEST_MESSAGE(AUTOPILOT_VERSION), sent again until the
//! AUTOPILOT_VERSION arrives, and its `capabilities` bits. A vehicle that refuses or does not
//! answer offers nothing beyond the basic protocols (`None`).

use std::time::{Duration, Instant};

use vtol_link::dialect::{MavCmd, MavMessage, MavProtocolCapability, MavResult};
use vtol_link::{ComponentId, SystemId};

use super::machine::{Inbound, Machine, Retry, Step};

/// Rounds of the question before the capabilities are called unknown. Unknown means the
/// parameter protocol, which over a lossy link takes three times as long as FTP: with a round
/// unanswered one time in eight or more at 30 % loss each way, three rounds gave up on one pull
/// in fifteen.
pub const VERSION_TRIES: u8 = 5;

/// The least wait for the answer before asking again: a busy vehicle or machine answers late,
/// and asked alongside the round-trip probe it costs no time of its own.
pub const VERSION_MIN_WAIT: Duration = Duration::from_millis(300);

/// AUTOPILOT_VERSION's id, for MAV_CMD_REQUEST_MESSAGE.
const AUTOPILOT_VERSION_ID: f32 = 148.0;

/// Copies of the question in each round, [`COPY_GAP`] apart: asked before the round trip is
/// known, a lost request or answer costs a whole timeout, and at 30 % loss each way one
/// exchange in two fails (three copies leave one round in eight unanswered); an extra answer
/// costs the link one AUTOPILOT_VERSION.
pub const VERSION_COPIES: u8 = 3;
/// The copies' spacing. ArduPilot sends a requested message at its next send slot, once however
/// many requests came since the last: copies sent together got one answer, whose loss (one
/// time in three) cost the round.
pub const COPY_GAP: Duration = Duration::from_millis(40);

/// The capabilities of `target`: `Some(bits)` from its AUTOPILOT_VERSION, `None` without one.
#[derive(Debug)]
pub struct VersionMachine {
    target: (SystemId, ComponentId),
    retry: Retry,
    /// The round's copies still to send, and when the next goes.
    copies_left: u8,
    next_copy: Instant,
    /// The round's request, repeated by its copies.
    round: Option<MavMessage>,
    done: Option<Option<MavProtocolCapability>>,
}

impl VersionMachine {
    /// Asks `target`, again every `rto` (then backing off).
    #[must_use]
    pub fn new(target: (SystemId, ComponentId), rto: Duration) -> Self {
        Self {
            target,
            retry: Retry::new(rto.max(VERSION_MIN_WAIT), VERSION_TRIES, Duration::ZERO),
            copies_left: 0,
            next_copy: Instant::now(),
            round: None,
            done: None,
        }
    }

    /// A round's first copy; the others follow [`COPY_GAP`] apart.
    fn request(&mut self, now: Instant) -> MavMessage {
        let send = self.retry.send(now);
        let m = vtol_link::frame::command_long(
            self.target,
            MavCmd::MAV_CMD_REQUEST_MESSAGE,
            [AUTOPILOT_VERSION_ID, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0],
            send - 1,
        );
        self.round = Some(m.clone());
        self.copies_left = VERSION_COPIES - 1;
        self.next_copy = now + COPY_GAP;
        m
    }
}

impl Machine for VersionMachine {
    type Output = Option<MavProtocolCapability>;

    fn start(&mut self, now: Instant) -> Vec<MavMessage> {
        vec![self.request(now)]
    }

    fn on_message(&mut self, _now: Instant, m: &Inbound) -> Vec<MavMessage> {
        if (m.sys, m.comp) != self.target || self.done.is_some() {
            return Vec::new();
        }
        match &m.msg {
            MavMessage::AUTOPILOT_VERSION(v) => self.done = Some(Some(v.capabilities)),
            MavMessage::COMMAND_ACK(a)
                if a.command == MavCmd::MAV_CMD_REQUEST_MESSAGE
                    && !matches!(
                        a.result,
                        MavResult::MAV_RESULT_ACCEPTED | MavResult::MAV_RESULT_IN_PROGRESS
                    ) =>
            {
                self.done = Some(None);
            }
            _ => {}
        }
        Vec::new()
    }

    fn on_time(&mut self, now: Instant) -> Vec<MavMessage> {
        if self.done.is_some() {
            return Vec::new();
        }
        if self.copies_left > 0 && now >= self.next_copy {
            self.copies_left -= 1;
            self.next_copy = now + COPY_GAP;
            // The round's wait counts from its last copy.
            let wait = self.retry.deadline() + COPY_GAP;
            self.retry.wait_until(wait);
            return self.round.clone().into_iter().collect();
        }
        match self.retry.step(now) {
            Step::Wait => Vec::new(),
            Step::Send => vec![self.request(now)],
            Step::GiveUp => {
                self.done = Some(None);
                Vec::new()
            }
        }
    }

    fn deadline(&self) -> Instant {
        if self.copies_left > 0 {
            self.next_copy.min(self.retry.deadline())
        } else {
            self.retry.deadline()
        }
    }

    fn result(&mut self) -> Option<Self::Output> {
        self.done.take()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const V: (SystemId, ComponentId) = (SystemId(1), ComponentId(1));

    fn version(caps: MavProtocolCapability) -> Inbound {
        Inbound {
            sys: V.0,
            comp: V.1,
            msg: MavMessage::AUTOPILOT_VERSION(vtol_link::dialect::AUTOPILOT_VERSION_DATA {
                capabilities: caps,
                ..Default::default()
            }),
        }
    }

    #[test]
    fn the_version_gives_the_capabilities_and_silence_gives_none() {
        let t0 = Instant::now();
        let mut m = VersionMachine::new(V, Duration::from_millis(20));
        assert_eq!(m.start(t0).len(), 1);
        // The round's other copies, apart: ArduPilot answers requests that come together once.
        let second = m.deadline();
        assert_eq!(second.duration_since(t0), COPY_GAP);
        assert_eq!(m.on_time(second).len(), 1);
        assert_eq!(m.on_time(m.deadline()).len(), 1);
        assert_eq!(m.copies_left, 0);
        assert!(
            m.deadline() >= second + COPY_GAP + VERSION_MIN_WAIT,
            "the wait counts from the last copy"
        );
        assert_eq!(m.on_time(m.deadline()).len(), 1, "asked again");
        m.on_message(
            t0,
            &version(MavProtocolCapability::MAV_PROTOCOL_CAPABILITY_FTP),
        );
        let caps = m.result().expect("done").expect("answered");
        assert!(caps.contains(MavProtocolCapability::MAV_PROTOCOL_CAPABILITY_FTP));

        let mut m = VersionMachine::new(V, Duration::from_millis(20));
        let mut sends = m.start(t0).len();
        while m.done.is_none() {
            sends += m.on_time(m.deadline()).len();
        }
        assert_eq!(
            sends,
            usize::from(VERSION_COPIES) * usize::from(VERSION_TRIES),
            "{sends}"
        );
        assert_eq!(m.result(), Some(None));
    }
}
