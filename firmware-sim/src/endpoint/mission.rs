//! The mission protocol (mavlink-devguide `services/mission.md`), vehicle side.
//!
//! - **Upload**: MISSION_COUNT → MISSION_REQUEST(0), MISSION_ITEM_INT(0) → MISSION_REQUEST(1) …
//!   → MISSION_ACK (requests as ArduPilot sends them, see `request_item`). Each item is checked
//!   as it arrives ([`crate::nav::mission::check_item`]); the first refused one ends the upload with
//!   its `MAV_MISSION_RESULT` and a STATUSTEXT saying why, and the stored mission stays as it
//!   was. Only a complete, accepted upload replaces it (and is saved beside the parameter file).
//!   Requests are repeated after [`RETRY_US`] of silence and the upload is cancelled after
//!   [`TIMEOUT_US`], counted in the endpoint's stream time (wall time when served, sim time
//!   under lockstep), so a ground station has as long to answer at any speed. One upload at a time: another ground station's MISSION_COUNT
//!   meanwhile gets `MAV_MISSION_DENIED`. MISSION_ITEM (floats) is accepted as well as
//!   MISSION_ITEM_INT.
//! - **Download**: MISSION_REQUEST_LIST → MISSION_COUNT; every MISSION_REQUEST_INT (or legacy
//!   MISSION_REQUEST) is answered with the item as stored, in MISSION_ITEM_INT (or
//!   MISSION_ITEM), so any order, repeats and retries work without a transfer state.
//! - MISSION_CLEAR_ALL, MISSION_SET_CURRENT (answered with MISSION_CURRENT); MISSION_CURRENT
//!   and MISSION_ITEM_REACHED go to every link as the mission is flown.
//! - Fences and rally points (mission types 1 and 2): the twin has none; a download gets a count
//!   of 0, an upload of anything but nothing is refused (`MAV_MISSION_UNSUPPORTED`).
//!
//! Items are read from and written as raw payloads: the `mavlink` crate's typed decoder rejects
//! a command or frame its enums lack, and an unsupported item must still get its refusal.
//! Replies address the sender's system and component (MAVProxy ignores requests for others).

use mavlink::dialects::ardupilotmega as apm;

use super::{Endpoint, Frame, LinkKey};
use crate::nav::mission::{
    MAX_ITEMS, Mission, MissionItem, check_item, xy_from_float, xy_to_float,
};

/// Silence after which the next item is requested again, µs of stream time.
pub const RETRY_US: u64 = 1_000_000;
/// Silence after which an upload is cancelled, µs of stream time (ArduPilot: 8 s).
pub const TIMEOUT_US: u64 = 8_000_000;

/// MISSION_ITEM (deprecated by MAVLink, still sent by older ground stations).
pub const MISSION_ITEM_ID: u32 = vtol_link::protocol::id::MISSION_ITEM;
/// MISSION_ITEM_INT.
pub const MISSION_ITEM_INT_ID: u32 = vtol_link::protocol::id::MISSION_ITEM_INT;

/// `MAV_MISSION_TYPE_MISSION`, as the raw byte the item messages carry.
const TYPE_MISSION: u8 = apm::MavMissionType::MAV_MISSION_TYPE_MISSION as u8;
/// `MAV_MISSION_TYPE_ALL`, likewise.
const TYPE_ALL: u8 = apm::MavMissionType::MAV_MISSION_TYPE_ALL as u8;
/// `current` of a MISSION_ITEM that is ArduPilot's guided waypoint, not part of an upload.
const GUIDED_WAYPOINT: u8 = 2;

/// An upload in progress.
#[derive(Debug, Clone)]
pub struct Upload {
    link: LinkKey,
    /// The uploading ground station (system, component).
    partner: (u8, u8),
    count: u16,
    items: Vec<MissionItem>,
    last_heard_us: u64,
    last_request_us: u64,
}

/// The last finished upload, to answer a repeated final item with the same MISSION_ACK.
#[derive(Debug, Clone, Copy)]
pub struct Finished {
    partner: (u8, u8),
    count: u16,
    result: apm::MavMissionResult,
}

/// A MISSION_ITEM or MISSION_ITEM_INT read from its raw payload.
#[derive(Debug, Clone, Copy)]
pub struct RawItem {
    /// Sequence number.
    pub seq: u16,
    /// Addressed system.
    pub target_system: u8,
    /// Addressed component.
    pub target_component: u8,
    /// `MAV_MISSION_TYPE`.
    pub mission_type: u8,
    /// The item (x, y converted to integers for MISSION_ITEM).
    pub item: MissionItem,
}

fn f32_at(p: &[u8], i: usize) -> f32 {
    f32::from_le_bytes([p[i], p[i + 1], p[i + 2], p[i + 3]])
}

fn i32_at(p: &[u8], i: usize) -> i32 {
    i32::from_le_bytes([p[i], p[i + 1], p[i + 2], p[i + 3]])
}

/// Reads a MISSION_ITEM_INT (73) or MISSION_ITEM (39) frame.
#[must_use]
pub fn raw_item(frame: &Frame) -> Option<RawItem> {
    if frame.message_id() != MISSION_ITEM_INT_ID && frame.message_id() != MISSION_ITEM_ID {
        return None;
    }
    // param1..4, x, y, z (4 bytes each), seq, command (u16), target sys/comp, frame, current,
    // autocontinue, mission_type (extension).
    let p: [u8; 38] = frame.payload_padded();
    let frame_no = p[34];
    let (x, y) = if frame.message_id() == MISSION_ITEM_INT_ID {
        (i32_at(&p, 16), i32_at(&p, 20))
    } else {
        (
            xy_from_float(frame_no, f64::from(f32_at(&p, 16))),
            xy_from_float(frame_no, f64::from(f32_at(&p, 20))),
        )
    };
    Some(RawItem {
        seq: u16::from_le_bytes([p[28], p[29]]),
        target_system: p[32],
        target_component: p[33],
        mission_type: p[37],
        item: MissionItem {
            params: [f32_at(&p, 0), f32_at(&p, 4), f32_at(&p, 8), f32_at(&p, 12)],
            x,
            y,
            z: f32_at(&p, 24),
            command: u16::from_le_bytes([p[30], p[31]]),
            frame: frame_no,
            current: p[35],
            autocontinue: p[36],
        },
    })
}

/// The payload of MISSION_ITEM_INT (or, `int` false, MISSION_ITEM) carrying `item`.
#[must_use]
pub fn item_payload(seq: u16, item: &MissionItem, target: (u8, u8), int: bool) -> [u8; 38] {
    let mut p = [0u8; 38];
    for (k, v) in item.params.iter().enumerate() {
        p[4 * k..4 * k + 4].copy_from_slice(&v.to_le_bytes());
    }
    if int {
        p[16..20].copy_from_slice(&item.x.to_le_bytes());
        p[20..24].copy_from_slice(&item.y.to_le_bytes());
    } else {
        let x = xy_to_float(item.frame, item.x) as f32;
        let y = xy_to_float(item.frame, item.y) as f32;
        p[16..20].copy_from_slice(&x.to_le_bytes());
        p[20..24].copy_from_slice(&y.to_le_bytes());
    }
    p[24..28].copy_from_slice(&item.z.to_le_bytes());
    p[28..30].copy_from_slice(&seq.to_le_bytes());
    p[30..32].copy_from_slice(&item.command.to_le_bytes());
    p[32] = target.0;
    p[33] = target.1;
    p[34] = item.frame;
    p[35] = item.current;
    p[36] = item.autocontinue;
    p[37] = TYPE_MISSION;
    p
}

/// The mission type a raw byte names; a number the dialect lacks is answered as the mission.
fn mission_type(t: u8) -> apm::MavMissionType {
    use num_traits::FromPrimitive as _;
    apm::MavMissionType::from_u8(t).unwrap_or(apm::MavMissionType::MAV_MISSION_TYPE_MISSION)
}

impl Endpoint {
    fn mission_ack(
        &mut self,
        link: LinkKey,
        to: (u8, u8),
        kind: u8,
        result: apm::MavMissionResult,
    ) {
        let msg = apm::MavMessage::MISSION_ACK(apm::MISSION_ACK_DATA {
            target_system: to.0,
            target_component: to.1,
            mavtype: result,
            mission_type: mission_type(kind),
            opaque_id: 0,
        });
        self.send(link, &msg);
    }

    /// Asks for item `seq` with MISSION_REQUEST, as ArduPilot does (the devguide prefers
    /// MISSION_REQUEST_INT, but scripts written against SITL wait for MISSION_REQUEST, and
    /// every ground station answers it, MAVProxy and Mission Planner with MISSION_ITEM_INT).
    #[allow(deprecated)]
    fn request_item(&mut self, link: LinkKey, to: (u8, u8), seq: u16) {
        let msg = apm::MavMessage::MISSION_REQUEST(apm::MISSION_REQUEST_DATA {
            seq,
            target_system: to.0,
            target_component: to.1,
            mission_type: apm::MavMissionType::MAV_MISSION_TYPE_MISSION,
        });
        self.send(link, &msg);
    }

    /// Handles the mission messages that must be read raw (MISSION_ITEM, MISSION_ITEM_INT).
    /// Returns whether the frame was one of them.
    pub(super) fn mission_raw(&mut self, link: LinkKey, frame: &Frame) -> bool {
        let Some(r) = raw_item(frame) else {
            return false;
        };
        if self.for_us(Some(r.target_system), Some(r.target_component)) {
            self.on_mission_item(link, frame, &r);
        } else {
            self.stats.not_for_us += 1;
        }
        true
    }

    // Long: the MISSION_ITEM(_INT) rules of the upload protocol in the order ArduPilot applies them
    // (type, guided waypoint, partner, sequence, item check, completion), each ending the handling.
    fn on_mission_item(&mut self, link: LinkKey, frame: &Frame, r: &RawItem) {
        use apm::MavMissionResult as R;
        let from = (frame.system_id(), frame.component_id());
        if r.mission_type != TYPE_MISSION {
            self.mission_ack(link, from, r.mission_type, R::MAV_MISSION_UNSUPPORTED);
            return;
        }
        if r.item.current == GUIDED_WAYPOINT {
            let result = match self.guided_item(&r.item) {
                Ok(()) => R::MAV_MISSION_ACCEPTED,
                Err(why) => {
                    self.say(link, apm::MavSeverity::MAV_SEVERITY_WARNING, &why);
                    R::MAV_MISSION_ERROR
                }
            };
            self.mission_ack(link, from, TYPE_MISSION, result);
            return;
        }
        let now = self.stream_now_us;
        let (expected, count) = match self.upload.as_mut().filter(|u| u.partner == from) {
            Some(up) => {
                up.last_heard_us = now;
                (up.items.len() as u16, up.count)
            }
            None => {
                // A repeated final item (our ACK was lost): the same ACK again. Anything else
                // outside an upload is stale and ignored.
                if let Some(f) = self.finished
                    && f.partner == from
                    && u32::from(r.seq) + 1 == u32::from(f.count)
                {
                    self.mission_ack(link, from, TYPE_MISSION, f.result);
                }
                return;
            }
        };
        if r.seq != expected {
            // Ahead of us: ask again for the one we need. Behind: a repeat of an item we
            // have, and the request for the next is on its way.
            if r.seq > expected {
                self.request_next(link, from, expected);
            }
            return;
        }
        if r.seq >= 1 {
            let limits = self.limits();
            if let Err(refusal) = check_item(r.seq, &r.item, &limits) {
                self.upload = None;
                self.finished = Some(Finished {
                    partner: from,
                    count,
                    result: refusal.result,
                });
                self.mission_ack(link, from, TYPE_MISSION, refusal.result);
                self.say(
                    link,
                    apm::MavSeverity::MAV_SEVERITY_WARNING,
                    &refusal.reason,
                );
                return;
            }
        }
        let Some(up) = self.upload.as_mut() else {
            return;
        };
        up.items.push(r.item);
        if up.items.len() < usize::from(count) {
            self.request_next(link, from, expected + 1);
            return;
        }
        // Complete: the new mission replaces the stored one.
        let items = std::mem::take(&mut up.items);
        self.upload = None;
        self.finished = Some(Finished {
            partner: from,
            count,
            result: R::MAV_MISSION_ACCEPTED,
        });
        self.replace_mission(Mission::new(items));
        self.mission_ack(link, from, TYPE_MISSION, R::MAV_MISSION_ACCEPTED);
        self.say(
            link,
            apm::MavSeverity::MAV_SEVERITY_INFO,
            &format!("Flight plan received ({count} items)"),
        );
    }

    /// Requests item `seq` of the upload in progress and restarts its retry timer.
    fn request_next(&mut self, link: LinkKey, to: (u8, u8), seq: u16) {
        if let Some(up) = self.upload.as_mut() {
            up.last_request_us = self.stream_now_us;
        }
        self.request_item(link, to, seq);
    }

    /// Stores a new mission (saving it beside the parameter file) and restarts it at item 1.
    fn replace_mission(&mut self, mission: Mission) {
        self.mission = mission;
        self.persist_mission();
        self.finish_mission_change();
    }

    fn persist_mission(&mut self) {
        let Some(path) = self.mission_file.clone() else {
            return;
        };
        if let Err(e) = self.mission.save(&path) {
            tracing::warn!("saving the mission: {e}");
            self.announce(
                apm::MavSeverity::MAV_SEVERITY_WARNING,
                "Mission save failed",
            );
        }
    }

    pub(super) fn on_mission_count(
        &mut self,
        link: LinkKey,
        frame: &Frame,
        m: &apm::MISSION_COUNT_DATA,
    ) {
        use apm::MavMissionResult as R;
        let from = (frame.system_id(), frame.component_id());
        let kind = m.mission_type as u8;
        if kind != TYPE_MISSION {
            let result = if m.count == 0 {
                R::MAV_MISSION_ACCEPTED
            } else {
                R::MAV_MISSION_UNSUPPORTED
            };
            self.mission_ack(link, from, kind, result);
            return;
        }
        if let Some(up) = &self.upload
            && up.partner != from
            && self.stream_now_us.saturating_sub(up.last_heard_us) < TIMEOUT_US
        {
            self.mission_ack(link, from, kind, R::MAV_MISSION_DENIED);
            self.say(
                link,
                apm::MavSeverity::MAV_SEVERITY_WARNING,
                "Mission upload refused: another upload is in progress",
            );
            return;
        }
        self.upload = None;
        if m.count == 0 {
            self.replace_mission(Mission::default());
            self.mission_ack(link, from, kind, R::MAV_MISSION_ACCEPTED);
            return;
        }
        if m.count > MAX_ITEMS {
            self.mission_ack(link, from, kind, R::MAV_MISSION_NO_SPACE);
            self.say(
                link,
                apm::MavSeverity::MAV_SEVERITY_WARNING,
                &format!("Mission of {} items refused: at most {MAX_ITEMS}", m.count),
            );
            return;
        }
        self.finished = None;
        self.upload = Some(Upload {
            link,
            partner: from,
            count: m.count,
            items: Vec::with_capacity(usize::from(m.count)),
            last_heard_us: self.stream_now_us,
            last_request_us: self.stream_now_us,
        });
        self.request_item(link, from, 0);
    }

    pub(super) fn on_mission_request_list(
        &mut self,
        link: LinkKey,
        frame: &Frame,
        m: &apm::MISSION_REQUEST_LIST_DATA,
    ) {
        let kind = m.mission_type as u8;
        let count = if kind == TYPE_MISSION {
            self.mission.count()
        } else {
            0
        };
        let msg = apm::MavMessage::MISSION_COUNT(apm::MISSION_COUNT_DATA {
            count,
            target_system: frame.system_id(),
            target_component: frame.component_id(),
            mission_type: m.mission_type,
            opaque_id: 0,
        });
        self.send(link, &msg);
    }

    /// MISSION_REQUEST_INT (`int`) or MISSION_REQUEST: the item, in the same flavour.
    pub(super) fn on_mission_request(
        &mut self,
        link: LinkKey,
        frame: &Frame,
        seq: u16,
        kind: u8,
        int: bool,
    ) {
        let to = (frame.system_id(), frame.component_id());
        // Item 0 is always the current home, whatever an upload put in the slot and also with
        // no mission stored (ArduPilot writes home into it whenever home is set).
        let item = if kind == TYPE_MISSION && seq == 0 {
            Some(self.home_item())
        } else {
            (kind == TYPE_MISSION)
                .then(|| self.mission.get(seq).copied())
                .flatten()
        };
        match item {
            Some(item) => {
                let payload = item_payload(seq, &item, to, int);
                let id = if int {
                    MISSION_ITEM_INT_ID
                } else {
                    MISSION_ITEM_ID
                };
                self.send_raw(link, id, &payload);
            }
            None => self.mission_ack(
                link,
                to,
                kind,
                apm::MavMissionResult::MAV_MISSION_INVALID_SEQUENCE,
            ),
        }
    }

    pub(super) fn on_mission_clear_all(
        &mut self,
        link: LinkKey,
        frame: &Frame,
        m: &apm::MISSION_CLEAR_ALL_DATA,
    ) {
        let kind = m.mission_type as u8;
        if kind == TYPE_MISSION || kind == TYPE_ALL {
            self.upload = None;
            self.replace_mission(Mission::default());
        }
        self.mission_ack(
            link,
            (frame.system_id(), frame.component_id()),
            kind,
            apm::MavMissionResult::MAV_MISSION_ACCEPTED,
        );
    }

    /// MISSION_WRITE_PARTIAL_LIST: partial updates are not offered.
    pub(super) fn on_mission_partial(&mut self, link: LinkKey, frame: &Frame, kind: u8) {
        self.mission_ack(
            link,
            (frame.system_id(), frame.component_id()),
            kind,
            apm::MavMissionResult::MAV_MISSION_UNSUPPORTED,
        );
    }

    /// Repeats the request of a stalled upload; cancels one that went silent.
    pub(super) fn mission_timeouts(&mut self) {
        let Some(up) = &mut self.upload else {
            return;
        };
        let now = self.stream_now_us;
        if now.saturating_sub(up.last_heard_us) >= TIMEOUT_US {
            let (link, to) = (up.link, up.partner);
            self.upload = None;
            self.mission_ack(
                link,
                to,
                TYPE_MISSION,
                apm::MavMissionResult::MAV_MISSION_OPERATION_CANCELLED,
            );
            self.say(
                link,
                apm::MavSeverity::MAV_SEVERITY_WARNING,
                "Mission upload timed out",
            );
        } else if now.saturating_sub(up.last_request_us) >= RETRY_US {
            up.last_request_us = now;
            let (link, to, next) = (up.link, up.partner, up.items.len() as u16);
            self.request_item(link, to, next);
        }
    }

    /// MISSION_CURRENT as it stands.
    pub(super) fn mission_current(&self) -> apm::MavMessage {
        use crate::nav::navigation::MissionState as S;
        let count = self.mission.count();
        let state = match self.navigator.mission_state(count) {
            S::NoMission => apm::MissionState::MISSION_STATE_NO_MISSION,
            S::NotStarted => apm::MissionState::MISSION_STATE_NOT_STARTED,
            S::Active => apm::MissionState::MISSION_STATE_ACTIVE,
            S::Paused => apm::MissionState::MISSION_STATE_PAUSED,
            S::Complete => apm::MissionState::MISSION_STATE_COMPLETE,
        };
        apm::MavMessage::MISSION_CURRENT(apm::MISSION_CURRENT_DATA {
            seq: self.navigator.current(),
            // Items after the home slot; UINT16_MAX = no mission (common.xml).
            total: count.checked_sub(1).unwrap_or(u16::MAX),
            mission_state: state,
            mission_mode: u8::from(
                self.vehicle.telemetry().mode == crate::model::mode::FlightMode::Auto,
            ),
            mission_id: 0,
            fence_id: 0,
            rally_points_id: 0,
        })
    }

    /// MISSION_ITEM_REACHED on every link.
    pub(super) fn item_reached(&mut self, seq: u16) {
        let msg = apm::MavMessage::MISSION_ITEM_REACHED(apm::MISSION_ITEM_REACHED_DATA { seq });
        self.broadcast(&msg);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::endpoint::test_support::from_gcs;

    #[test]
    fn item_payload_round_trips_raw() {
        let item = MissionItem {
            params: [1.0, f32::NAN, -0.0, 3.25],
            x: -353_632_610,
            y: 1_491_652_300,
            z: 2.5,
            command: 65000,
            frame: 6,
            current: 1,
            autocontinue: 1,
        };
        let p = item_payload(4, &item, (1, 1), true);
        let f = from_gcs(0, MISSION_ITEM_INT_ID, &p);
        let r = raw_item(&f).unwrap();
        assert_eq!((r.seq, r.target_system, r.target_component), (4, 1, 1));
        assert_eq!(r.item, item);
        // MISSION_ITEM: degrees as floats, back to 1e-7 degree within float32 precision.
        let p = item_payload(4, &item, (1, 1), false);
        let f = from_gcs(0, MISSION_ITEM_ID, &p);
        let r = raw_item(&f).unwrap();
        assert!((r.item.x - item.x).abs() < 40, "{} vs {}", r.item.x, item.x);
        assert_eq!(r.item.command, 65000);
    }
}
