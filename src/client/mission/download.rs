//! The download as a state machine: MISSION_REQUEST_LIST until MISSION_COUNT, then each item
//! by MISSION_REQUEST_INT, asked again on the round-trip timeout (backing off as every request
//! does) until it arrives, then MISSION_ACK. An item that arrives as MISSION_ITEM (a vehicle
//! without MISSION_ITEM_INT) is taken as well.

use std::time::{Duration, Instant};

use vtol_link::dialect::{self as apm, MavMessage, MavMissionResult};
use vtol_link::{ComponentId, SystemId};

use super::super::machine::{GIVE_UP_AFTER, Inbound, Machine, Retry, Rtt, Step};
use super::{MISSION_TRIES, from_float_wire, from_wire, mission_type};
use crate::mission::{Item, Kind};

/// Where a download stopped.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct DownloadStalled {
    /// Items received.
    pub received: usize,
    /// The count, if it came.
    pub total: Option<usize>,
}

/// The download exchange.
#[derive(Debug)]
pub struct DownloadMachine {
    me: (SystemId, ComponentId),
    target: (SystemId, ComponentId),
    kind: Kind,
    rto: Duration,
    retry: Retry,
    total: Option<u16>,
    items: Vec<Item>,
    rtt: Vec<Duration>,
    measured: Rtt,
    done: Option<Result<Vec<Item>, DownloadStalled>>,
}

impl DownloadMachine {
    /// Downloads the `kind` list of `target`; `me` is who its answers are addressed to.
    #[must_use]
    pub fn new(
        me: (SystemId, ComponentId),
        target: (SystemId, ComponentId),
        kind: Kind,
        rto: Duration,
    ) -> Self {
        Self {
            me,
            target,
            kind,
            rto,
            retry: Retry::new(rto, MISSION_TRIES, GIVE_UP_AFTER),
            total: None,
            items: Vec::new(),
            rtt: Vec::new(),
            measured: Rtt::default(),
            done: None,
        }
    }

    /// Items received so far.
    #[must_use]
    pub fn received(&self) -> usize {
        self.items.len()
    }

    /// The count, once known (0 before).
    #[must_use]
    pub fn total(&self) -> usize {
        self.total.map_or(0, usize::from)
    }

    fn request(&mut self, now: Instant) -> MavMessage {
        self.retry.send(now);
        let (target_system, target_component) = (self.target.0.0, self.target.1.0);
        let mission_type = mission_type(self.kind);
        match self.total {
            None => MavMessage::MISSION_REQUEST_LIST(apm::MISSION_REQUEST_LIST_DATA {
                target_system,
                target_component,
                mission_type,
            }),
            Some(_) => MavMessage::MISSION_REQUEST_INT(apm::MISSION_REQUEST_INT_DATA {
                seq: u16::try_from(self.items.len()).unwrap_or(u16::MAX),
                target_system,
                target_component,
                mission_type,
            }),
        }
    }

    /// An answer arrived: note its round trip, then ask for what comes next (or finish).
    fn next(&mut self, now: Instant) -> Vec<MavMessage> {
        if let Some(rtt) = self.retry.first_try_rtt(now) {
            self.rtt.push(rtt);
            self.measured.sample(rtt);
        }
        if self.items.len() >= self.total() {
            self.done = Some(Ok(std::mem::take(&mut self.items)));
            return vec![MavMessage::MISSION_ACK(apm::MISSION_ACK_DATA {
                target_system: self.target.0.0,
                target_component: self.target.1.0,
                mavtype: MavMissionResult::MAV_MISSION_ACCEPTED,
                mission_type: mission_type(self.kind),
                opaque_id: 0,
            })];
        }
        self.retry = Retry::new(self.rto_now(), MISSION_TRIES, GIVE_UP_AFTER);
        vec![self.request(now)]
    }

    /// The timeout for the next request: the one given, or what this transfer measured.
    fn rto_now(&self) -> Duration {
        if self.measured.srtt().is_some() {
            self.measured.rto()
        } else {
            self.rto
        }
    }

    fn take_item(&mut self, now: Instant, seq: u16, item: Item) -> Vec<MavMessage> {
        if self.total.is_none() || usize::from(seq) != self.items.len() {
            return Vec::new();
        }
        self.items.push(item);
        self.next(now)
    }
}

impl Machine for DownloadMachine {
    type Output = Result<Vec<Item>, DownloadStalled>;

    fn start(&mut self, now: Instant) -> Vec<MavMessage> {
        vec![self.request(now)]
    }

    fn on_message(&mut self, now: Instant, m: &Inbound) -> Vec<MavMessage> {
        if self.done.is_some() || (m.sys, m.comp) != self.target || !super::for_me(&m.msg, self.me)
        {
            return Vec::new();
        }
        let ours = mission_type(self.kind);
        match &m.msg {
            MavMessage::MISSION_COUNT(c) if c.mission_type == ours && self.total.is_none() => {
                self.total = Some(c.count);
                self.next(now)
            }
            MavMessage::MISSION_ITEM_INT(i) if i.mission_type == ours => {
                self.take_item(now, i.seq, from_wire(i))
            }
            MavMessage::MISSION_ITEM(i) if i.mission_type == ours => {
                self.take_item(now, i.seq, from_float_wire(i))
            }
            _ => Vec::new(),
        }
    }

    fn on_time(&mut self, now: Instant) -> Vec<MavMessage> {
        if self.done.is_some() {
            return Vec::new();
        }
        match self.retry.step(now) {
            Step::Wait => Vec::new(),
            Step::Send => vec![self.request(now)],
            Step::GiveUp => {
                self.done = Some(Err(DownloadStalled {
                    received: self.items.len(),
                    total: self.total.map(usize::from),
                }));
                Vec::new()
            }
        }
    }

    fn deadline(&self) -> Instant {
        self.retry.deadline()
    }

    fn result(&mut self) -> Option<Self::Output> {
        self.done.take()
    }

    fn take_rtt_samples(&mut self) -> Vec<Duration> {
        std::mem::take(&mut self.rtt)
    }
}
