//! The vehicle side of MAVLink (`PROTOCOL.md` (A)) as a synchronous state machine with no I/O:
//! [`Endpoint::handle`] takes one received frame and returns the replies; [`Endpoint::tick`]
//! advances the twin to a sim time and returns the telemetry that became due. The serve loop
//! ([`crate::shell::serve`]) owns sockets and clocks; tests drive the endpoint directly.
//!
//! Identity: system id `SYSID_THISMAV` (or `--sysid`), component id 1. Output is always
//! MAVLink 2, from the first frame; input may be v1 or v2. A message is processed when its
//! `target_system` is 0 or ours and its `target_component` is 0 or 1, or when it has no target.
//!
//! One concern per file: [`heartbeat`] (HEARTBEAT, GCS failsafe), [`streams`] (telemetry and
//! rates), [`params_protocol`], [`commands`] (COMMAND_LONG/INT and legacy SET_MODE /
//! REQUEST_DATA_STREAM), [`manual`] (MANUAL_CONTROL, RC_CHANNELS_OVERRIDE, position targets),
//! [`mission`] (the mission protocol), [`guided`] (GUIDED, AUTO and QRTL: the navigator, home,
//! take-off and reposition), [`position`] (telemetry on the globe, battery), [`statustext`]
//! (texts in chunks), [`ftp`] (the NAK that sends MAVProxy to the parameter protocol).
//!
//! Framing is `vtol_link`'s, the daemon's own: frames come in as [`Frame`]s the transport has
//! already split and CRC-checked, and go out as [`Frame`]s, so signing is applied to them (by
//! the serve loop, with `vtol_link::signing`) without parsing anything twice. Hand-read fields
//! (commands, PARAM_SET, mission items) are read from the frame's zero-filled payload.

pub mod commands;
mod failsafe;
pub mod ftp;
pub mod guided;
pub mod heartbeat;
pub mod identity;
pub mod manual;
pub mod mission;
pub mod params_protocol;
pub mod position;
pub mod readiness;
pub mod statustext;
pub mod streams;

use std::collections::{BTreeMap, VecDeque};
use std::path::PathBuf;

use mavlink::dialects::ardupilotmega as apm;
use vtol_link::{ComponentId, Frame, SystemId};

use crate::model::vehicle::{PHYSICS_DT_S, SystemState, Vehicle, VehicleConfig};
use crate::nav::globe::Origin;
use crate::nav::mission::Mission;
use crate::nav::navigation::Navigator;
use crate::nav::params::Params;

/// Our component id (MAV_COMP_ID_AUTOPILOT1): pymavlink reads params of `(sysid, 1)`.
pub const COMPID: ComponentId = ComponentId::AUTOPILOT1;

/// Physics step in µs.
const STEP_US: u64 = (PHYSICS_DT_S * 1e6) as u64;

/// Identifies one connection (a TCP client, a UDP peer set, an in-memory stream). The serve loop
/// assigns them; the endpoint keeps per-link sequence numbers, stream rates and param queues.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub struct LinkKey(pub u64);

/// A frame to send on one link.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Outbound {
    /// Destination link.
    pub link: LinkKey,
    /// A complete, unsigned MAVLink 2 frame (the serve loop signs it when the twin is keyed).
    pub frame: Frame,
    /// A scheduled stream message (true) rather than a reply or an event (false). A link that
    /// is short of room sheds telemetry first, so replies are never lost behind it.
    pub telemetry: bool,
}

/// How to build an endpoint.
#[derive(Debug, Clone, Default)]
pub struct EndpointConfig {
    /// The twin. Its gains and control rate are replaced by the parameter table's.
    pub vehicle: VehicleConfig,
    /// Parameter values at start (defaults, or loaded from `param_file`).
    pub params: Params,
    /// Where accepted parameter changes are saved (atomically), if anywhere. The mission is
    /// saved beside it ([`crate::nav::mission::file_beside`]).
    pub param_file: Option<PathBuf>,
    /// System id override (`--sysid`); None = `SYSID_THISMAV`.
    pub sysid: Option<u8>,
    /// The mission at start (empty, or loaded from beside `param_file`).
    pub mission: Mission,
}

/// Counters for diagnostics and tests.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct EndpointStats {
    /// Frames handled (valid, any target).
    pub frames_in: u64,
    /// Frames that failed CRC or framing (reported by the transports' decoders).
    pub bad_frames: u64,
    /// Valid frames addressed to another system or component.
    pub not_for_us: u64,
    /// Frames sent.
    pub frames_out: u64,
}

#[derive(Debug, Clone)]
struct LinkState {
    seq: u8,
    schedule: streams::Schedule,
    /// Param indices still to send for a PARAM_REQUEST_LIST.
    param_queue: VecDeque<u16>,
}

/// The MAVLink vehicle: the twin, its parameters, and the protocol state of every link.
#[derive(Debug)]
pub struct Endpoint {
    sysid: SystemId,
    vehicle: Vehicle,
    params: Params,
    param_file: Option<PathBuf>,
    now_us: u64,
    /// The time stream rates count in, µs (see [`Endpoint::tick_at`]).
    stream_now_us: u64,
    links: BTreeMap<LinkKey, LinkState>,
    out: Vec<Outbound>,
    stats: EndpointStats,
    commands: commands::CommandMemory,
    manual: manual::ManualState,
    failsafe: heartbeat::Failsafe,
    /// The battery failsafe's level this boot.
    battery_failsafe: crate::nav::failsafe::BatteryFailsafe,
    /// One-shot `SIM_PUSH_*` parameters to reset to 0 at a sim time, µs.
    push_resets: Vec<(&'static str, u64)>,
    last_armed: bool,
    last_state: SystemState,
    /// `--sysid`, which outlives a reboot (`SYSID_THISMAV` is re-read at one).
    sysid_override: Option<u8>,
    /// While rebooting (after MAV_CMD_PREFLIGHT_REBOOT_SHUTDOWN): silent until this sim time, µs.
    rebooting_until_us: Option<u64>,
    /// The stored mission (item 0 is the home slot).
    mission: Mission,
    /// Where the mission is saved, if anywhere.
    mission_file: Option<PathBuf>,
    /// A mission upload in progress.
    upload: Option<mission::Upload>,
    /// The last finished upload (to repeat its ACK).
    finished: Option<mission::Finished>,
    /// GUIDED, AUTO and QRTL.
    navigator: Navigator,
    /// Sim time of the next navigation step, µs.
    next_nav_us: u64,
    /// The motion-capture frame on the globe (`SIM_HOME_*`, read at start and reboot).
    origin: Origin,
    /// Home, local NED, m.
    home_ned_m: nalgebra::Vector3<f64>,
    /// Id of the last STATUSTEXT sent in chunks.
    text_id: u16,
    /// The failing pre-arm check last announced.
    prearm: readiness::PreArmReport,
}

/// How long a reboot keeps the twin silent, µs: a small autopilot restarting (ArduPilot's own
/// boards are gone for a second or two).
pub const REBOOT_SILENCE_US: u64 = 1_500_000;

impl Endpoint {
    /// A vehicle at sim time 0 with no links yet.
    #[must_use]
    pub fn new(config: EndpointConfig) -> Self {
        let EndpointConfig {
            mut vehicle,
            params,
            param_file,
            sysid,
            mission,
        } = config;
        vehicle.gains = params.gains();
        vehicle.control_rate_hz = params.value("CTRL_RATE_HZ");
        vehicle.battery = params.battery();
        let mission_file = param_file.as_deref().map(crate::nav::mission::file_beside);
        let origin = params.origin();
        let sysid_override = sysid;
        let sysid = SystemId(sysid.unwrap_or(params.value("SYSID_THISMAV") as u8));
        let vehicle = Vehicle::new(vehicle);
        let last_armed = vehicle.telemetry().armed;
        let last_state = vehicle.telemetry().state;
        let home_ned_m = crate::model::frames::paper_to_ned(&vehicle.telemetry().pos_m);
        let mut ep = Self {
            sysid,
            vehicle,
            params,
            param_file,
            now_us: 0,
            stream_now_us: 0,
            links: BTreeMap::new(),
            out: Vec::new(),
            stats: EndpointStats::default(),
            commands: commands::CommandMemory::default(),
            manual: manual::ManualState::default(),
            failsafe: heartbeat::Failsafe::default(),
            battery_failsafe: crate::nav::failsafe::BatteryFailsafe::default(),
            push_resets: Vec::new(),
            last_armed,
            last_state,
            sysid_override,
            rebooting_until_us: None,
            mission,
            mission_file,
            upload: None,
            finished: None,
            navigator: Navigator::new(),
            next_nav_us: 0,
            origin,
            home_ned_m,
            text_id: 0,
            prearm: readiness::PreArmReport::default(),
        };
        ep.apply_wind();
        ep
    }

    /// The stored mission.
    #[must_use]
    pub fn mission(&self) -> &Mission {
        &self.mission
    }

    /// Home, local NED, m.
    #[must_use]
    pub fn home_ned_m(&self) -> nalgebra::Vector3<f64> {
        self.home_ned_m
    }

    /// Our system id.
    #[must_use]
    pub fn sysid(&self) -> SystemId {
        self.sysid
    }

    /// Current sim time, µs.
    #[must_use]
    pub fn now_us(&self) -> u64 {
        self.now_us
    }

    /// The time stream rates count in, µs: wall time under the serve loop's real-time and fast
    /// clocks, sim time otherwise.
    #[must_use]
    pub fn stream_now_us(&self) -> u64 {
        self.stream_now_us
    }

    /// The twin.
    #[must_use]
    pub fn vehicle(&self) -> &Vehicle {
        &self.vehicle
    }

    /// The parameter table.
    #[must_use]
    pub fn params(&self) -> &Params {
        &self.params
    }

    /// Counters.
    #[must_use]
    pub fn stats(&self) -> EndpointStats {
        self.stats
    }

    /// The frames queued outside [`Endpoint::handle`] and [`Endpoint::tick`] (e.g. by
    /// [`Endpoint::set_param_announced`]), oldest first.
    pub fn take_outbound(&mut self) -> Vec<Outbound> {
        std::mem::take(&mut self.out)
    }

    /// Adds bad frames counted by a transport's decoder (reported in SYS_STATUS `errors_comm`).
    pub fn note_bad_frames(&mut self, n: u64) {
        self.stats.bad_frames += n;
    }

    /// Registers a link. Telemetry and heartbeats start on it at the next tick.
    pub fn add_link(&mut self, link: LinkKey) {
        let groups = self.group_rates_from_params();
        self.links.entry(link).or_insert_with(|| LinkState {
            seq: 0,
            schedule: streams::Schedule::new(groups),
            param_queue: VecDeque::new(),
        });
    }

    /// Forgets a link (client disconnected).
    pub fn remove_link(&mut self, link: LinkKey) {
        self.links.remove(&link);
    }

    /// Whether the twin is rebooting (silent, deaf to frames).
    #[must_use]
    pub fn is_rebooting(&self) -> bool {
        self.rebooting_until_us.is_some()
    }

    /// Restarts the vehicle as the reboot command does: on the ground, level, disarmed, where
    /// it was (horizontally), with the parameters as they stand (`CTRL_RATE_HZ` and
    /// `SYSID_THISMAV` take effect here), the battery drawn as it was, then silent for
    /// [`REBOOT_SILENCE_US`]. Clears a crash.
    pub(crate) fn reboot(&mut self) {
        let mut config = self.vehicle.config().clone();
        let here = self.vehicle.telemetry().pos_m;
        config.initial = crate::model::vehicle::InitialState {
            pos_m: nalgebra::Vector3::new(here.x, here.y, 0.0),
            euler: crate::model::frames::Euler::new(self.vehicle.telemetry().euler.psi, 0.0, 0.0),
        };
        config.armed = false;
        // A reboot calibrates the gyros again, at rest.
        config.calibrated = false;
        config.position_setpoint_m = None;
        config.rc_us = [0; 8];
        config.gains = self.params.gains();
        config.control_rate_hz = self.params.value("CTRL_RATE_HZ");
        config.battery = self.params.battery();
        // The pack is not the firmware's: it stays drawn as it was (a process restart is a
        // fresh pack).
        let pack = self.vehicle.battery().restarted(config.battery);
        self.vehicle = Vehicle::new(config);
        self.vehicle.replace_battery(pack);
        self.origin = self.params.origin();
        self.home_ned_m = crate::model::frames::paper_to_ned(&self.vehicle.telemetry().pos_m);
        self.navigator = Navigator::new();
        self.upload = None;
        self.finished = None;
        self.sysid = SystemId(
            self.sysid_override
                .unwrap_or(self.params.value("SYSID_THISMAV") as u8),
        );
        self.push_resets.clear();
        self.manual = manual::ManualState::default();
        self.failsafe = heartbeat::Failsafe::default();
        self.battery_failsafe = crate::nav::failsafe::BatteryFailsafe::default();
        self.commands = commands::CommandMemory::default();
        self.prearm = readiness::PreArmReport::default();
        let groups = self.group_rates_from_params();
        for l in self.links.values_mut() {
            l.schedule = streams::Schedule::new(groups);
            l.param_queue.clear();
        }
        self.last_armed = false;
        self.last_state = self.vehicle.telemetry().state;
        self.apply_wind();
        self.rebooting_until_us = Some(self.now_us + REBOOT_SILENCE_US);
    }

    /// Handles one frame received on `link` (as a transport's decoder yields it) and returns
    /// the replies. A frame of a message id the dialect does not know (unverified) is ignored.
    pub fn handle(&mut self, link: LinkKey, frame: &Frame) -> Vec<Outbound> {
        if self.is_rebooting() {
            // Nobody is listening during a reboot.
            return Vec::new();
        }
        self.add_link(link);
        if frame.is_verified() {
            self.handle_frame(link, frame);
        }
        std::mem::take(&mut self.out)
    }

    /// Advances the twin to sim time `now_us` (1 kHz physics steps) and returns the frames that
    /// became due: streams, heartbeats, paced parameter lists, status texts. Stream rates count
    /// in sim time.
    pub fn tick(&mut self, now_us: u64) -> Vec<Outbound> {
        self.tick_at(now_us, now_us)
    }

    /// [`Endpoint::tick`] with stream rates counted in `stream_us` instead of sim time: the serve
    /// loop passes wall time, so a twin running 1 000× faster than real time still sends
    /// ATTITUDE 20 times a wall second, not 20 000 times (each message then carries the latest
    /// sample). `stream_us` never goes back.
    pub fn tick_at(&mut self, now_us: u64, stream_us: u64) -> Vec<Outbound> {
        self.stream_now_us = self.stream_now_us.max(stream_us);
        while self.now_us + STEP_US <= now_us {
            self.vehicle.step();
            self.now_us += STEP_US;
            if self.now_us >= self.next_nav_us {
                self.navigate();
            }
        }
        if let Some(until) = self.rebooting_until_us {
            if self.now_us < until {
                // Rebooting: nothing goes out, the vehicle sits on the ground calibrating.
                self.out.clear();
                return Vec::new();
            }
            self.rebooting_until_us = None;
            self.announce(apm::MavSeverity::MAV_SEVERITY_INFO, "Rebooted");
        }
        self.manual.expire(self.now_us, &mut self.vehicle);
        self.expire_pushes();
        self.check_failsafe();
        self.check_battery_failsafe();
        self.report_vehicle_events();
        self.report_prearm();
        self.mission_timeouts();
        self.drain_param_queues();
        let errors_comm = self.stats.bad_frames.min(u64::from(u16::MAX)) as u16;
        let keys: Vec<LinkKey> = self.links.keys().copied().collect();
        let replies = self.out.len();
        for link in keys {
            let due = match self.links.get_mut(&link) {
                Some(l) => l.schedule.due(self.stream_now_us),
                None => continue,
            };
            for msgid in due {
                for msg in self.build_messages(msgid, errors_comm) {
                    self.send(link, &msg);
                }
            }
        }
        for o in &mut self.out[replies..] {
            o.telemetry = true;
        }
        std::mem::take(&mut self.out)
    }

    /// The messages one stream id stands for (one, except the controller's outputs).
    fn build_messages(&self, msgid: u32, errors_comm: u16) -> Vec<apm::MavMessage> {
        match msgid {
            streams::id::HEARTBEAT => vec![self.heartbeat()],
            streams::id::SYS_STATUS => self.sys_status(errors_comm).into_iter().collect(),
            readiness::EKF_STATUS_REPORT => vec![readiness::ekf_status_report(&self.vehicle)],
            streams::id::AUTOPILOT_VERSION => vec![identity::autopilot_version(self.sysid)],
            streams::id::NAMED_VALUE_FLOAT => {
                streams::controller_outputs(self.vehicle.telemetry()).into()
            }
            position::MISSION_CURRENT => vec![self.mission_current()],
            id if position::builds(id) => position::GlobeView {
                t: self.vehicle.telemetry(),
                origin: self.origin,
                home_ned_m: self.home_ned_m,
                target_ned_m: self.navigator.target_ned_m(),
                capacity_mah: self.params.value("BATT_CAPACITY"),
            }
            .build(id)
            .into_iter()
            .collect(),
            _ => streams::build(msgid, self.vehicle.telemetry(), errors_comm)
                .into_iter()
                .collect(),
        }
    }

    fn handle_frame(&mut self, link: LinkKey, frame: &Frame) {
        self.stats.frames_in += 1;
        // Commands first, raw: the typed decoder cannot represent unknown command ids.
        if let Some(cmd) = frame.raw_command().map(|c| commands::Command::from(&c)) {
            if self.for_us(Some(cmd.target_system), Some(cmd.target_component)) {
                self.handle_command(link, frame, &cmd);
            } else {
                self.stats.not_for_us += 1;
            }
            return;
        }
        // Mission items, raw too: an unsupported command must still get its refusal.
        if self.mission_raw(link, frame) {
            return;
        }
        let msg = match frame.decode() {
            Ok(m) => m,
            Err(_) => {
                // PARAM_SET with a param_type outside the enum: the contract ignores the type.
                if let Some((value, tsys, tcomp, name)) = params_protocol::raw_param_set(frame)
                    && self.for_us(Some(tsys), Some(tcomp))
                {
                    self.param_set(link, frame, &name, value);
                }
                return;
            }
        };
        use mavlink::Message;
        if !self.for_us(msg.target_system_id(), msg.target_component_id()) {
            self.stats.not_for_us += 1;
            return;
        }
        use apm::MavMessage as M;
        // SET_MODE and REQUEST_DATA_STREAM are deprecated but still sent by MAVProxy (A.5).
        #[allow(deprecated)]
        match msg {
            M::HEARTBEAT(hb) => self.on_heartbeat(frame, &hb),
            M::PARAM_REQUEST_LIST(_) => self.param_request_list(link),
            M::PARAM_REQUEST_READ(r) => self.param_request_read(link, frame, &r),
            M::PARAM_SET(s) => {
                let name = s.param_id.to_str().unwrap_or("").to_owned();
                self.param_set(link, frame, &name, s.param_value);
            }
            M::SET_MODE(m) => self.on_set_mode(link, frame, &m),
            M::REQUEST_DATA_STREAM(r) => self.on_request_data_stream(link, &r),
            M::MANUAL_CONTROL(m) => self.on_manual_control(frame, &m),
            M::RC_CHANNELS_OVERRIDE(o) => self.on_rc_override(frame, &o),
            M::SET_POSITION_TARGET_LOCAL_NED(t) => self.on_position_target(link, &t),
            M::SET_POSITION_TARGET_GLOBAL_INT(t) => self.on_position_target_global(link, &t),
            M::MISSION_COUNT(m) => self.on_mission_count(link, frame, &m),
            M::MISSION_REQUEST_LIST(m) => self.on_mission_request_list(link, frame, &m),
            M::MISSION_REQUEST_INT(m) => {
                self.on_mission_request(link, frame, m.seq, m.mission_type as u8, true);
            }
            M::MISSION_REQUEST(m) => {
                self.on_mission_request(link, frame, m.seq, m.mission_type as u8, false);
            }
            M::MISSION_CLEAR_ALL(m) => self.on_mission_clear_all(link, frame, &m),
            M::MISSION_SET_CURRENT(m) => {
                self.set_mission_current(link, f32::from(m.seq));
            }
            M::MISSION_WRITE_PARTIAL_LIST(m) => {
                self.on_mission_partial(link, frame, m.mission_type as u8);
            }
            M::FILE_TRANSFER_PROTOCOL(f) => self.on_ftp(link, frame, &f),
            M::TIMESYNC(t) => self.on_timesync(link, frame, &t),
            _ => {}
        }
    }

    /// Routing rule of `PROTOCOL.md` A.1: no target, or target 0 or ours.
    fn for_us(&self, sys: Option<u8>, comp: Option<u8>) -> bool {
        sys.is_none_or(|s| s == 0 || s == self.sysid.0)
            && comp.is_none_or(|c| c == 0 || c == COMPID.0)
    }

    fn next_seq(&mut self, link: LinkKey) -> u8 {
        self.add_link(link);
        let l = self
            .links
            .get_mut(&link)
            .unwrap_or_else(|| unreachable!("link just added"));
        let s = l.seq;
        l.seq = s.wrapping_add(1);
        s
    }

    /// Queues a typed message on one link.
    fn send(&mut self, link: LinkKey, msg: &apm::MavMessage) {
        let seq = self.next_seq(link);
        let frame = Frame::encode_v2(self.sysid, COMPID, seq, msg);
        self.push_out(link, frame);
    }

    /// Queues a hand-built payload of a dialect message on one link (trailing zeros stripped).
    fn send_raw(&mut self, link: LinkKey, msgid: u32, payload: &[u8]) {
        let seq = self.next_seq(link);
        match Frame::encode_payload_v2(self.sysid, COMPID, seq, msgid, payload) {
            Ok(frame) => self.push_out(link, frame),
            // Only dialect ids with payloads of at most 255 bytes are built here.
            Err(e) => unreachable!("hand-built payload does not frame: {e}"),
        }
    }

    /// Queues a COMMAND_ACK for any command number, including ones the dialect's `MavCmd`
    /// lacks, addressed back to `to` (system, component).
    fn send_ack(&mut self, link: LinkKey, command: u16, result: u8, to: (SystemId, ComponentId)) {
        let seq = self.next_seq(link);
        let frame = vtol_link::RawCommandAck::new(command, result, to.0, to.1)
            .to_frame(self.sysid, COMPID, seq);
        self.push_out(link, frame);
    }

    fn push_out(&mut self, link: LinkKey, frame: Frame) {
        self.stats.frames_out += 1;
        self.out.push(Outbound {
            link,
            frame,
            telemetry: false,
        });
    }

    /// Queues a message on every link.
    fn broadcast(&mut self, msg: &apm::MavMessage) {
        let keys: Vec<LinkKey> = self.links.keys().copied().collect();
        for link in keys {
            self.send(link, msg);
        }
    }

    fn group_rates_from_params(&self) -> [Option<f64>; streams::Group::ALL.len()] {
        streams::Group::ALL.map(|g| {
            let v = self.params.value(g.param());
            (v >= 0.0).then_some(v)
        })
    }

    fn on_timesync(&mut self, link: LinkKey, frame: &Frame, t: &apm::TIMESYNC_DATA) {
        // tc1 == 0 is a request; anything else is someone's reply to their own request.
        if t.tc1 != 0 {
            return;
        }
        let reply = apm::MavMessage::TIMESYNC(apm::TIMESYNC_DATA {
            tc1: (self.now_us * 1000) as i64,
            ts1: t.ts1,
            target_system: frame.system_id(),
            target_component: frame.component_id(),
        });
        self.send(link, &reply);
    }

    /// STATUSTEXT for changes the vehicle makes on its own (QLAND disarm, crash) or that
    /// commands caused.
    fn report_vehicle_events(&mut self) {
        let t = *self.vehicle.telemetry();
        if t.armed != self.last_armed {
            self.last_armed = t.armed;
            if t.armed {
                // Home is where the vehicle was armed (ArduPlane).
                self.set_home(crate::model::frames::paper_to_ned(&t.pos_m));
            }
            let text = if t.armed {
                "Arming motors"
            } else {
                "Disarming motors"
            };
            self.announce(apm::MavSeverity::MAV_SEVERITY_INFO, text);
            // The changed HEARTBEAT goes out at once, as ArduPilot sends it.
            let hb = self.heartbeat();
            self.broadcast(&hb);
        }
        if t.state != self.last_state {
            self.last_state = t.state;
            if t.state == SystemState::Emergency {
                self.announce(apm::MavSeverity::MAV_SEVERITY_CRITICAL, "Crash detected");
            }
            if t.state == SystemState::Critical {
                // The only CRITICAL the vehicle model raises: say why.
                self.announce(
                    apm::MavSeverity::MAV_SEVERITY_CRITICAL,
                    "No RC receiver: throttle at zero in QSTABILIZE",
                );
            }
        }
    }
}

#[cfg(test)]
mod forward_mission_tests;
#[cfg(test)]
mod forward_stick_tests;
#[cfg(test)]
mod mission_tests;
#[cfg(test)]
mod params_tests;
#[cfg(test)]
mod readiness_tests;
#[cfg(test)]
mod test_support;
#[cfg(test)]
mod tests;
