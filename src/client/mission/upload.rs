//! The upload as a state machine.
//!
//! MISSION_COUNT is repeated on the round-trip timeout until the vehicle asks for an item; from
//! then on the vehicle drives: every MISSION_REQUEST_INT or MISSION_REQUEST is answered with the
//! item it names (again, when it asks again because an item was lost). The transfer ends with
//! the vehicle's MISSION_ACK; a refusal waits briefly for the STATUSTEXT that explains it.
//! The vehicle asks again for an item it did not get, but only after a second (ArduPilot, the
//! twin): on a lossy link that second would be paid for every lost frame. So when the next
//! request does not come within the round-trip timeout, the item last asked for is sent again
//! (it may have been lost) with the one after it (the vehicle's request for that one may have
//! been lost; ArduPilot and the twin take the item they wait for whether or not its request
//! arrived, and answer one they do not wait for with MAV_MISSION_INVALID_SEQUENCE or nothing,
//! which does not end the transfer). Silence for [`UPLOAD_SILENCE`] ends the upload without an
//! ACK. The last item is repeated until the ACK comes, for [`LAST_ACK_WAIT`] at least (the
//! twin and MAVProxy answer a repeated last item with the ACK again). A refusal that answers
//! such a repeat, or no ACK at all, ends the upload without an ACK: the caller's verifying
//! download tells whether the vehicle took the list.

use std::time::{Duration, Instant};

use vtol_link::dialect::{self as apm, MavMessage, MavMissionResult};
use vtol_link::{ComponentId, SystemId};

use super::super::machine::{GIVE_UP_AFTER, Inbound, Machine, Retry, Rtt, Step};
use super::{MISSION_TRIES, mission_type};
use crate::mission::Kind;
use vtol_link::statustext::TextAssembler;

/// Silence after which an upload under way is given up (ArduPilot cancels its side after 8 s).
pub const UPLOAD_SILENCE: Duration = Duration::from_secs(8);
/// The least time the last item is repeated for before the ACK is called lost.
pub const LAST_ACK_WAIT: Duration = Duration::from_millis(2500);
/// How long a refusal waits for the STATUSTEXT that explains it.
const REASON_GRACE: Duration = Duration::from_millis(150);

/// How an upload ended.
#[derive(Debug, Clone, PartialEq)]
pub enum UploadOutcome {
    /// The vehicle's MISSION_ACK, with its STATUSTEXT reason for a refusal.
    Acked {
        /// MAV_MISSION_RESULT.
        result: MavMissionResult,
        /// The vehicle's explanation.
        reason: Option<String>,
    },
    /// No MISSION_ACK.
    NoAck {
        /// Distinct items the vehicle asked for.
        requested: usize,
        /// Items in the list.
        total: usize,
    },
}

/// The upload exchange.
#[derive(Debug)]
pub struct UploadMachine {
    me: (SystemId, ComponentId),
    target: (SystemId, ComponentId),
    kind: Kind,
    items: Vec<apm::MISSION_ITEM_INT_DATA>,
    retry: Retry,
    asked: Vec<bool>,
    last_heard: Option<Instant>,
    refused: Option<(MavMissionResult, Instant)>,
    /// The item last asked for and the repeats of its answer.
    pending: Option<(u16, Retry)>,
    /// Round trips measured in this transfer (request to the next request).
    measured: Rtt,
    rto: Duration,
    texts: Vec<String>,
    assembler: TextAssembler,
    rtt: Option<Duration>,
    done: Option<UploadOutcome>,
}

impl UploadMachine {
    /// Uploads `items` (already addressed and numbered) as the `kind` list of `target`;
    /// `me` is who the vehicle's requests and ACK are addressed to.
    #[must_use]
    pub fn new(
        me: (SystemId, ComponentId),
        target: (SystemId, ComponentId),
        kind: Kind,
        items: Vec<apm::MISSION_ITEM_INT_DATA>,
        rto: Duration,
    ) -> Self {
        let n = items.len();
        Self {
            me,
            target,
            kind,
            items,
            retry: Retry::new(rto, MISSION_TRIES, GIVE_UP_AFTER),
            asked: vec![false; n],
            last_heard: None,
            refused: None,
            pending: None,
            measured: Rtt::default(),
            rto,
            texts: Vec::new(),
            assembler: TextAssembler::default(),
            rtt: None,
            done: None,
        }
    }

    /// Distinct items the vehicle asked for so far.
    #[must_use]
    pub fn sent(&self) -> usize {
        self.asked.iter().filter(|a| **a).count()
    }

    /// Items in the list.
    #[must_use]
    pub fn total(&self) -> usize {
        self.items.len()
    }

    fn count(&mut self, now: Instant) -> MavMessage {
        self.retry.send(now);
        MavMessage::MISSION_COUNT(apm::MISSION_COUNT_DATA {
            count: u16::try_from(self.items.len()).unwrap_or(u16::MAX),
            target_system: self.target.0.0,
            target_component: self.target.1.0,
            mission_type: mission_type(self.kind),
            opaque_id: 0,
        })
    }

    fn no_ack(&mut self) {
        self.done = Some(UploadOutcome::NoAck {
            requested: self.sent(),
            total: self.total(),
        });
    }

    fn requested(&mut self, now: Instant, seq: u16) -> Vec<MavMessage> {
        let Some(item) = self.items.get(usize::from(seq)) else {
            return Vec::new();
        };
        if self.last_heard.is_none()
            && let Some(rtt) = self.retry.first_try_rtt(now)
        {
            self.measured.sample(rtt);
            self.rtt = Some(rtt);
        }
        let msg = MavMessage::MISSION_ITEM_INT(item.clone());
        if let Some((prev, r)) = &self.pending
            && u32::from(*prev) + 1 == u32::from(seq)
            && let Some(rtt) = r.first_try_rtt(now)
        {
            self.measured.sample(rtt);
            self.rtt = Some(rtt);
        }
        self.last_heard = Some(now);
        self.asked[usize::from(seq)] = true;
        let last = usize::from(seq) + 1 == self.items.len();
        let rto = if self.measured.srtt().is_some() {
            self.measured.rto()
        } else {
            self.rto
        };
        let mut r = Retry::new(
            rto,
            MISSION_TRIES,
            if last { LAST_ACK_WAIT } else { UPLOAD_SILENCE },
        );
        r.send(now);
        self.pending = Some((seq, r));
        vec![msg]
    }
}

impl Machine for UploadMachine {
    type Output = UploadOutcome;

    fn start(&mut self, now: Instant) -> Vec<MavMessage> {
        vec![self.count(now)]
    }

    fn on_message(&mut self, now: Instant, m: &Inbound) -> Vec<MavMessage> {
        if self.done.is_some() || (m.sys, m.comp) != self.target || !super::for_me(&m.msg, self.me)
        {
            return Vec::new();
        }
        let ours = mission_type(self.kind);
        match &m.msg {
            MavMessage::MISSION_REQUEST_INT(r) if r.mission_type == ours => {
                self.requested(now, r.seq)
            }
            MavMessage::MISSION_REQUEST(r) if r.mission_type == ours => self.requested(now, r.seq),
            MavMessage::MISSION_ACK(a) if a.mission_type == ours => {
                // An out-of-sequence item (a duplicate) is not the end of the transfer.
                if a.mavtype == MavMissionResult::MAV_MISSION_INVALID_SEQUENCE {
                    return Vec::new();
                }
                let last = u16::try_from(self.items.len().saturating_sub(1)).unwrap_or(u16::MAX);
                let repeated = self
                    .pending
                    .as_ref()
                    .is_some_and(|(seq, r)| *seq == last && r.tries() > 1);
                if a.mavtype == MavMissionResult::MAV_MISSION_ACCEPTED {
                    self.done = Some(UploadOutcome::Acked {
                        result: a.mavtype,
                        reason: None,
                    });
                } else if repeated {
                    // Perhaps the answer to a repeat after the vehicle finished: the download
                    // that follows tells.
                    self.no_ack();
                } else if self.refused.is_none() {
                    self.refused = Some((a.mavtype, now));
                    if !self.texts.is_empty() {
                        self.done = Some(UploadOutcome::Acked {
                            result: a.mavtype,
                            reason: self.texts.last().cloned(),
                        });
                    }
                }
                Vec::new()
            }
            MavMessage::STATUSTEXT(t) => {
                if let Some(text) = self.assembler.push(t) {
                    if let Some((result, _)) = self.refused {
                        self.done = Some(UploadOutcome::Acked {
                            result,
                            reason: Some(text),
                        });
                    } else {
                        // The twin and ArduPilot explain a refusal just before its ACK.
                        self.texts.push(text);
                    }
                }
                Vec::new()
            }
            _ => Vec::new(),
        }
    }

    fn on_time(&mut self, now: Instant) -> Vec<MavMessage> {
        if self.done.is_some() || now < self.deadline() {
            return Vec::new();
        }
        if let Some((result, _)) = self.refused {
            self.done = Some(UploadOutcome::Acked {
                result,
                reason: None,
            });
            return Vec::new();
        }
        if let Some((seq, r)) = &mut self.pending {
            return match r.step(now) {
                Step::Wait => Vec::new(),
                Step::Send => {
                    r.send(now);
                    let k = usize::from(*seq);
                    self.items
                        .iter()
                        .skip(k)
                        .take(2)
                        .map(|i| MavMessage::MISSION_ITEM_INT(i.clone()))
                        .collect()
                }
                Step::GiveUp => {
                    self.no_ack();
                    Vec::new()
                }
            };
        }
        match self.retry.step(now) {
            Step::Wait => Vec::new(),
            Step::Send => vec![self.count(now)],
            Step::GiveUp => {
                self.no_ack();
                Vec::new()
            }
        }
    }

    fn deadline(&self) -> Instant {
        if let Some((_, at)) = self.refused {
            return at + REASON_GRACE;
        }
        match &self.pending {
            Some((_, r)) => r.deadline(),
            None => self.retry.deadline(),
        }
    }

    fn result(&mut self) -> Option<Self::Output> {
        self.done.take()
    }

    fn take_rtt_samples(&mut self) -> Vec<Duration> {
        self.rtt.take().into_iter().collect()
    }
}
