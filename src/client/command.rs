//! COMMAND_LONG as a state machine: retries with `confirmation` incremented, the ACK matched
//! by command and target, IN_PROGRESS extending the wait, and the vehicle's STATUSTEXT reason
//! attached to a refusal. The twin (like ArduPilot) sends the reason just before the ACK, other
//! vehicles just after, so texts from the target seen since the first send count, and a
//! refusal waits a short grace period for one when none came yet.

use std::time::{Duration, Instant};

use vtol_link::dialect::{self as apm, MavCmd, MavMessage, MavResult};
use vtol_link::{ComponentId, SystemId};

use super::machine::{GIVE_UP_AFTER, Inbound, Machine, Retry, Step};
use vtol_link::statustext::TextAssembler;

/// Sends of one command before giving up (the first plus retries): enough that 30 % loss each
/// way (half the exchanges failing) almost never exhausts them.
pub const COMMAND_TRIES: u8 = 10;
/// How long an IN_PROGRESS keeps the command alive without another word.
pub const IN_PROGRESS_WAIT: Duration = Duration::from_secs(5);
/// How long a refusal waits for the vehicle's STATUSTEXT when none came before the ACK.
pub const REASON_GRACE: Duration = Duration::from_millis(150);

/// A command's final answer.
#[derive(Debug, Clone, PartialEq)]
pub struct CommandOutcome {
    /// The vehicle's result (never IN_PROGRESS).
    pub result: MavResult,
    /// The vehicle's explanation (STATUSTEXT), when it sent one.
    pub reason: Option<String>,
    /// Sends it took (1 = answered on the first).
    pub tries: u8,
    /// First send to final ACK.
    pub elapsed: Duration,
}

impl CommandOutcome {
    /// Whether the vehicle accepted the command.
    #[must_use]
    pub fn accepted(&self) -> bool {
        self.result == MavResult::MAV_RESULT_ACCEPTED
    }
}

/// Why a command got no final answer.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct NoAck {
    /// Sends made.
    pub tries: u8,
}

/// The command exchange.
#[derive(Debug)]
pub struct CommandMachine {
    me: (SystemId, ComponentId),
    target: (SystemId, ComponentId),
    command: MavCmd,
    params: [f32; 7],
    retry: Retry,
    in_progress: bool,
    texts: Vec<String>,
    /// Long reasons come in chunks (STATUSTEXT `id`/`chunk_seq`).
    assembler: TextAssembler,
    refused: Option<(MavResult, Instant)>,
    /// Set once an ACK for the first send arrived before any retry (for the RTT estimate).
    pub first_try_rtt: Option<Duration>,
    result: Option<Result<CommandOutcome, NoAck>>,
}

impl CommandMachine {
    /// A command from `me` to `target`, retried every `rto`.
    #[must_use]
    pub fn new(
        me: (SystemId, ComponentId),
        target: (SystemId, ComponentId),
        command: MavCmd,
        params: [f32; 7],
        rto: Duration,
    ) -> Self {
        Self {
            me,
            target,
            command,
            params,
            retry: Retry::new(rto, COMMAND_TRIES, GIVE_UP_AFTER),
            in_progress: false,
            texts: Vec::new(),
            assembler: TextAssembler::default(),
            refused: None,
            first_try_rtt: None,
            result: None,
        }
    }

    fn frame(&mut self, now: Instant) -> MavMessage {
        let confirmation = self.retry.send(now) - 1;
        vtol_link::command_long(self.target, self.command, self.params, confirmation)
    }

    fn finish(&mut self, result: MavResult, now: Instant) {
        self.result = Some(Ok(CommandOutcome {
            result,
            reason: self.texts.last().cloned(),
            tries: self.retry.tries(),
            elapsed: self.retry.elapsed(now),
        }));
    }
}

impl Machine for CommandMachine {
    type Output = Result<CommandOutcome, NoAck>;

    fn start(&mut self, now: Instant) -> Vec<MavMessage> {
        vec![self.frame(now)]
    }

    fn on_message(&mut self, now: Instant, m: &Inbound) -> Vec<MavMessage> {
        if self.result.is_some() || (m.sys, m.comp) != self.target {
            return Vec::new();
        }
        match &m.msg {
            MavMessage::STATUSTEXT(t) => {
                if (t.severity as u32) <= apm::MavSeverity::MAV_SEVERITY_WARNING as u32
                    && let Some(s) = self.assembler.push(t)
                {
                    self.texts.push(s);
                    if let Some((r, _)) = self.refused {
                        self.finish(r, now);
                    }
                }
            }
            MavMessage::COMMAND_ACK(a) if a.command == self.command => {
                // Targets (0, 0) come from senders that leave the extension out: accept them.
                // Otherwise the ACK must be ours: scripts speaking as (255, 0) get their own.
                let to_us = (a.target_system, a.target_component) == (0, 0)
                    || (a.target_system, a.target_component) == (self.me.0.0, self.me.1.0);
                if !to_us || self.refused.is_some() {
                    return Vec::new();
                }
                if !self.in_progress
                    && let Some(rtt) = self.retry.first_try_rtt(now)
                {
                    self.first_try_rtt = Some(rtt);
                }
                match a.result {
                    MavResult::MAV_RESULT_IN_PROGRESS => {
                        self.in_progress = true;
                        self.retry.wait_until(now + IN_PROGRESS_WAIT);
                    }
                    MavResult::MAV_RESULT_ACCEPTED => self.finish(a.result, now),
                    r if self.texts.is_empty() => {
                        self.refused = Some((r, now));
                        self.retry.wait_until(now + REASON_GRACE);
                    }
                    r => self.finish(r, now),
                }
            }
            _ => {}
        }
        Vec::new()
    }

    fn on_time(&mut self, now: Instant) -> Vec<MavMessage> {
        let step = self.retry.step(now);
        if self.result.is_some() || step == Step::Wait {
            return Vec::new();
        }
        if let Some((r, _)) = self.refused {
            self.finish(r, now);
            return Vec::new();
        }
        if step == Step::GiveUp {
            self.result = Some(Err(NoAck {
                tries: self.retry.tries(),
            }));
            return Vec::new();
        }
        // An IN_PROGRESS that went quiet is asked again, like a lost ACK.
        self.in_progress = false;
        vec![self.frame(now)]
    }

    fn deadline(&self) -> Instant {
        self.retry.deadline()
    }

    fn result(&mut self) -> Option<Self::Output> {
        self.result.take()
    }

    fn take_rtt_samples(&mut self) -> Vec<Duration> {
        self.first_try_rtt.take().into_iter().collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const ME: (SystemId, ComponentId) = (SystemId(255), ComponentId(190));
    const V: (SystemId, ComponentId) = (SystemId(1), ComponentId(1));

    fn ack(result: MavResult, target: (SystemId, ComponentId)) -> Inbound {
        Inbound {
            sys: V.0,
            comp: V.1,
            msg: MavMessage::COMMAND_ACK(apm::COMMAND_ACK_DATA {
                command: MavCmd::MAV_CMD_COMPONENT_ARM_DISARM,
                result,
                progress: 0,
                result_param2: 0,
                target_system: target.0.0,
                target_component: target.1.0,
            }),
        }
    }

    fn text(s: &str) -> Inbound {
        Inbound {
            sys: V.0,
            comp: V.1,
            msg: MavMessage::STATUSTEXT(apm::STATUSTEXT_DATA {
                severity: apm::MavSeverity::MAV_SEVERITY_CRITICAL,
                text: s.into(),
                id: 0,
                chunk_seq: 0,
            }),
        }
    }

    fn arm() -> CommandMachine {
        CommandMachine::new(
            ME,
            V,
            MavCmd::MAV_CMD_COMPONENT_ARM_DISARM,
            [1.0, 0., 0., 0., 0., 0., 0.],
            Duration::from_millis(100),
        )
    }

    fn confirmation(m: &[MavMessage]) -> u8 {
        match &m[0] {
            MavMessage::COMMAND_LONG(c) => c.confirmation,
            other => panic!("{other:?}"),
        }
    }

    #[test]
    fn retries_count_up_confirmation_and_give_up() {
        let t0 = Instant::now();
        let mut m = arm();
        assert_eq!(confirmation(&m.start(t0)), 0);
        assert!(
            m.on_time(t0 + Duration::from_millis(50)).is_empty(),
            "not due yet"
        );
        for k in 1..COMMAND_TRIES {
            let out = m.on_time(m.deadline());
            assert_eq!(confirmation(&out), k);
        }
        // Past the tries, it keeps asking (at the longest wait) until GIVE_UP_AFTER.
        let mut tries = COMMAND_TRIES;
        loop {
            let d = m.deadline();
            if m.on_time(d).is_empty() {
                assert!(d.duration_since(t0) >= GIVE_UP_AFTER);
                break;
            }
            tries += 1;
        }
        assert_eq!(m.result(), Some(Err(NoAck { tries })));
    }

    #[test]
    fn ack_for_another_client_or_command_is_ignored() {
        let t0 = Instant::now();
        let mut m = arm();
        m.start(t0);
        m.on_message(
            t0,
            &ack(
                MavResult::MAV_RESULT_ACCEPTED,
                (SystemId(255), ComponentId(0)),
            ),
        );
        assert!(m.result().is_none());
        let mut other = ack(MavResult::MAV_RESULT_ACCEPTED, ME);
        if let MavMessage::COMMAND_ACK(a) = &mut other.msg {
            a.command = MavCmd::MAV_CMD_DO_SET_MODE;
        }
        m.on_message(t0, &other);
        assert!(m.result().is_none());
        m.on_message(t0, &ack(MavResult::MAV_RESULT_ACCEPTED, ME));
        assert!(m.result().expect("done").expect("acked").accepted());
    }

    #[test]
    fn in_progress_extends_the_wait() {
        let t0 = Instant::now();
        let mut m = arm();
        m.start(t0);
        m.on_message(t0, &ack(MavResult::MAV_RESULT_IN_PROGRESS, ME));
        assert!(
            m.on_time(t0 + Duration::from_secs(1)).is_empty(),
            "no retry while in progress"
        );
        m.on_message(
            t0 + Duration::from_secs(2),
            &ack(MavResult::MAV_RESULT_ACCEPTED, ME),
        );
        let o = m.result().expect("done").expect("acked");
        assert_eq!((o.tries, o.accepted()), (1, true));
    }

    #[test]
    fn refusal_carries_the_text_before_or_after_the_ack() {
        let t0 = Instant::now();
        let mut before = arm();
        before.start(t0);
        before.on_message(t0, &text("PreArm: gyro calibration in progress"));
        before.on_message(t0, &ack(MavResult::MAV_RESULT_FAILED, ME));
        let o = before.result().expect("done").expect("acked");
        assert_eq!(
            o.reason.as_deref(),
            Some("PreArm: gyro calibration in progress")
        );

        let mut after = arm();
        after.start(t0);
        after.on_message(t0, &ack(MavResult::MAV_RESULT_DENIED, ME));
        assert!(after.result().is_none(), "waits for the reason");
        after.on_message(t0, &text("Arming denied"));
        let o = after.result().expect("done").expect("acked");
        assert_eq!(
            (o.result, o.reason.as_deref()),
            (MavResult::MAV_RESULT_DENIED, Some("Arming denied"))
        );

        let mut silent = arm();
        silent.start(t0);
        silent.on_message(t0, &ack(MavResult::MAV_RESULT_DENIED, ME));
        silent.on_time(silent.deadline());
        assert_eq!(silent.result().expect("done").expect("acked").reason, None);
    }
}
