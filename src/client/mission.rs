//! The mission protocol (MAVLink's mission microservice), ground station side, for the
//! mission, fence and rally lists (`mission_type`):
//!
//! - **Upload** ([`UploadMachine`], `mission/upload.rs`): MISSION_COUNT, then each item the
//!   vehicle asks for (MISSION_REQUEST_INT, or MISSION_REQUEST as ArduPilot sends it) answered
//!   with MISSION_ITEM_INT, until its MISSION_ACK. A request late by the round-trip timeout
//!   gets the item last asked for again with the one after it (see `mission/upload.rs`).
//! - **Download** ([`DownloadMachine`], `mission/download.rs`): MISSION_REQUEST_LIST,
//!   MISSION_COUNT, then MISSION_REQUEST_INT for each item, repeated until it arrives
//!   (MISSION_ITEM_INT, or MISSION_ITEM from a vehicle that only has that), and a MISSION_ACK at
//!   the end.
//! - **Clear** ([`ClearMachine`]): MISSION_CLEAR_ALL until its MISSION_ACK.
//! - Set current and start are commands (MAV_CMD_DO_SET_MISSION_CURRENT, MAV_CMD_MISSION_START).
//!
//! Every wait is scaled to the measured round trip ([`super::machine::Rtt`]).

// MISSION_ITEM and MISSION_REQUEST are deprecated by MAVLink and still what ArduPilot sends.
#![allow(deprecated)]

use num_traits::{FromPrimitive, ToPrimitive};
use vtol_link::dialect::{self as apm, MavCmd, MavFrame, MavMissionResult, MavMissionType};
use vtol_link::{ComponentId, SystemId};

use super::{ClientError, ClientHandle};
use crate::mission::{Item, Kind};

mod download;
#[cfg(test)]
mod tests;
mod upload;

pub use download::{DownloadMachine, DownloadStalled};
pub use upload::{UploadMachine, UploadOutcome};

/// Sends of a request before it is given up (as the parameter reads).
pub const MISSION_TRIES: u8 = 12;

/// The dialect's MAV_MISSION_TYPE of a list.
#[must_use]
pub fn mission_type(kind: Kind) -> MavMissionType {
    match kind {
        Kind::Mission => MavMissionType::MAV_MISSION_TYPE_MISSION,
        Kind::Fence => MavMissionType::MAV_MISSION_TYPE_FENCE,
        Kind::Rally => MavMissionType::MAV_MISSION_TYPE_RALLY,
    }
}

/// The MISSION_ITEM_INT that carries `item` as number `seq`; `None` for a command or frame the
/// dialect does not have (refused earlier by [`crate::mission::check`]).
#[must_use]
pub fn to_wire(
    seq: u16,
    item: &Item,
    target: (SystemId, ComponentId),
    kind: Kind,
) -> Option<apm::MISSION_ITEM_INT_DATA> {
    let (x, y) = item.wire_xy();
    Some(apm::MISSION_ITEM_INT_DATA {
        param1: item.params[0],
        param2: item.params[1],
        param3: item.params[2],
        param4: item.params[3],
        x,
        y,
        z: item.z,
        seq,
        command: MavCmd::from_u16(item.command)?,
        target_system: target.0.0,
        target_component: target.1.0,
        frame: MavFrame::from_u8(item.frame)?,
        current: u8::from(item.current),
        autocontinue: u8::from(item.autocontinue),
        mission_type: mission_type(kind),
    })
}

/// The item a MISSION_ITEM_INT carries.
#[must_use]
pub fn from_wire(m: &apm::MISSION_ITEM_INT_DATA) -> Item {
    let mut item = Item {
        frame: m.frame.to_u8().unwrap_or(u8::MAX),
        command: m.command.to_u16().unwrap_or(u16::MAX),
        current: m.current != 0,
        autocontinue: m.autocontinue != 0,
        params: [m.param1, m.param2, m.param3, m.param4],
        x: 0.0,
        y: 0.0,
        z: m.z,
    };
    item.set_wire_xy(m.x, m.y);
    item
}

/// The item a legacy MISSION_ITEM carries (x and y as floats in their units).
#[must_use]
pub fn from_float_wire(m: &apm::MISSION_ITEM_DATA) -> Item {
    Item {
        frame: m.frame.to_u8().unwrap_or(u8::MAX),
        command: m.command.to_u16().unwrap_or(u16::MAX),
        current: m.current != 0,
        autocontinue: m.autocontinue != 0,
        params: [m.param1, m.param2, m.param3, m.param4],
        x: f64::from(m.x),
        y: f64::from(m.y),
        z: m.z,
    }
}

/// Whether a mission message is addressed to `me` (or to all of our system's components):
/// another ground station's transfer on the same link is not ours.
fn for_me(msg: &apm::MavMessage, me: (SystemId, ComponentId)) -> bool {
    use apm::MavMessage as M;
    let (sys, comp) = match msg {
        M::MISSION_REQUEST_INT(r) => (r.target_system, r.target_component),
        M::MISSION_REQUEST(r) => (r.target_system, r.target_component),
        M::MISSION_ACK(a) => (a.target_system, a.target_component),
        M::MISSION_COUNT(c) => (c.target_system, c.target_component),
        M::MISSION_ITEM_INT(i) => (i.target_system, i.target_component),
        M::MISSION_ITEM(i) => (i.target_system, i.target_component),
        _ => return true,
    };
    (sys == 0 || sys == me.0.0) && (comp == 0 || comp == me.1.0)
}

/// A MAV_MISSION_RESULT in words: its name and what it means.
#[must_use]
pub fn result_words(r: MavMissionResult) -> String {
    use MavMissionResult as R;
    let what = match r {
        R::MAV_MISSION_ACCEPTED => "accepted",
        R::MAV_MISSION_ERROR => "generic error",
        R::MAV_MISSION_UNSUPPORTED_FRAME => "coordinate frame not supported",
        R::MAV_MISSION_UNSUPPORTED => "command not supported",
        R::MAV_MISSION_NO_SPACE => "more items than the vehicle can store",
        R::MAV_MISSION_INVALID => "a parameter is invalid",
        R::MAV_MISSION_INVALID_PARAM1 => "param1 is invalid",
        R::MAV_MISSION_INVALID_PARAM2 => "param2 is invalid",
        R::MAV_MISSION_INVALID_PARAM3 => "param3 is invalid",
        R::MAV_MISSION_INVALID_PARAM4 => "param4 is invalid",
        R::MAV_MISSION_INVALID_PARAM5_X => "x / latitude is invalid",
        R::MAV_MISSION_INVALID_PARAM6_Y => "y / longitude is invalid",
        R::MAV_MISSION_INVALID_PARAM7 => "z / altitude is invalid",
        R::MAV_MISSION_INVALID_SEQUENCE => "item out of sequence",
        R::MAV_MISSION_DENIED => "not accepting mission commands now",
        R::MAV_MISSION_OPERATION_CANCELLED => "the transfer was cancelled",
    };
    format!("{r:?} ({what})")
}

/// The whole-list clear: MISSION_CLEAR_ALL until a MISSION_ACK for that list.
#[derive(Debug)]
pub struct ClearMachine {
    target: (SystemId, ComponentId),
    kind: Kind,
    retry: super::machine::Retry,
    done: Option<Option<MavMissionResult>>,
}

impl ClearMachine {
    /// Clears `kind` on `target`.
    #[must_use]
    pub fn new(target: (SystemId, ComponentId), kind: Kind, rto: std::time::Duration) -> Self {
        Self {
            target,
            kind,
            retry: super::machine::Retry::new(rto, MISSION_TRIES, super::machine::GIVE_UP_AFTER),
            done: None,
        }
    }

    fn request(&mut self, now: std::time::Instant) -> apm::MavMessage {
        self.retry.send(now);
        apm::MavMessage::MISSION_CLEAR_ALL(apm::MISSION_CLEAR_ALL_DATA {
            target_system: self.target.0.0,
            target_component: self.target.1.0,
            mission_type: mission_type(self.kind),
        })
    }
}

impl super::machine::Machine for ClearMachine {
    /// The vehicle's result, `None` without an answer.
    type Output = Option<MavMissionResult>;

    fn start(&mut self, now: std::time::Instant) -> Vec<apm::MavMessage> {
        vec![self.request(now)]
    }

    fn on_message(
        &mut self,
        _now: std::time::Instant,
        m: &super::machine::Inbound,
    ) -> Vec<apm::MavMessage> {
        if let apm::MavMessage::MISSION_ACK(a) = &m.msg
            && (m.sys, m.comp) == self.target
            && a.mission_type == mission_type(self.kind)
        {
            self.done = Some(Some(a.mavtype));
        }
        Vec::new()
    }

    fn on_time(&mut self, now: std::time::Instant) -> Vec<apm::MavMessage> {
        match self.retry.step(now) {
            super::machine::Step::Wait => Vec::new(),
            super::machine::Step::Send => vec![self.request(now)],
            super::machine::Step::GiveUp => {
                self.done = Some(None);
                Vec::new()
            }
        }
    }

    fn deadline(&self) -> std::time::Instant {
        self.retry.deadline()
    }

    fn result(&mut self) -> Option<Self::Output> {
        self.done.take()
    }
}

impl ClientHandle {
    /// Uploads `items` as the `kind` list. `progress` gets (items sent, total).
    ///
    /// # Errors
    /// [`ClientError::Usage`] for an item the dialect cannot carry (nothing is sent);
    /// [`ClientError::NoVehicle`], [`ClientError::Link`].
    pub async fn mission_upload(
        &self,
        items: &[Item],
        kind: Kind,
        mut progress: impl FnMut(usize, usize),
    ) -> Result<UploadOutcome, ClientError> {
        let target = self.vehicle().await?;
        let wire = items
            .iter()
            .enumerate()
            .map(|(seq, i)| {
                u16::try_from(seq)
                    .ok()
                    .and_then(|seq| to_wire(seq, i, target, kind))
                    .ok_or_else(|| ClientError::Usage(format!("item {seq} cannot be sent")))
            })
            .collect::<Result<Vec<_>, _>>()?;
        let mut m = UploadMachine::new(self.me, target, kind, wire, self.rto());
        self.drive(&mut m, |m| progress(m.sent(), m.total())).await
    }

    /// Downloads the `kind` list. `progress` gets (items received, total).
    ///
    /// # Errors
    /// [`ClientError::Timeout`] when the transfer stalls; [`ClientError::NoVehicle`],
    /// [`ClientError::Link`].
    pub async fn mission_download(
        &self,
        kind: Kind,
        mut progress: impl FnMut(usize, usize),
    ) -> Result<Vec<Item>, ClientError> {
        let target = self.vehicle().await?;
        let mut m = DownloadMachine::new(self.me, target, kind, self.rto());
        let out = self
            .drive(&mut m, |m| progress(m.received(), m.total()))
            .await?;
        out.map_err(|s| {
            ClientError::Timeout(match s.total {
                None => format!("no MISSION_COUNT for the {} list", kind.name()),
                Some(t) => format!("download stalled at item {} of {t}", s.received),
            })
        })
    }

    /// Clears the `kind` list.
    ///
    /// # Errors
    /// [`ClientError::Refused`] with the vehicle's result in words; [`ClientError::Timeout`].
    pub async fn mission_clear(&self, kind: Kind) -> Result<(), ClientError> {
        let target = self.vehicle().await?;
        let mut m = ClearMachine::new(target, kind, self.rto());
        match self.drive(&mut m, |_| {}).await? {
            Some(MavMissionResult::MAV_MISSION_ACCEPTED) => Ok(()),
            Some(r) => Err(ClientError::Refused {
                reason: result_words(r),
            }),
            None => Err(ClientError::Timeout(
                "no MISSION_ACK to MISSION_CLEAR_ALL".into(),
            )),
        }
    }

    /// Makes `seq` the item the mission flies next (MAV_CMD_DO_SET_MISSION_CURRENT).
    ///
    /// # Errors
    /// As [`ClientHandle::command_long`], and a refusal with the vehicle's reason.
    pub async fn mission_set_current(&self, seq: u16) -> Result<(), ClientError> {
        self.command_ok(
            MavCmd::MAV_CMD_DO_SET_MISSION_CURRENT,
            [f32::from(seq), 0.0, 0.0, 0.0, 0.0, 0.0, 0.0],
        )
        .await
    }

    /// Starts the mission (MAV_CMD_MISSION_START), at `first` when given: ArduPlane switches to
    /// AUTO; it does not arm.
    ///
    /// # Errors
    /// As [`ClientHandle::mission_set_current`].
    pub async fn mission_start(&self, first: Option<u16>) -> Result<(), ClientError> {
        let first = first.map_or(0.0, f32::from);
        self.command_ok(
            MavCmd::MAV_CMD_MISSION_START,
            [first, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0],
        )
        .await
    }
}
