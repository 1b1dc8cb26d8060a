//! GUIDED, AUTO and QRTL at the wire: the navigator ([`crate::nav::navigation`]) run in sim time,
//! its events turned into messages, home, and the commands and targets that steer it.
//!
//! - Every [`NAV_PERIOD_US`] the navigator chooses what GUIDED, AUTO and QRTL fly; reached
//!   items become MISSION_ITEM_REACHED, a new current item MISSION_CURRENT, both on every link.
//! - NAV_TAKEOFF (and NAV_VTOL_TAKEOFF): climb `param7` m in GUIDED. DO_REPOSITION (COMMAND_INT
//!   in its frame, or COMMAND_LONG with degrees and an altitude above home, as ArduPilot reads
//!   it; bit 0 of `param2` switches to GUIDED), SET_POSITION_TARGET_GLOBAL_INT and, in GUIDED,
//!   SET_POSITION_TARGET_LOCAL_NED move the point held. A latitude and longitude of 0 (or
//!   INT32_MAX, or NaN) keep the current one, a NaN altitude the current altitude.
//! - NAV_RETURN_TO_LAUNCH and the RTL mode become QRTL; MISSION_START starts AUTO;
//!   DO_SET_MISSION_CURRENT and MISSION_SET_CURRENT choose the next item.
//! - Home is where the vehicle stood when it was armed (ArduPlane), or where DO_SET_HOME puts
//!   it; HOME_POSITION answers GET_HOME_POSITION and goes to every link when home moves.
//!
//! Refusals say why in a STATUSTEXT (chunked when long) to the requester: FAILED when the
//! vehicle's state forbids it now, DENIED for a target outside the flight envelope
//! (`NAV_RADIUS_MAX`, `NAV_ALT_MAX`) or an unusable value.

use mavlink::dialects::ardupilotmega::{self as apm, MavCmd, MavFrame, MavResult};
use nalgebra::Vector3;

use super::commands::Command;
use super::{Endpoint, LinkKey, position};
use crate::model::frames::paper_to_ned;
use crate::model::mode::FlightMode;
use crate::nav::fixed_wing::FixedWingInput;
use crate::nav::globe::{deg_to_e7, valid_lat_lon};
use crate::nav::l1::L1Params;
use crate::nav::mission::{Limits, frame};
use crate::nav::navigation::{
    NAV_PERIOD_US, NavEvent, NavInput, Navigator, Refused, loiter_entry_point, loiter_takeoff_point,
};

/// QLOITER on the ground climbs only on a throttle stick above this (mid and a dead zone), µs;
/// at or below mid, or with no receiver signal, it stays landed as ArduPlane's does.
const QLOITER_CLIMB_STICK_US: u16 = 1600;

/// Home moves (and is announced) only by more than this, m.
const HOME_MOVE_M: f64 = 0.01;

impl Endpoint {
    /// The flight envelope now: the frame's origin, home and the `NAV_*_MAX` limits.
    pub(super) fn limits(&self) -> Limits {
        Limits {
            origin: self.origin,
            home_ned_m: self.home_ned_m,
            radius_max_m: self.params.value("NAV_RADIUS_MAX"),
            alt_max_m: self.params.value("NAV_ALT_MAX"),
        }
    }

    /// Where the vehicle is, local NED.
    fn pos_ned(&self) -> Vector3<f64> {
        paper_to_ned(&self.vehicle.telemetry().pos_m)
    }

    /// Runs `f` on the navigator with the vehicle's state, then acts on what it reported.
    fn run_nav<R>(
        &mut self,
        f: impl FnOnce(&mut Navigator, &NavInput<'_>, &mut Vec<NavEvent>) -> R,
    ) -> R {
        let limits = self.limits();
        let t = *self.vehicle.telemetry();
        let mut events = Vec::new();
        let inp = NavInput {
            now_us: self.now_us,
            mode: t.mode,
            armed: t.armed,
            landed: t.landed,
            pos_ned_m: paper_to_ned(&t.pos_m),
            mission: &self.mission,
            limits: &limits,
            wp_radius_m: self.params.value("Q_WP_RADIUS") / 100.0,
            speed_up_m_s: self.params.value("WP_SPEED_UP"),
            speed_dn_m_s: self.params.value("WP_SPEED_DN"),
            fixed_wing: FixedWingInput {
                vtol: t.vtol_state,
                vel_ned_m_s: paper_to_ned(&t.vel_m_s),
                airspeed_m_s: self.params.value("TRIM_ARSPD_CM") / 100.0,
                l1: L1Params {
                    period_s: self.params.value("NAVL1_PERIOD"),
                    damping: self.params.value("NAVL1_DAMPING"),
                },
                loiter_radius_m: match self.params.value("RTL_RADIUS").abs() {
                    r if t.mode == FlightMode::Rtl && r > 0.0 => r,
                    _ => self.params.value("WP_LOITER_RAD"),
                },
                wp_radius_m: self.params.value("WP_RADIUS"),
                gravity_m_s2: self.vehicle.config().airframe.gravity_m_s2,
                rtl_vtol_land: matches!(self.params.value("Q_RTL_MODE") as i32, 1 | 2),
                trans_decel_m_s2: self.params.value("Q_TRANS_DECEL"),
                guided_on_the_wing: self.params.value("Q_GUIDED_MODE") == 0.0,
                rtl_altitude_m: Some(self.params.value("RTL_ALTITUDE")).filter(|a| *a >= 0.0),
                vtol_auto: self.params.value("Q_ENABLE") == 2.0,
            },
        };
        let r = f(&mut self.navigator, &inp, &mut events);
        self.apply_nav_events(events);
        r
    }

    fn apply_nav_events(&mut self, events: Vec<NavEvent>) {
        for e in events {
            match e {
                NavEvent::Reached(seq) => self.item_reached(seq),
                NavEvent::Current(_) => {
                    let m = self.mission_current();
                    self.broadcast(&m);
                }
                NavEvent::SetMode(m) => {
                    let m = if m == FlightMode::Rtl {
                        self.rtl_or_qrtl()
                    } else {
                        m
                    };
                    self.vehicle.set_mode(m);
                }
                NavEvent::Info(text) => self.announce(apm::MavSeverity::MAV_SEVERITY_INFO, &text),
                NavEvent::Transition(forward) => {
                    if forward {
                        self.vehicle.start_forward_transition();
                    } else {
                        self.vehicle.start_back_transition();
                    }
                }
            }
        }
    }

    /// One navigation step: the guidance of GUIDED, AUTO and QRTL for the next period.
    pub(super) fn navigate(&mut self) {
        self.next_nav_us = self.now_us + NAV_PERIOD_US;
        let t = self.vehicle.telemetry();
        if !t.mode.is_autonomous() {
            if t.mode == FlightMode::QLoiter {
                if self.navigator.is_entering(t.mode) {
                    self.hold_here();
                } else if t.armed && t.landed && t.rc_us[2] > QLOITER_CLIMB_STICK_US {
                    // Throttle stick above mid: climb to `HOVER_ALT` above the spot.
                    let p = loiter_takeoff_point(
                        &paper_to_ned(&t.pos_m),
                        self.params.value("HOVER_ALT"),
                    );
                    self.vehicle
                        .set_position_setpoint(crate::model::frames::ned_to_paper(&p));
                }
            }
            // Nothing to navigate in the pilot and hover modes.
            let t = self.vehicle.telemetry();
            self.navigator.note_pilot_mode(t.mode, t.armed);
            return;
        }
        // A step may end the mission and change the mode: then once more, in the new mode.
        for _ in 0..2 {
            let mode = self.vehicle.telemetry().mode;
            let g = self.run_nav(|nav, inp, ev| nav.step(inp, ev));
            if self.vehicle.telemetry().mode == mode {
                if mode.is_autonomous() {
                    self.vehicle.set_guidance(g);
                }
                return;
            }
        }
    }

    /// QLOITER entered: hold where the vehicle is ([`loiter_entry_point`]), not where an
    /// earlier target was.
    fn hold_here(&mut self) {
        let t = self.vehicle.telemetry();
        let p = loiter_entry_point(&paper_to_ned(&t.pos_m));
        self.vehicle
            .set_position_setpoint(crate::model::frames::ned_to_paper(&p));
    }

    /// The stored mission changed: the navigator starts it over.
    pub(super) fn finish_mission_change(&mut self) {
        self.run_nav(|nav, inp, ev| nav.mission_changed(inp, ev));
        self.navigate();
    }

    /// ACK result of a navigator refusal, with its reason to the requester.
    fn refusal(&mut self, link: LinkKey, r: Result<(), Refused>) -> MavResult {
        match r {
            Ok(()) => {
                self.navigate();
                MavResult::MAV_RESULT_ACCEPTED
            }
            Err(e) => {
                self.say(link, apm::MavSeverity::MAV_SEVERITY_WARNING, &e.to_string());
                match e {
                    Refused::NotNow(_) => MavResult::MAV_RESULT_FAILED,
                    Refused::Invalid(_) => MavResult::MAV_RESULT_DENIED,
                }
            }
        }
    }

    /// NAV_TAKEOFF / NAV_VTOL_TAKEOFF: `param7` metres up, in GUIDED.
    pub(super) fn cmd_takeoff(&mut self, link: LinkKey, alt_m: f32) -> MavResult {
        let r = self.run_nav(|nav, inp, ev| nav.takeoff(f64::from(alt_m), inp, ev));
        self.refusal(link, r)
    }

    /// A global point (1e-7 degree, altitude in `frame_no`) as local NED; a missing latitude
    /// and longitude or altitude keeps the one of `keep`.
    fn global_target(
        &self,
        frame_no: u8,
        lat_e7: i32,
        lon_e7: i32,
        alt_m: f64,
        keep: &Vector3<f64>,
    ) -> Result<Vector3<f64>, Refused> {
        if !frame::is_global(frame_no) {
            return Err(Refused::Invalid(format!(
                "Target frame {frame_no} is not supported (global frames only)"
            )));
        }
        let limits = self.limits();
        let no_xy = (lat_e7 == 0 && lon_e7 == 0) || lat_e7 == i32::MAX || lon_e7 == i32::MAX;
        if !no_xy && !valid_lat_lon(lat_e7, lon_e7) {
            return Err(Refused::Invalid(
                "Target latitude/longitude out of range".into(),
            ));
        }
        let ned = limits.local_ned(frame_no, lat_e7, lon_e7, alt_m);
        Ok(Vector3::new(
            if no_xy { keep.x } else { ned.x },
            if no_xy { keep.y } else { ned.y },
            if alt_m.is_nan() { keep.z } else { ned.z },
        ))
    }

    /// DO_REPOSITION (192).
    pub(super) fn cmd_reposition(&mut self, link: LinkKey, c: &Command) -> MavResult {
        let p = c.params;
        let t = *self.vehicle.telemetry();
        // Bit 0 of param2 (MAV_DO_REPOSITION_FLAGS_CHANGE_MODE): switch to GUIDED first.
        if (p[1] as u32) & 1 != 0 && t.mode != FlightMode::Guided && t.armed && !t.landed {
            self.vehicle.set_mode(FlightMode::Guided);
            self.navigate();
        }
        let here = self.pos_ned();
        let keep = self.navigator.hold_point(&here);
        let target = if c.is_int {
            self.global_target(c.frame, c.x, c.y, f64::from(p[6]), &keep)
        } else {
            // COMMAND_LONG: degrees, altitude above home (ArduPilot's reading).
            let deg = |v: f32| {
                if v.is_nan() {
                    0
                } else {
                    deg_to_e7(f64::from(v))
                }
            };
            self.global_target(
                MavFrame::MAV_FRAME_GLOBAL_RELATIVE_ALT as u8,
                deg(p[4]),
                deg(p[5]),
                f64::from(p[6]),
                &keep,
            )
        };
        let r = match target {
            Ok(target) => self.run_nav(|nav, inp, ev| nav.reposition(target, inp, ev)),
            Err(e) => Err(e),
        };
        self.refusal(link, r)
    }

    /// A GUIDED position target (SET_POSITION_TARGET_*), local NED. No ACK exists for these:
    /// a target outside the envelope is refused with a STATUSTEXT; outside GUIDED it is
    /// ignored, as ArduPilot does.
    pub(super) fn guided_target(&mut self, link: LinkKey, target: Vector3<f64>) {
        match self.run_nav(|nav, inp, ev| nav.reposition(target, inp, ev)) {
            Ok(()) => self.navigate(),
            Err(Refused::NotNow(why)) => tracing::debug!("position target ignored: {why}"),
            Err(e @ Refused::Invalid(_)) => {
                self.say(link, apm::MavSeverity::MAV_SEVERITY_WARNING, &e.to_string());
            }
        }
    }

    /// SET_POSITION_TARGET_GLOBAL_INT: the position part, in GUIDED.
    pub(super) fn on_position_target_global(
        &mut self,
        link: LinkKey,
        m: &apm::SET_POSITION_TARGET_GLOBAL_INT_DATA,
    ) {
        use apm::PositionTargetTypemask as Mask;
        let ignore = Mask::POSITION_TARGET_TYPEMASK_X_IGNORE
            | Mask::POSITION_TARGET_TYPEMASK_Y_IGNORE
            | Mask::POSITION_TARGET_TYPEMASK_Z_IGNORE;
        if m.type_mask.intersects(ignore) {
            // Velocity and acceleration targets are not flown.
            return;
        }
        let here = self.pos_ned();
        let keep = self.navigator.hold_point(&here);
        match self.global_target(
            m.coordinate_frame as u8,
            m.lat_int,
            m.lon_int,
            f64::from(m.alt),
            &keep,
        ) {
            Ok(target) => self.guided_target(link, target),
            Err(e) => self.say(link, apm::MavSeverity::MAV_SEVERITY_WARNING, &e.to_string()),
        }
    }

    /// A MISSION_ITEM or MISSION_ITEM_INT with `current` = 2: ArduPilot's guided waypoint (what
    /// DroneKit's `simple_goto` sends). Flown in GUIDED only, as ArduPlane does; anything else is
    /// refused with the reason.
    pub(super) fn guided_item(
        &mut self,
        item: &crate::nav::mission::MissionItem,
    ) -> Result<(), String> {
        let t = *self.vehicle.telemetry();
        if t.mode != FlightMode::Guided {
            return Err(format!(
                "Guided waypoint refused: mode is {}, not GUIDED",
                t.mode
            ));
        }
        let here = self.pos_ned();
        let keep = self.navigator.hold_point(&here);
        let target = self
            .global_target(item.frame, item.x, item.y, f64::from(item.z), &keep)
            .map_err(|e| e.to_string())?;
        self.run_nav(|nav, inp, ev| nav.reposition(target, inp, ev))
            .map_err(|e| e.to_string())?;
        self.navigate();
        Ok(())
    }

    /// MISSION_START (300): AUTO from item `param1` (1 when 0).
    pub(super) fn cmd_mission_start(&mut self, link: LinkKey, first: f32) -> MavResult {
        if self.mission.count() <= 1 {
            self.say(
                link,
                apm::MavSeverity::MAV_SEVERITY_WARNING,
                "Mission start: no mission",
            );
            return MavResult::MAV_RESULT_FAILED;
        }
        let seq = if first.is_finite() && first >= 1.0 {
            first as u16
        } else {
            1
        };
        if let Err(why) = self.run_nav(|nav, inp, ev| nav.set_current(seq, inp, ev)) {
            self.say(link, apm::MavSeverity::MAV_SEVERITY_WARNING, &why);
            return MavResult::MAV_RESULT_DENIED;
        }
        self.apply_custom_mode(link, FlightMode::Auto.custom_mode())
    }

    /// DO_SET_MISSION_CURRENT (224) and MISSION_SET_CURRENT (41): the next item.
    pub(super) fn set_mission_current(&mut self, link: LinkKey, seq: f32) -> MavResult {
        if !(seq.is_finite() && (0.0..65535.0).contains(&seq)) {
            return MavResult::MAV_RESULT_DENIED;
        }
        let r = self.run_nav(|nav, inp, ev| nav.set_current(seq as u16, inp, ev));
        match r {
            Ok(()) => {
                self.navigate();
                let m = self.mission_current();
                self.send(link, &m);
                MavResult::MAV_RESULT_ACCEPTED
            }
            Err(why) => {
                self.say(link, apm::MavSeverity::MAV_SEVERITY_WARNING, &why);
                MavResult::MAV_RESULT_DENIED
            }
        }
    }

    /// HOME_POSITION now.
    pub(super) fn home_position(&self) -> apm::MavMessage {
        position::home_position(
            &self.origin,
            &self.home_ned_m,
            self.vehicle.telemetry().t_us,
        )
    }

    /// Home as mission item 0 (a NAV_WAYPOINT in the global frame, altitude above mean sea
    /// level), what ArduPilot serves in the home slot.
    pub(super) fn home_item(&self) -> crate::nav::mission::MissionItem {
        let p = self.origin.to_global(&self.home_ned_m);
        crate::nav::mission::MissionItem {
            x: p.lat_e7,
            y: p.lon_e7,
            z: p.alt_amsl_m as f32,
            command: MavCmd::MAV_CMD_NAV_WAYPOINT as u16,
            frame: MavFrame::MAV_FRAME_GLOBAL as u8,
            autocontinue: 1,
            ..Default::default()
        }
    }

    /// Moves home, telling every link when it moved.
    pub(super) fn set_home(&mut self, ned: Vector3<f64>) {
        let moved = (ned - self.home_ned_m).norm() > HOME_MOVE_M;
        self.home_ned_m = ned;
        if moved {
            let m = self.home_position();
            self.broadcast(&m);
        }
    }

    /// DO_SET_HOME (179): here (`param1` = 1) or the given point (altitude AMSL), inside the
    /// flying area.
    pub(super) fn cmd_set_home(&mut self, link: LinkKey, c: &Command) -> MavResult {
        let p = c.params;
        if p[0] == 1.0 {
            let here = self.pos_ned();
            self.set_home(here);
            return MavResult::MAV_RESULT_ACCEPTED;
        }
        let (frame_no, lat, lon) = if c.is_int {
            (c.frame, c.x, c.y)
        } else {
            (
                MavFrame::MAV_FRAME_GLOBAL as u8,
                deg_to_e7(f64::from(p[4])),
                deg_to_e7(f64::from(p[5])),
            )
        };
        let origin_home = Limits {
            home_ned_m: Vector3::zeros(),
            ..self.limits()
        };
        let target = if frame::is_global(frame_no) && valid_lat_lon(lat, lon) && p[6].is_finite() {
            let ned =
                origin_home.local_ned(MavFrame::MAV_FRAME_GLOBAL as u8, lat, lon, f64::from(p[6]));
            origin_home
                .check("Home", &Vector3::new(ned.x, ned.y, 0.0))
                .map(|()| ned)
                .map_err(|r| r.reason)
        } else {
            Err("Home: invalid position".into())
        };
        match target {
            Ok(ned) => {
                self.set_home(ned);
                MavResult::MAV_RESULT_ACCEPTED
            }
            Err(why) => {
                self.say(link, apm::MavSeverity::MAV_SEVERITY_WARNING, &why);
                MavResult::MAV_RESULT_DENIED
            }
        }
    }
}
