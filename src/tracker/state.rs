//! What the daemon knows about each vehicle and each link, built by applying frames one at a
//! time. Pure: `apply` takes the frame and the time it arrived, so it tests without sockets.

use std::collections::{BTreeMap, VecDeque};
use std::time::{Duration, Instant};

use foldhash::{HashMap, HashSet};
use vtol_link::dialect::{
    MavAutopilot, MavMessage, MavModeFlag, MavState, MavType, SERVO_OUTPUT_RAW_DATA,
};
use vtol_link::protocol::id::{ATTITUDE, LOCAL_POSITION_NED, SERVO_OUTPUT_RAW, STATUSTEXT};
use vtol_link::{ComponentId, Frame, LinkId, SystemId};

use super::seq::Seen;
use super::window::{Stamp, Window};
use crate::links::Side;

/// ATTITUDE, LOCAL_POSITION_NED, SERVO_OUTPUT_RAW, STATUSTEXT: the messages the view holds.
const TRACKED: [u32; 4] = [ATTITUDE, LOCAL_POSITION_NED, SERVO_OUTPUT_RAW, STATUSTEXT];

/// How many status texts a vehicle keeps.
pub const STATUS_TEXTS_KEPT: usize = 32;
/// A link with no traffic for this long is shown as lost (MAVProxy's default timeout).
pub const LINK_TIMEOUT: Duration = Duration::from_secs(5);

/// How many links that went down the state remembers (to ignore their frames still on the way).
/// Their frames reach the tracker within a tick of their Down; a fleet's departures are many.
pub const DOWN_MEMORY: usize = 1024;

/// Attitude in NED, radians and rad/s.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Attitude {
    /// Roll, pitch, yaw.
    pub rpy_rad: [f32; 3],
    /// Body rates.
    pub rates_rad_s: [f32; 3],
    /// Vehicle boot time of the sample.
    pub time_boot_ms: u32,
}

/// Local position in NED, m and m/s.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct LocalPosition {
    /// x, y, z (z down).
    pub pos_ned_m: [f32; 3],
    /// vx, vy, vz.
    pub vel_ned_m_s: [f32; 3],
}

/// One vehicle's latest state.
#[derive(Debug, Clone, PartialEq)]
pub struct VehicleView {
    /// System id.
    pub system_id: SystemId,
    /// Component id.
    pub component_id: ComponentId,
    /// The link it was last heard on.
    pub link: LinkId,
    /// Its frames received (all message types, this vehicle only).
    pub frames: u64,
    /// Its frames missing by sequence gaps.
    pub lost: u64,
    /// Its frames received and lost over the last seconds: this vehicle's link health, apart
    /// from other vehicles sharing the link.
    pub window: Window,
    /// MAV_TYPE as the heartbeat gave it (a value the dialect lacks included).
    pub mav_type: u8,
    /// MAV_AUTOPILOT as the heartbeat gave it.
    pub autopilot: u8,
    /// custom_mode.
    pub custom_mode: u32,
    /// Armed bit of the last heartbeat.
    pub armed: bool,
    /// system_status.
    pub system_status: MavState,
    /// Latest attitude.
    pub attitude: Option<Attitude>,
    /// Latest local position.
    pub position: Option<LocalPosition>,
    /// servo1..16 of SERVO_OUTPUT_RAW, µs (0 = unused).
    pub servo_us: [u16; 16],
    /// Last status texts, oldest first: (severity, text).
    pub status_texts: VecDeque<(u8, String)>,
    /// When the last heartbeat arrived.
    pub last_heartbeat: Instant,
    /// The link of its last heartbeat went down (and no heartbeat came since): lost at once,
    /// not after [`LINK_TIMEOUT`].
    pub link_down: bool,
    /// When the vehicle was last seen to arm (None while disarmed): the flight time's start.
    pub armed_since: Option<Instant>,
    /// Reboots seen: ATTITUDE's `time_boot_ms` went back (the vehicle's clock restarted).
    pub reboots: u32,
    /// The last reboot: `time_boot_ms` before and after it, and when it was seen.
    pub last_reboot: Option<Reboot>,
}

/// A vehicle reboot, seen as its boot clock going back.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Reboot {
    /// The last `time_boot_ms` before the reboot.
    pub before_ms: u32,
    /// The first `time_boot_ms` after it.
    pub after_ms: u32,
    /// When the tracker saw it.
    pub at: Instant,
}

impl VehicleView {
    /// Whether no heartbeat came for [`LINK_TIMEOUT`], or the link it came on went down.
    #[must_use]
    pub fn is_lost(&self, now: Instant) -> bool {
        self.link_down || now.duration_since(self.last_heartbeat) >= LINK_TIMEOUT
    }

    /// One line of its state for a list of vehicles: id, mode, armed, frame rate and loss
    /// (`1 QHOVER ARMED 50 Hz 0.0%`).
    #[must_use]
    pub fn summary(&self, now: Instant) -> String {
        format!(
            "{} {} {} {:.0} Hz {:.1}%",
            self.system_id,
            self.mode_name(),
            crate::words::armed(self.armed),
            self.window.rate_hz(now),
            self.window.loss_pct(now)
        )
    }

    /// The mode's name for this vehicle's autopilot and type (`QHOVER` on ArduPlane, `LOITER`
    /// on ArduCopter, `POSCTL` on PX4), or `MODE(n)`.
    #[must_use]
    pub fn mode_name(&self) -> String {
        crate::modes::mode_name(self.autopilot, self.mav_type, self.custom_mode)
    }

    /// What the vehicle is (`ArduPlane`, `PX4 quadrotor`, or its numbers).
    #[must_use]
    pub fn kind(&self) -> String {
        crate::modes::vehicle_name(self.autopilot, self.mav_type)
    }
}

/// A SERVO_OUTPUT_RAW's 16 outputs, µs, in channel order.
#[must_use]
pub fn servo_outputs(s: &SERVO_OUTPUT_RAW_DATA) -> [u16; 16] {
    [
        s.servo1_raw,
        s.servo2_raw,
        s.servo3_raw,
        s.servo4_raw,
        s.servo5_raw,
        s.servo6_raw,
        s.servo7_raw,
        s.servo8_raw,
        s.servo9_raw,
        s.servo10_raw,
        s.servo11_raw,
        s.servo12_raw,
        s.servo13_raw,
        s.servo14_raw,
        s.servo15_raw,
        s.servo16_raw,
    ]
}

/// Names of ArduPlane's mode numbers (what pymavlink's `mode_mapping_apm` holds).
#[must_use]
pub fn plane_mode_name(mode: u32) -> Option<&'static str> {
    crate::modes::PLANE
        .iter()
        .find(|(_, n)| *n == mode)
        .map(|(name, _)| *name)
}

/// Health of one link, from what arrived on it.
#[derive(Debug, Clone, PartialEq)]
pub struct LinkHealth {
    /// Vehicle or client side.
    pub side: Side,
    /// Frames received since the link came up.
    pub frames: u64,
    /// Frames missing by sequence gaps since the link came up.
    pub lost: u64,
    /// When the last frame arrived.
    pub last_heard: Instant,
    /// Received and lost over the last seconds.
    pub window: Window,
    /// Bytes of the frames received over the last seconds (as `received`).
    pub bytes: Window,
}

impl LinkHealth {
    /// Bytes of frames per second over the last 2 s: what the link delivers.
    #[must_use]
    pub fn bytes_per_s(&self, now: Instant) -> f64 {
        self.bytes.rate_hz(now)
    }

    /// Whether the link has been silent for [`LINK_TIMEOUT`].
    #[must_use]
    pub fn is_lost(&self, now: Instant) -> bool {
        now.duration_since(self.last_heard) >= LINK_TIMEOUT
    }
}

/// One message id from one sender, as a message inspector lists it.
#[derive(Debug, Clone, PartialEq)]
pub struct MessageStats {
    /// Frames received.
    pub count: u64,
    /// The latest frame (decoded on demand by the view).
    pub last: Frame,
    /// When it arrived.
    pub last_at: Instant,
    /// Arrivals over the last seconds.
    pub window: Window,
}

/// Everything the tracker knows; published as a snapshot.
#[derive(Debug, Clone)]
pub struct VehicleState {
    /// The time windows count from (when the tracker started).
    pub epoch: Instant,
    /// Vehicles by (system, component); the router never lets two vehicle links share a
    /// system id, so each entry is one vehicle.
    pub vehicles: BTreeMap<(SystemId, ComponentId), VehicleView>,
    /// Links by id.
    pub links: BTreeMap<LinkId, LinkHealth>,
    /// Every message seen, by (system, component, message id).
    pub messages: BTreeMap<(SystemId, ComponentId, u32), MessageStats>,
    last_seq: HashMap<(LinkId, SystemId, ComponentId), super::seq::SenderSeq>,
    /// Long STATUSTEXTs come in chunks: put together per vehicle before they are kept.
    text_chunks: HashMap<(SystemId, ComponentId), vtol_link::statustext::TextAssembler>,
    /// Links that went down: frames of theirs still on the way to the tracker are stale and
    /// must not bring their vehicles back (a link that reconnects under its id leaves the set).
    /// The last [`DOWN_MEMORY`] only: a fleet's vehicles come and go on new links for ever.
    down: HashSet<LinkId>,
    /// The links of `down`, oldest first.
    down_order: VecDeque<LinkId>,
    /// The time of the last frame applied, with its window bucket: a run's frames share it.
    stamp: Option<Stamp>,
}

impl Default for VehicleState {
    fn default() -> Self {
        Self::new(Instant::now())
    }
}

/// Whether a heartbeat comes from a vehicle (pymavlink `probably_vehicle_heartbeat`), from
/// its raw `type` and `autopilot` (a type the dialect does not define is a vehicle).
#[must_use]
pub fn is_vehicle_heartbeat(mav_type: u8, autopilot: u8) -> bool {
    autopilot != MavAutopilot::MAV_AUTOPILOT_INVALID as u8
        && ![
            MavType::MAV_TYPE_GCS as u8,
            MavType::MAV_TYPE_GIMBAL as u8,
            MavType::MAV_TYPE_ADSB as u8,
            MavType::MAV_TYPE_ONBOARD_CONTROLLER as u8,
        ]
        .contains(&mav_type)
}

impl VehicleState {
    /// An empty state whose windows count from `epoch`.
    #[must_use]
    pub fn new(epoch: Instant) -> Self {
        Self {
            epoch,
            vehicles: BTreeMap::new(),
            links: BTreeMap::new(),
            messages: BTreeMap::new(),
            last_seq: HashMap::default(),
            text_chunks: HashMap::default(),
            down: HashSet::default(),
            down_order: VecDeque::new(),
            stamp: None,
        }
    }

    /// Applies one frame that arrived on `link` at `now`, and returns the message it decoded
    /// (only the ones the view tracks; the rest stay raw).
    pub fn apply(
        &mut self,
        link: LinkId,
        side: Side,
        frame: &Frame,
        now: Instant,
    ) -> Option<MavMessage> {
        let stamp = self.stamp(now);
        self.apply_stamped(link, side, frame, &stamp)
    }

    /// `now` with its window bucket, for [`VehicleState::apply_stamped`] and the history.
    pub fn stamp(&mut self, now: Instant) -> Stamp {
        match self.stamp {
            Some(s) if s.at() == now && s.epoch() == self.epoch => s,
            _ => *self.stamp.insert(Stamp::new(self.epoch, now)),
        }
    }

    /// [`VehicleState::apply`] at a time already stamped.
    pub fn apply_stamped(
        &mut self,
        link: LinkId,
        side: Side,
        frame: &Frame,
        stamp: &Stamp,
    ) -> Option<MavMessage> {
        if !self.down.is_empty() && self.down.contains(&link) {
            return None;
        }
        let (now, stamp) = (stamp.at(), *stamp);
        let seen = self.account(link, side, frame, &stamp);
        let key = frame.sender();
        if let Some(v) = self.vehicles.get_mut(&key) {
            v.link = link;
            match seen {
                Seen::Next { lost } => {
                    v.frames += 1;
                    v.lost += u64::from(lost);
                    v.window.add_stamped(&stamp, 1, lost);
                }
                Seen::Late => {
                    v.frames += 1;
                    v.lost = v.lost.saturating_sub(1);
                    v.window.add_stamped(&stamp, 1, 0);
                    v.window.take_back_lost();
                }
                Seen::Repeat => {}
            }
        }
        if seen == Seen::Repeat {
            // A repeated datagram: counted and applied once already.
            return None;
        }
        self.count_message(key, frame, &stamp);
        // Decode only what the view uses, and only from known vehicles (or their heartbeat):
        // the tracker sees every routed frame, and a full decode of each would cost more than
        // routing it.
        let id = frame.message_id();
        let wanted = if id == vtol_link::protocol::id::HEARTBEAT {
            true
        } else {
            TRACKED.contains(&id) && self.vehicles.contains_key(&key)
        };
        if !wanted {
            return None;
        }
        // Leniently, as pymavlink: a value the dialect does not define (a newer MAV_TYPE)
        // must not lose the vehicle; its raw numbers are read from the payload.
        let Ok(msg) = frame.decode_lenient().map(|l| l.msg) else {
            return None;
        };
        if let MavMessage::HEARTBEAT(hb) = &msg {
            let (mav_type, autopilot) = frame.heartbeat_kind()?;
            if !is_vehicle_heartbeat(mav_type, autopilot) {
                return None;
            }
            self.apply_heartbeat(key, link, hb, (mav_type, autopilot), &stamp);
            return Some(msg);
        }
        let v = self.vehicles.get_mut(&key)?;
        apply_telemetry(v, &mut self.text_chunks, key, &msg, now);
        Some(msg)
    }

    /// Counts a frame in its message's statistics.
    fn count_message(&mut self, key: (SystemId, ComponentId), frame: &Frame, stamp: &Stamp) {
        let (epoch, now, stamp) = (self.epoch, stamp.at(), *stamp);
        self.messages
            .entry((key.0, key.1, frame.message_id()))
            .and_modify(|m| {
                m.count += 1;
                m.last = frame.clone();
                m.last_at = now;
                m.window.add_stamped(&stamp, 1, 0);
            })
            .or_insert_with(|| {
                let mut window = Window::new(epoch);
                window.add_stamped(&stamp, 1, 0);
                MessageStats {
                    count: 1,
                    last: frame.clone(),
                    last_at: now,
                    window,
                }
            });
    }

    /// A vehicle's heartbeat: the vehicle is added if new, its mode, arming and state read.
    fn apply_heartbeat(
        &mut self,
        key: (SystemId, ComponentId),
        link: LinkId,
        hb: &vtol_link::dialect::HEARTBEAT_DATA,
        (mav_type, autopilot): (u8, u8),
        stamp: &Stamp,
    ) {
        let (epoch, now, stamp) = (self.epoch, stamp.at(), *stamp);
        let v = self.vehicles.entry(key).or_insert_with(|| VehicleView {
            system_id: key.0,
            component_id: key.1,
            link,
            frames: 1,
            lost: 0,
            window: {
                let mut w = Window::new(epoch);
                w.add_stamped(&stamp, 1, 0);
                w
            },
            mav_type,
            autopilot,
            custom_mode: hb.custom_mode,
            armed: false,
            system_status: hb.system_status,
            attitude: None,
            position: None,
            servo_us: [0; 16],
            status_texts: VecDeque::new(),
            last_heartbeat: now,
            link_down: false,
            armed_since: None,
            reboots: 0,
            last_reboot: None,
        });
        v.mav_type = mav_type;
        v.autopilot = autopilot;
        v.custom_mode = hb.custom_mode;
        v.armed = hb
            .base_mode
            .contains(MavModeFlag::MAV_MODE_FLAG_SAFETY_ARMED);
        v.armed_since = match (v.armed, v.armed_since) {
            (true, None) => Some(now),
            (true, since) => since,
            (false, _) => None,
        };
        v.system_status = hb.system_status;
        v.last_heartbeat = now;
        v.link_down = false;
    }
}

/// A known vehicle's telemetry (attitude, position, servo outputs, text) applied to its view.
fn apply_telemetry(
    v: &mut VehicleView,
    text_chunks: &mut HashMap<(SystemId, ComponentId), vtol_link::statustext::TextAssembler>,
    key: (SystemId, ComponentId),
    msg: &MavMessage,
    now: Instant,
) {
    match msg {
        MavMessage::ATTITUDE(a) => {
            // The boot clock only moves forward while the vehicle runs; going back means
            // it restarted (a reboot command, a power cycle, a new process on the port).
            if let Some(prev) = v.attitude
                && a.time_boot_ms < prev.time_boot_ms
            {
                v.reboots += 1;
                v.last_reboot = Some(Reboot {
                    before_ms: prev.time_boot_ms,
                    after_ms: a.time_boot_ms,
                    at: now,
                });
            }
            v.attitude = Some(Attitude {
                rpy_rad: [a.roll, a.pitch, a.yaw],
                rates_rad_s: [a.rollspeed, a.pitchspeed, a.yawspeed],
                time_boot_ms: a.time_boot_ms,
            });
        }
        MavMessage::LOCAL_POSITION_NED(p) => {
            v.position = Some(LocalPosition {
                pos_ned_m: [p.x, p.y, p.z],
                vel_ned_m_s: [p.vx, p.vy, p.vz],
            });
        }
        MavMessage::SERVO_OUTPUT_RAW(s) => {
            v.servo_us = servo_outputs(s);
        }
        MavMessage::STATUSTEXT(t) => {
            if let Some(text) = text_chunks.entry(key).or_default().push(t) {
                if v.status_texts.len() == STATUS_TEXTS_KEPT {
                    v.status_texts.pop_front();
                }
                v.status_texts.push_back((t.severity as u8, text));
            }
        }
        _ => {}
    }
}

fn frame_bytes(frame: &Frame) -> u32 {
    u32::try_from(frame.as_bytes().len()).unwrap_or(u32::MAX)
}

impl VehicleState {
    /// Counts a frame in its link's health; returns what its sender's sequence says it is: the
    /// next frame (with the frames lost just before it), a late one, or a repeat (not counted).
    fn account(&mut self, link: LinkId, side: Side, frame: &Frame, stamp: &Stamp) -> Seen {
        let (epoch, now) = (self.epoch, stamp.at());
        let h = self.links.entry(link).or_insert_with(|| LinkHealth {
            side,
            frames: 0,
            lost: 0,
            last_heard: now,
            window: Window::new(epoch),
            bytes: Window::new(epoch),
        });
        h.last_heard = now;
        // A new session of the sender (a restart, a second process under its identity) is
        // no loss; a late frame takes its loss back, a repeated one counts nothing: see
        // [`super::seq`].
        let at_us =
            u64::try_from(now.saturating_duration_since(epoch).as_micros()).unwrap_or(u64::MAX);
        let seen = self
            .last_seq
            .entry((link, frame.sender().0, frame.sender().1))
            .or_default()
            .see(frame.seq(), Some(frame.crc()), at_us);
        match seen {
            Seen::Next { lost } => {
                h.frames += 1;
                h.lost += u64::from(lost);
                h.window.add_stamped(stamp, 1, lost);
                h.bytes.add_stamped(stamp, frame_bytes(frame), 0);
            }
            Seen::Late => {
                h.frames += 1;
                h.bytes.add_stamped(stamp, frame_bytes(frame), 0);
                h.lost = h.lost.saturating_sub(1);
                h.window.add_stamped(stamp, 1, 0);
                h.window.take_back_lost();
            }
            Seen::Repeat => {}
        }
        seen
    }

    /// Forgets a link that went down: its health and its sequence history (a link that comes
    /// back starts afresh instead of counting the gap as loss). Its vehicles are lost at once,
    /// and its frames still on their way to the tracker are ignored until
    /// [`VehicleState::retain_links`] sees it live again.
    pub fn forget_link(&mut self, link: LinkId) {
        if self.down.insert(link) {
            self.down_order.push_back(link);
            while self.down_order.len() > DOWN_MEMORY {
                if let Some(old) = self.down_order.pop_front() {
                    self.down.remove(&old);
                }
            }
        }
        self.links.remove(&link);
        self.last_seq.retain(|(l, _, _), _| *l != link);
        for v in self.vehicles.values_mut().filter(|v| v.link == link) {
            v.link_down = true;
        }
    }

    /// Forgets every link not in `live` (the router's current links).
    pub fn retain_links(&mut self, live: &[LinkId]) {
        for id in live {
            if self.down.remove(id) {
                self.down_order.retain(|l| l != id);
            }
        }
        let gone: Vec<LinkId> = self
            .links
            .keys()
            .filter(|id| !live.contains(id))
            .copied()
            .collect();
        for id in gone {
            self.forget_link(id);
        }
    }

    /// Whether no vehicle has been heard for [`LINK_TIMEOUT`] (or none ever was).
    #[must_use]
    pub fn vehicle_lost(&self, now: Instant) -> bool {
        self.vehicles.values().all(|v| v.is_lost(now))
    }
}

#[cfg(test)]
#[path = "state_tests.rs"]
mod tests;
