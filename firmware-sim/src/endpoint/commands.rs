//! The command protocol (`PROTOCOL.md` A.4) and the legacy SET_MODE / REQUEST_DATA_STREAM (A.5).
//!
//! Every COMMAND_LONG/COMMAND_INT addressed to us gets exactly one COMMAND_ACK, built from raw
//! bytes so that command ids the dialect does not know still get `UNSUPPORTED`. A retransmission
//! (`confirmation` > 0) of the command last done for the same sender gets the same result again
//! without acting twice. SET_MODE gets one too, COMMAND_ACK with `command` = 11, as ArduPilot
//! answers it.
//!
//! Modes: the twin's own (`FlightMode`); RTL (11) flies home on the wing (QRTL with
//! `Q_RTL_MODE` = 3, QRTL always, or in the `paper` model); any other mode number is refused
//! with a reason. Navigation commands (take-off, reposition, mission start, home) are
//! `guided`'s.

use mavlink::dialects::ardupilotmega::{self as apm, MavCmd, MavResult, MavVtolState, PlaneMode};
use num_traits::FromPrimitive as _;

use vtol_link::{Frame, RawCommand, RawCommandKind};

use super::{Endpoint, LinkKey, streams};
use crate::model::mode::FlightMode;
use crate::model::vehicle::ArmError;

/// ArduPlane's RTL mode number, flown as QRTL.
pub const RTL_MODE: u32 = PlaneMode::PLANE_MODE_RTL as u32;

/// SET_MODE's message id, which its COMMAND_ACK carries as `command` (ArduPilot).
#[allow(deprecated)]
const SET_MODE_ID: u16 = <apm::SET_MODE_DATA as mavlink::MessageData>::ID as u16;

/// The force-arm magic number (ArduPilot, common.xml).
pub const FORCE_MAGIC: f32 = 21196.0;

/// How long a remembered result answers retransmissions, µs.
const RETRY_WINDOW_US: u64 = 5_000_000;

/// A COMMAND_LONG or COMMAND_INT as the twin acts on it, from vtol-link's raw reading (so
/// command ids the dialect's `MavCmd` lacks still get their ACK).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Command {
    /// Command number.
    pub command: u16,
    /// param1..param7 (COMMAND_INT: x, y as f32 of the integer, z).
    pub params: [f32; 7],
    /// Addressed system.
    pub target_system: u8,
    /// Addressed component.
    pub target_component: u8,
    /// Retransmission counter (COMMAND_LONG only; 0 for COMMAND_INT).
    pub confirmation: u8,
    /// Came as COMMAND_INT.
    pub is_int: bool,
    /// COMMAND_INT's x as sent (latitude in 1e-7 degree in global frames); 0 for COMMAND_LONG.
    pub x: i32,
    /// COMMAND_INT's y as sent (longitude in 1e-7 degree); 0 for COMMAND_LONG.
    pub y: i32,
    /// COMMAND_INT's `MAV_FRAME`; 0 for COMMAND_LONG.
    pub frame: u8,
}

impl From<&RawCommand> for Command {
    fn from(c: &RawCommand) -> Self {
        let (params, confirmation, is_int, x, y, frame) = match c.kind {
            RawCommandKind::Long {
                params,
                confirmation,
            } => (params, confirmation, false, 0, 0, 0),
            RawCommandKind::Int {
                params: p,
                x,
                y,
                z,
                frame,
                ..
            } => (
                [p[0], p[1], p[2], p[3], x as f32, y as f32, z],
                0,
                true,
                x,
                y,
                frame,
            ),
        };
        Command {
            command: c.command,
            params,
            target_system: c.target_system,
            target_component: c.target_component,
            confirmation,
            is_int,
            x,
            y,
            frame,
        }
    }
}

/// The last command done per sender, to answer retries without acting twice.
#[derive(Debug, Clone, Default)]
pub struct CommandMemory {
    /// (sender sysid, sender compid, command) → (its parameters' bits, result, sim time done).
    last: std::collections::HashMap<(u8, u8, u16), Remembered>,
}

/// A command done: a retransmission is the same command with the same parameters.
#[derive(Debug, Clone, Copy)]
struct Remembered {
    params: [u32; 7],
    result: MavResult,
    at_us: u64,
}

/// The parameters' bits, so NaN ("unchanged") compares equal to itself.
fn param_bits(c: &Command) -> [u32; 7] {
    let mut bits = c.params.map(f32::to_bits);
    if c.is_int {
        // COMMAND_INT's x and y as sent, not their f32 approximations.
        bits[4] = c.x as u32;
        bits[5] = c.y as u32;
    }
    bits
}

impl Endpoint {
    pub(super) fn handle_command(&mut self, link: LinkKey, frame: &Frame, c: &Command) {
        let key = (frame.system_id(), frame.component_id(), c.command);
        let params = param_bits(c);
        let remembered = self.commands.last.get(&key).copied();
        let result = match remembered {
            // Only a retransmission of the command done is answered from memory: a different
            // command of the same number (a mode change to another mode whose first send was
            // lost) is acted on.
            Some(m)
                if c.confirmation > 0
                    && m.params == params
                    && self.now_us.saturating_sub(m.at_us) < RETRY_WINDOW_US =>
            {
                m.result
            }
            _ => {
                let mut follow_up = Vec::new();
                let mode_before = self.vehicle.telemetry().mode;
                let r = self.execute(link, c, &mut follow_up);
                let done = Remembered {
                    params,
                    result: r,
                    at_us: self.now_us,
                };
                self.commands.last.insert(key, done);
                self.ack(link, frame, c.command, r);
                for msg in follow_up {
                    self.send(link, &msg);
                }
                self.heartbeat_on_mode_change(mode_before);
                // The ACK goes out first, then the autopilot restarts.
                if c.command == MavCmd::MAV_CMD_PREFLIGHT_REBOOT_SHUTDOWN as u16
                    && r == MavResult::MAV_RESULT_ACCEPTED
                {
                    let p1 = c.params[0].round();
                    if p1 == 1.0 {
                        self.reboot();
                    }
                }
                return;
            }
        };
        self.ack(link, frame, c.command, result);
    }

    /// After a command changed the mode, the changed HEARTBEAT to every link at once (ArduPilot
    /// sends it at once too), so a client sees the new mode without waiting for the 1 Hz one.
    fn heartbeat_on_mode_change(&mut self, before: FlightMode) {
        if self.vehicle.telemetry().mode != before {
            let hb = self.heartbeat();
            self.broadcast(&hb);
        }
    }

    fn ack(&mut self, link: LinkKey, frame: &Frame, command: u16, result: MavResult) {
        let to = frame.sender();
        self.send_ack(link, command, result as u8, to);
    }

    /// Runs a command. Messages that must follow the ACK go to `after` (ArduPilot ACKs a
    /// REQUEST_MESSAGE first and sends the message after).
    // Long: one arm per MAV_CMD the twin answers, most a line or two that call the command's own
    // handler; the dispatch table reads best in one place. GET_MESSAGE_INTERVAL,
    // REQUEST_AUTOPILOT_CAPABILITIES and GET_HOME_POSITION are deprecated but still sent.
    #[allow(deprecated)]
    fn execute(
        &mut self,
        link: LinkKey,
        c: &Command,
        after: &mut Vec<apm::MavMessage>,
    ) -> MavResult {
        use MavCmd as C;
        let p = c.params;
        let Some(command) = MavCmd::from_u16(c.command) else {
            return MavResult::MAV_RESULT_UNSUPPORTED;
        };
        match command {
            C::MAV_CMD_COMPONENT_ARM_DISARM => self.cmd_arm_disarm(link, p[0], p[1]),
            C::MAV_CMD_DO_SET_MODE => {
                // Only CUSTOM_MODE_ENABLED matters; SAFETY_ARMED in p1 is ignored (common.xml).
                if (p[0] as u32) & 1 == 0 {
                    return MavResult::MAV_RESULT_DENIED;
                }
                self.apply_custom_mode(link, p[1] as u32)
            }
            C::MAV_CMD_SET_MESSAGE_INTERVAL => {
                let now = self.stream_now_us;
                let msgid = p[0] as u32;
                let ok = self
                    .links
                    .get_mut(&link)
                    .is_some_and(|l| l.schedule.set_interval(msgid, f64::from(p[1]), now));
                if ok {
                    MavResult::MAV_RESULT_ACCEPTED
                } else {
                    MavResult::MAV_RESULT_DENIED
                }
            }
            C::MAV_CMD_GET_MESSAGE_INTERVAL => {
                let msgid = p[0] as u32;
                let interval = self
                    .links
                    .get(&link)
                    .and_then(|l| l.schedule.interval_us(msgid))
                    // A message we cannot stream has interval 0 with "not supported" semantics;
                    // common.xml: 0 = not sent / unknown.
                    .unwrap_or(0);
                after.push(apm::MavMessage::MESSAGE_INTERVAL(
                    apm::MESSAGE_INTERVAL_DATA {
                        interval_us: interval.clamp(i64::from(i32::MIN), i64::from(i32::MAX))
                            as i32,
                        message_id: msgid as u16,
                    },
                ));
                MavResult::MAV_RESULT_ACCEPTED
            }
            C::MAV_CMD_REQUEST_MESSAGE => {
                let msgid = p[0] as u32;
                if !streams::can_produce(msgid) {
                    return MavResult::MAV_RESULT_FAILED;
                }
                let errors = self.stats.bad_frames.min(u64::from(u16::MAX)) as u16;
                let msgs = self.build_messages(msgid, errors);
                if msgs.is_empty() {
                    MavResult::MAV_RESULT_FAILED
                } else {
                    after.extend(msgs);
                    MavResult::MAV_RESULT_ACCEPTED
                }
            }
            C::MAV_CMD_REQUEST_AUTOPILOT_CAPABILITIES => {
                after.push(super::identity::autopilot_version(self.sysid));
                MavResult::MAV_RESULT_ACCEPTED
            }
            C::MAV_CMD_DO_VTOL_TRANSITION => self.cmd_vtol_transition(link, p[0]),
            C::MAV_CMD_NAV_TAKEOFF | C::MAV_CMD_NAV_VTOL_TAKEOFF => self.cmd_takeoff(link, p[6]),
            C::MAV_CMD_DO_REPOSITION => self.cmd_reposition(link, c),
            C::MAV_CMD_NAV_RETURN_TO_LAUNCH => self.apply_custom_mode(link, RTL_MODE),
            C::MAV_CMD_MISSION_START => self.cmd_mission_start(link, p[0]),
            C::MAV_CMD_DO_SET_MISSION_CURRENT => self.set_mission_current(link, p[0]),
            C::MAV_CMD_GET_HOME_POSITION => {
                after.push(self.home_position());
                MavResult::MAV_RESULT_ACCEPTED
            }
            C::MAV_CMD_DO_SET_HOME => self.cmd_set_home(link, c),
            // Speed type (air, ground, climb, descent) and a speed, −1 (or −2) = unchanged, as
            // ArduPlane checks them. The twin's position loop sets its own horizontal speed, so
            // an accepted change has nothing to act on.
            C::MAV_CMD_DO_CHANGE_SPEED => {
                let ok_type = (0.0..=3.0).contains(&p[0]) && p[0].fract() == 0.0;
                let ok_speed = p[1] > 0.0 || p[1] == -1.0 || p[1] == -2.0;
                if ok_type && ok_speed && p[1].is_finite() {
                    MavResult::MAV_RESULT_ACCEPTED
                } else {
                    MavResult::MAV_RESULT_FAILED
                }
            }
            // Landing is a mode (QLAND, QRTL) or a mission item on ArduPlane, not a command.
            C::MAV_CMD_NAV_LAND | C::MAV_CMD_NAV_VTOL_LAND => MavResult::MAV_RESULT_UNSUPPORTED,
            C::MAV_CMD_PREFLIGHT_REBOOT_SHUTDOWN => match p[0].round() {
                // Reboot the autopilot: only on the ground, disarmed, as ArduPilot does.
                1.0 if self.vehicle.telemetry().armed => MavResult::MAV_RESULT_DENIED,
                1.0 => MavResult::MAV_RESULT_ACCEPTED,
                0.0 => MavResult::MAV_RESULT_ACCEPTED,
                // Shutdown or bootloader: there is no hardware to power off.
                _ => MavResult::MAV_RESULT_UNSUPPORTED,
            },
            _ => MavResult::MAV_RESULT_UNSUPPORTED,
        }
    }

    /// MAV_CMD_DO_VTOL_TRANSITION, where ArduPlane takes it: in AUTO, in the air. `to` is the
    /// MAV_VTOL_STATE asked for (3 MC, 4 FW); asking for the phase the vehicle is in or going
    /// to succeeds and changes nothing.
    fn cmd_vtol_transition(&mut self, link: LinkKey, to: f32) -> MavResult {
        use crate::model::mode::VtolState;
        let forward = match MavVtolState::from_u32(to as u32) {
            Some(MavVtolState::MAV_VTOL_STATE_MC) => false,
            Some(MavVtolState::MAV_VTOL_STATE_FW) => true,
            _ => return MavResult::MAV_RESULT_DENIED,
        };
        let t = self.vehicle.telemetry();
        if t.mode == FlightMode::Auto {
            // The mission's position items are flown in this phase from now on (ArduPlane's
            // auto_state.vtol_mode).
            self.navigator.set_vtol_mode(!forward);
        }
        let already = if forward {
            matches!(t.vtol_state, VtolState::Fw | VtolState::TransitionToFw)
        } else {
            matches!(t.vtol_state, VtolState::Mc | VtolState::TransitionToMc)
        };
        if already {
            return MavResult::MAV_RESULT_ACCEPTED;
        }
        if t.mode != FlightMode::Auto {
            self.say(
                link,
                apm::MavSeverity::MAV_SEVERITY_WARNING,
                "VTOL transition: only in AUTO",
            );
            return MavResult::MAV_RESULT_DENIED;
        }
        let started = if forward {
            self.vehicle.start_forward_transition()
        } else {
            self.vehicle.start_back_transition()
        };
        if started {
            MavResult::MAV_RESULT_ACCEPTED
        } else {
            self.say(
                link,
                apm::MavSeverity::MAV_SEVERITY_WARNING,
                "VTOL transition: not flying",
            );
            MavResult::MAV_RESULT_DENIED
        }
    }

    fn cmd_arm_disarm(&mut self, link: LinkKey, p1: f32, p2: f32) -> MavResult {
        let force = p2 == FORCE_MAGIC;
        let outcome = if p1 == 1.0 {
            if self.vehicle.telemetry().armed {
                return MavResult::MAV_RESULT_ACCEPTED;
            }
            match self.mission_prearm() {
                Some(why) if !force && self.vehicle.pre_arm_check().is_ok() => {
                    // ArduPilot's arming command says "Arm:", its periodic report "PreArm:".
                    let text = format!("Arm: {why}");
                    self.say(link, apm::MavSeverity::MAV_SEVERITY_CRITICAL, &text);
                    return MavResult::MAV_RESULT_FAILED;
                }
                _ => self.vehicle.arm(force),
            }
        } else if p1 == 0.0 {
            if !self.vehicle.telemetry().armed {
                return MavResult::MAV_RESULT_ACCEPTED;
            }
            self.vehicle.disarm(force)
        } else {
            return MavResult::MAV_RESULT_DENIED;
        };
        match outcome {
            Ok(()) => {
                // Announce now so the text precedes the next heartbeat showing the change.
                self.report_vehicle_events();
                MavResult::MAV_RESULT_ACCEPTED
            }
            Err(e) => {
                let text = match e {
                    ArmError::PreArm(_) => format!("PreArm: {e}"),
                    ArmError::InFlight => format!("Disarm: {e}"),
                    ArmError::Mode(_) => format!("Arm: {e}"),
                };
                self.say(link, apm::MavSeverity::MAV_SEVERITY_CRITICAL, &text);
                MavResult::MAV_RESULT_FAILED
            }
        }
    }

    /// The mode RTL is flown as: RTL, home as a plane (a hovering vehicle transitions first), as
    /// ArduPlane's; with Q_RTL_MODE 3 (QRTL always) QRTL, and so in the `paper` model, which has
    /// no forward flight.
    pub(super) fn rtl_or_qrtl(&self) -> FlightMode {
        let paper = self.vehicle.config().model == crate::model::airframe::ModelMode::Paper;
        if paper || self.params.value("Q_RTL_MODE") as i32 == 3 {
            FlightMode::QRtl
        } else {
            FlightMode::Rtl
        }
    }

    pub(super) fn apply_custom_mode(&mut self, link: LinkKey, custom_mode: u32) -> MavResult {
        let wanted = if custom_mode == RTL_MODE {
            self.rtl_or_qrtl().custom_mode()
        } else {
            custom_mode
        };
        match FlightMode::from_custom_mode(wanted) {
            Some(mode) => {
                self.vehicle.set_mode(mode);
                // The navigator takes over at once, so an autonomous mode never flies a
                // stale guidance for a navigation period.
                self.navigate();
                MavResult::MAV_RESULT_ACCEPTED
            }
            None => {
                let text = format!("Mode {custom_mode} not available");
                self.say(link, apm::MavSeverity::MAV_SEVERITY_WARNING, &text);
                MavResult::MAV_RESULT_FAILED
            }
        }
    }

    // SET_MODE and REQUEST_DATA_STREAM are deprecated in common.xml, but MAVProxy and older
    // GCSs still send them (A.5).
    #[allow(deprecated)]
    /// SET_MODE (11): like DO_SET_MODE, answered with COMMAND_ACK(`command` = 11) as ArduPilot
    /// does (built from raw bytes: the crate's `MavCmd` has no 11).
    pub(super) fn on_set_mode(&mut self, link: LinkKey, frame: &Frame, m: &apm::SET_MODE_DATA) {
        if m.target_system != self.sysid.0 && m.target_system != 0 {
            return;
        }
        let mode_before = self.vehicle.telemetry().mode;
        let r = if m
            .base_mode
            .contains(apm::MavModeFlag::MAV_MODE_FLAG_CUSTOM_MODE_ENABLED)
        {
            self.apply_custom_mode(link, m.custom_mode)
        } else {
            MavResult::MAV_RESULT_DENIED
        };
        self.ack(link, frame, SET_MODE_ID, r);
        self.heartbeat_on_mode_change(mode_before);
    }

    #[allow(deprecated)]
    /// REQUEST_DATA_STREAM (66): group rates on this link; ALL (0) = every group. No ACK.
    pub(super) fn on_request_data_stream(
        &mut self,
        link: LinkKey,
        r: &apm::REQUEST_DATA_STREAM_DATA,
    ) {
        let hz = if r.start_stop == 0 {
            0.0
        } else {
            f64::from(r.req_message_rate)
        };
        let groups: Vec<streams::Group> = match r.req_stream_id as u8 {
            0 => streams::Group::ALL.to_vec(),
            n => streams::Group::from_stream_id(n).into_iter().collect(),
        };
        let now = self.stream_now_us;
        if let Some(l) = self.links.get_mut(&link) {
            for g in groups {
                l.schedule.set_group(g, Some(hz), now);
            }
        }
    }
}
