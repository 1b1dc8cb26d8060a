//! The navigator of the autonomous modes: GUIDED (take-off, reposition, position targets), AUTO
//! (the stored mission) and QRTL (home, then land). It decides, every [`NAV_PERIOD_US`] of sim
//! time, what the vehicle flies ([`Guidance`]: QLOITER's law to a point, QLAND's law, or idle on
//! the ground), and reports what a ground station must hear (an item reached, the current item,
//! a mode change at the end of the mission).
//!
//! It is a plain state machine: no I/O, no clock; the endpoint feeds it the vehicle's state and
//! the mission and applies what it returns. Frames: local NED (the motion-capture frame, z
//! down), m; the endpoint converts to and from the globe.
//!
//! Behaviour follows ArduPlane's quadplane in VTOL flight, where it has one:
//! - GUIDED on the ground waits for NAV_TAKEOFF, which climbs straight up to the altitude above
//!   where the vehicle stands; then it holds, and a reposition or a position target moves the
//!   point it holds. Entering GUIDED in the air holds where the vehicle is.
//! - AUTO flies the mission from the current item (item 1 after an upload; item 0 is home).
//!   VTOL_TAKEOFF climbs straight up; WAYPOINT and LOITER_TIME fly to their point and hold
//!   `param1` seconds there; VTOL_LAND flies to its point and lands; RETURN_TO_LAUNCH flies home
//!   and lands. An item is reached within `WP_RADIUS` (or a waypoint's `param2`) of its point, a
//!   take-off at its altitude, a landing when the vehicle has touched down and disarmed. When
//!   the last item is done in the air, the mode changes to RTL ("Mission complete"), as
//!   ArduPlane's does. Outside VTOL mode (a DO_VTOL_TRANSITION to MC sets it) the position items
//!   are flown on the wing, as ArduPlane flies them (see [`fixed_wing`]).
//! - QRTL flies home at its altitude, then lands and disarms. RTL flies home on the wing, then
//!   circles home or lands by `Q_RTL_MODE`.
//!
//! Altitude changes are flown at `WP_SPEED_UP`/`WP_SPEED_DN`: the altitude the controller holds
//! moves towards the target at that rate, so a take-off does not overshoot the way a step in the
//! altitude law (37) would. Horizontal moves are steps: the nested saturations bound the tilt,
//! and so the speed, by design.

use mavlink::dialects::ardupilotmega::{MavCmd, MavVtolState};
use nalgebra::{Vector2, Vector3};

use crate::model::frames::ned_to_paper;
use crate::model::mode::{FlightMode, Guidance, VtolState};
use crate::nav::fixed_wing::{self, FixedWingInput};
use crate::nav::globe::horizontal_distance_m;
use crate::nav::mission::{Limits, Mission, MissionItem};

/// Navigation period, µs of sim time (50 Hz).
pub const NAV_PERIOD_US: u64 = 20_000;

/// A take-off is complete within this of its altitude, m.
pub const TAKEOFF_ALT_TOLERANCE_M: f64 = 0.1;

/// A landing descends on QLOITER's law over its point (so it lands there) down to this height,
/// then on QLAND's law to touch down (ArduPlane's `Q_LAND_FINAL_ALT`, scaled to the twin), m.
/// The ground is the motion-capture frame's floor, z = 0.
pub const LAND_FINAL_ALT_M: f64 = 0.5;

/// What the navigator needs to know about the vehicle and its settings.
#[derive(Debug, Clone, Copy)]
pub struct NavInput<'a> {
    /// Sim time, µs.
    pub now_us: u64,
    /// Current flight mode.
    pub mode: FlightMode,
    /// Armed.
    pub armed: bool,
    /// On the ground.
    pub landed: bool,
    /// Where the vehicle is (local NED), m.
    pub pos_ned_m: Vector3<f64>,
    /// The stored mission.
    pub mission: &'a Mission,
    /// The globe, home and the flight envelope.
    pub limits: &'a Limits,
    /// `WP_RADIUS`, m.
    pub wp_radius_m: f64,
    /// `WP_SPEED_UP`, m/s.
    pub speed_up_m_s: f64,
    /// `WP_SPEED_DN`, m/s.
    pub speed_dn_m_s: f64,
    /// The vehicle's phase and what the fixed-wing legs need.
    pub fixed_wing: FixedWingInput,
}

/// What the endpoint must tell the ground stations or do.
#[derive(Debug, Clone, PartialEq)]
pub enum NavEvent {
    /// MISSION_ITEM_REACHED for this item.
    Reached(u16),
    /// The current mission item changed (MISSION_CURRENT).
    Current(u16),
    /// Change the flight mode (the end of a mission).
    SetMode(FlightMode),
    /// An information text (STATUSTEXT, severity INFO).
    Info(String),
    /// Start a transition: to forward flight (`true`) or back to a hover.
    Transition(bool),
}

/// Why a GUIDED request is refused.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum Refused {
    /// Not possible in the vehicle's state (mode, armed, flying).
    #[error("{0}")]
    NotNow(String),
    /// The target is outside the flight envelope or not a valid value.
    #[error("{0}")]
    Invalid(String),
}

/// Where a mission stands (`MISSION_STATE`).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum MissionState {
    /// No item to fly (nothing stored, or only the home slot).
    NoMission,
    /// Not started since the upload, the last reset or the last completion.
    NotStarted,
    /// Being flown (AUTO).
    Active,
    /// Started, but the vehicle left AUTO.
    Paused,
    /// Every item done.
    Complete,
}

/// What the vehicle is doing towards the current target.
#[derive(Debug, Clone, Copy, PartialEq)]
enum Leg {
    /// Armed or not, on the ground, nothing to fly: motors idle.
    Idle,
    /// Climb straight up at this point to the altitude (NED z), then the follow-up.
    Takeoff { xy: Vector2<f64>, z: f64 },
    /// Fly to the point and stay there.
    Goto { xy: Vector2<f64>, z: f64 },
    /// Fly to the point at the current altitude, then land.
    LandAt { xy: Vector2<f64>, z: f64 },
    /// Descending over the point to touch down (`last`: below [`LAND_FINAL_ALT_M`], on QLAND's law).
    Landing { xy: Vector2<f64>, last: bool },
    /// On the wing: fly the line to the point (a waypoint or a loiter's centre).
    Cruise {
        from: Vector2<f64>,
        xy: Vector2<f64>,
        z: f64,
    },
    /// On the wing: circle the point (NAV_LOITER_TIME reached).
    Circle { xy: Vector2<f64>, z: f64 },
    /// On the wing toward a VTOL landing: the back transition starts
    /// [`APPROACH_DISTANCE_M`] from the point.
    Approach {
        from: Vector2<f64>,
        xy: Vector2<f64>,
        z: f64,
    },
}

/// The navigator (see the module docs).
#[derive(Debug, Clone)]
pub struct Navigator {
    mode: Option<FlightMode>,
    armed: bool,
    leg: Leg,
    /// The altitude the controller holds (NED z), moving towards the leg's at the climb rate.
    z_cmd: f64,
    /// The mission item in progress or next (≥ 1 when the mission has items).
    current: u16,
    state: MissionState,
    /// AUTO: when the hold at the current item's point ends, µs (None: not there yet).
    hold_until_us: Option<u64>,
    /// Sim time of the last step, µs (the climb rate's time base).
    last_step_us: Option<u64>,
    /// AUTO flies its position items in a hover (ArduPlane's `auto_state.vtol_mode`): set by a
    /// DO_VTOL_TRANSITION to MC, cleared by one to FW and whenever AUTO is entered.
    vtol_mode: bool,
}

impl Default for Navigator {
    fn default() -> Self {
        Self {
            mode: None,
            armed: false,
            leg: Leg::Idle,
            z_cmd: 0.0,
            current: 1,
            state: MissionState::NotStarted,
            hold_until_us: None,
            last_step_us: None,
            vtol_mode: false,
        }
    }
}

impl Navigator {
    /// A navigator with nothing to do.
    #[must_use]
    pub fn new() -> Self {
        Self::default()
    }

    /// The current mission item (what MISSION_CURRENT reports).
    #[must_use]
    pub fn current(&self) -> u16 {
        self.current
    }

    /// Where the mission stands, for a mission of `count` items (home slot included).
    #[must_use]
    pub fn mission_state(&self, count: u16) -> MissionState {
        if count <= 1 {
            MissionState::NoMission
        } else {
            self.state
        }
    }

    /// The point the vehicle is heading to (local NED), if it flies to one.
    #[must_use]
    pub fn target_ned_m(&self) -> Option<Vector3<f64>> {
        match self.leg {
            Leg::Takeoff { xy, z }
            | Leg::Goto { xy, z }
            | Leg::LandAt { xy, z }
            | Leg::Cruise { xy, z, .. }
            | Leg::Circle { xy, z }
            | Leg::Approach { xy, z, .. } => Some(Vector3::new(xy.x, xy.y, z)),
            Leg::Landing { xy, .. } => Some(Vector3::new(xy.x, xy.y, 0.0)),
            Leg::Idle => None,
        }
    }

    /// The leg follows the vehicle's phase: a point is flown to on the wing once the vehicle
    /// flies forward, in hover once it is back in a hover.
    fn follow_phase(&mut self, inp: &NavInput<'_>) {
        let here = inp.pos_ned_m.xy();
        let wing = inp.fixed_wing.on_the_wing();
        let hover = inp.fixed_wing.vtol == VtolState::Mc;
        self.leg = match self.leg {
            Leg::Goto { xy, z } if wing => Leg::Cruise { from: here, xy, z },
            Leg::LandAt { xy, z } if wing => Leg::Approach { from: here, xy, z },
            Leg::Cruise { xy, z, .. } | Leg::Circle { xy, z } if hover => {
                self.z_cmd = inp.pos_ned_m.z;
                Leg::Goto { xy, z }
            }
            Leg::Approach { xy, .. } if hover => {
                self.z_cmd = inp.pos_ned_m.z;
                Leg::LandAt {
                    xy,
                    z: inp.pos_ned_m.z,
                }
            }
            leg => leg,
        };
    }

    /// Takes note of mode changes, arming and disarming since the last call, starting what
    /// the new mode does. Every command that acts on the navigator calls this first, so it sees
    /// a mode change made by the previous frame even before the next navigation step.
    pub fn sync(&mut self, inp: &NavInput<'_>, events: &mut Vec<NavEvent>) {
        let entered = self.mode != Some(inp.mode);
        let armed_now = inp.armed && !self.armed;
        let disarmed_now = !inp.armed && self.armed;
        if entered && self.mode == Some(FlightMode::Auto) && self.state == MissionState::Active {
            self.state = MissionState::Paused;
        }
        if entered && inp.mode == FlightMode::Auto {
            // ArduPlane's ModeAuto::_enter: position items are flown on the wing, or in a hover
            // with Q_ENABLE 2 (VTOL AUTO).
            self.vtol_mode = inp.fixed_wing.vtol_auto;
        }
        self.mode = Some(inp.mode);
        self.armed = inp.armed;
        if !inp.mode.is_autonomous() {
            self.leg = Leg::Idle;
            return;
        }
        if disarmed_now {
            // QLAND's law disarms on the ground: a landing item is then done.
            self.landing_done(inp, events);
            self.leg = Leg::Idle;
            return;
        }
        if !(entered || armed_now) || !inp.armed {
            if entered {
                self.leg = Leg::Idle;
            }
            return;
        }
        // The vehicle starts from where it is.
        self.z_cmd = inp.pos_ned_m.z;
        self.hold_until_us = None;
        let here = inp.pos_ned_m;
        match inp.mode {
            FlightMode::Guided => {
                self.leg = if inp.landed {
                    Leg::Idle
                } else {
                    Leg::Goto {
                        xy: here.xy(),
                        z: here.z,
                    }
                };
            }
            FlightMode::QRtl | FlightMode::Rtl => self.start_return(inp, events),
            FlightMode::Auto => {
                // Resume where the mission was; a completed one starts over (ArduPilot).
                let seq = if self.state == MissionState::Complete {
                    1
                } else {
                    self.current.max(1)
                };
                self.state = MissionState::Active;
                self.start_item(seq, inp, events);
            }
            _ => {}
        }
    }

    /// Whether `mode` is new since the navigator's last call (it was entered just now).
    #[must_use]
    pub fn is_entering(&self, mode: FlightMode) -> bool {
        self.mode != Some(mode)
    }

    /// Takes note of a mode the navigator does not fly (the pilot and hover modes), as
    /// [`Navigator::sync`] would, without the vehicle's state: the endpoint's cheap path for the
    /// modes where there is nothing to navigate.
    pub fn note_pilot_mode(&mut self, mode: FlightMode, armed: bool) {
        if self.mode != Some(mode)
            && self.mode == Some(FlightMode::Auto)
            && self.state == MissionState::Active
        {
            self.state = MissionState::Paused;
        }
        self.mode = Some(mode);
        self.armed = armed;
        self.leg = Leg::Idle;
        self.last_step_us = None;
    }

    fn start_return(&mut self, inp: &NavInput<'_>, events: &mut Vec<NavEvent>) {
        let here = inp.pos_ned_m;
        if inp.mode == FlightMode::Rtl && !inp.landed && inp.fixed_wing.vtol == VtolState::Mc {
            // RTL is a fixed-wing mode: a hovering vehicle goes to the wing to fly home.
            events.push(NavEvent::Transition(true));
        }
        // RTL flies home at RTL_ALTITUDE above home (negative: where it is), as ArduPlane's
        // get_RTL_altitude_cm; QRTL at its altitude.
        let z = match inp.fixed_wing.rtl_altitude_m {
            Some(alt) if inp.mode == FlightMode::Rtl => inp.limits.home_ned_m.z - alt,
            _ => here.z.min(self.z_cmd),
        };
        self.leg = if inp.landed {
            landing_here(&here)
        } else {
            Leg::LandAt {
                xy: inp.limits.home_ned_m.xy(),
                z,
            }
        };
    }

    /// Starts mission item `seq` (AUTO). Past the end: the mission is complete.
    fn start_item(&mut self, seq: u16, inp: &NavInput<'_>, events: &mut Vec<NavEvent>) {
        self.hold_until_us = None;
        let item = match inp.mission.get(seq) {
            Some(i) if seq >= 1 => *i,
            _ => {
                self.complete_mission(inp, events);
                return;
            }
        };
        if seq != self.current {
            self.current = seq;
            events.push(NavEvent::Current(seq));
        }
        let here = inp.pos_ned_m;
        let t = item.target(inp.limits);
        let xy = t.xy_ned_m.unwrap_or_else(|| here.xy());
        self.leg = match item.cmd() {
            Some(MavCmd::MAV_CMD_NAV_TAKEOFF | MavCmd::MAV_CMD_NAV_VTOL_TAKEOFF) => Leg::Takeoff {
                xy: here.xy(),
                z: t.z_ned_m,
            },
            Some(MavCmd::MAV_CMD_NAV_WAYPOINT | MavCmd::MAV_CMD_NAV_LOITER_TIME) => {
                self.to_the_wing(inp, events);
                Leg::Goto { xy, z: t.z_ned_m }
            }
            Some(MavCmd::MAV_CMD_NAV_LAND | MavCmd::MAV_CMD_NAV_VTOL_LAND) => {
                if inp.landed {
                    landing_here(&here)
                } else {
                    // ArduPlane's poscontrol_init_approach: a landing point farther than the
                    // transition threshold is approached on the wing (in VTOL mode too).
                    let dist = (xy - here.xy()).norm();
                    if inp.fixed_wing.vtol == VtolState::Mc {
                        if dist >= inp.fixed_wing.transition_threshold_m() {
                            events.push(NavEvent::Info(format!("VTOL approach d={dist:.1}")));
                            if inp.mode == FlightMode::Auto && inp.armed {
                                events.push(NavEvent::Transition(true));
                            }
                        } else {
                            events.push(NavEvent::Info(format!("VTOL Position1 d={dist:.1}")));
                        }
                    }
                    Leg::LandAt { xy, z: here.z }
                }
            }
            Some(MavCmd::MAV_CMD_DO_VTOL_TRANSITION) => {
                let forward = item.params[0] as u8 == MavVtolState::MAV_VTOL_STATE_FW as u8;
                self.vtol_mode = !forward;
                events.push(NavEvent::Transition(forward));
                self.item_done(inp, events, "Transition");
                return;
            }
            Some(MavCmd::MAV_CMD_NAV_RETURN_TO_LAUNCH) => {
                if inp.landed {
                    landing_here(&here)
                } else {
                    self.to_the_wing(inp, events);
                    Leg::LandAt {
                        xy: inp.limits.home_ned_m.xy(),
                        z: here.z.min(self.z_cmd),
                    }
                }
            }
            // Refused at upload; an unknown item is skipped rather than flown.
            _ => {
                self.item_done(inp, events, "Skipped");
                return;
            }
        };
    }

    /// AUTO outside VTOL mode flies its position items on the wing, as ArduPlane does (its
    /// `in_vtol_auto` is false for them): a vehicle hovering in the air starts a forward
    /// transition (the `paper` model has none, and keeps flying them in a hover).
    fn to_the_wing(&self, inp: &NavInput<'_>, events: &mut Vec<NavEvent>) {
        if inp.mode == FlightMode::Auto
            && !self.vtol_mode
            && inp.armed
            && !inp.landed
            && inp.fixed_wing.vtol == VtolState::Mc
        {
            events.push(NavEvent::Transition(true));
        }
    }

    /// MAV_CMD_DO_VTOL_TRANSITION taken in AUTO: to MC, the mission's position items are
    /// flown in a hover from now on; to FW, on the wing (ArduPlane's `handle_do_vtol_transition`).
    pub fn set_vtol_mode(&mut self, hover: bool) {
        self.vtol_mode = hover;
    }

    fn complete_mission(&mut self, inp: &NavInput<'_>, events: &mut Vec<NavEvent>) {
        self.state = MissionState::Complete;
        // Nothing of AUTO is left to fly: a leg started in another mode (a GUIDED take-off
        // still climbing) must not complete as if it were a mission item.
        self.leg = Leg::Idle;
        if inp.armed && !inp.landed {
            // ArduPlane's exit_mission_callback: RTL, home as a plane, then Q_RTL_MODE (the
            // endpoint makes it QRTL where RTL is: Q_RTL_MODE 3, the `paper` model).
            events.push(NavEvent::Info(
                "Mission complete, changing mode to RTL".into(),
            ));
            events.push(NavEvent::SetMode(FlightMode::Rtl));
        } else {
            events.push(NavEvent::Info("Mission complete".into()));
        }
    }

    /// The current item is done: report it and start the next.
    fn item_done(&mut self, inp: &NavInput<'_>, events: &mut Vec<NavEvent>, what: &str) {
        let seq = self.current;
        let dist = self
            .target_ned_m()
            .map_or(0.0, |t| (t - inp.pos_ned_m).norm());
        events.push(NavEvent::Reached(seq));
        events.push(NavEvent::Info(format!("{what} #{seq} dist {dist:.1}m")));
        self.start_item(seq.saturating_add(1), inp, events);
    }

    /// One navigation step: what to fly now, and what happened.
    pub fn step(&mut self, inp: &NavInput<'_>, events: &mut Vec<NavEvent>) -> Guidance {
        self.sync(inp, events);
        let dt_s = self
            .last_step_us
            .map_or(0.0, |t| inp.now_us.saturating_sub(t) as f64 * 1e-6)
            .min(1.0);
        self.last_step_us = Some(inp.now_us);
        if !inp.mode.is_autonomous() || !inp.armed {
            return Guidance::Idle;
        }
        self.follow_phase(inp);
        let here = inp.pos_ned_m;
        let radius = self.item_radius(inp);
        match self.leg {
            Leg::Idle | Leg::Circle { .. } => {}
            Leg::Cruise { .. } | Leg::Approach { .. } => self.wing_leg_step(inp, events, radius),
            Leg::Takeoff { xy, z } => {
                if here.z <= z + TAKEOFF_ALT_TOLERANCE_M {
                    // At altitude: hold there.
                    self.leg = Leg::Goto { xy, z };
                    if inp.mode == FlightMode::Auto {
                        self.item_done(inp, events, "Takeoff complete");
                    } else {
                        events.push(NavEvent::Info(format!(
                            "Takeoff complete at {:.1}m",
                            inp.limits.home_ned_m.z - here.z
                        )));
                    }
                }
            }
            Leg::Goto { xy, z } => {
                if inp.mode == FlightMode::Auto {
                    let arrived = (Vector3::new(xy.x, xy.y, z) - here).norm() <= radius;
                    if arrived && self.hold_until_us.is_none() {
                        let hold_s = self.item_hold_s(inp);
                        self.hold_until_us = Some(inp.now_us + (hold_s * 1e6) as u64);
                    }
                    if self.hold_until_us.is_some_and(|t| inp.now_us >= t) {
                        self.item_done(inp, events, "Reached waypoint");
                    }
                }
            }
            Leg::LandAt { xy, .. } => {
                let close = horizontal_distance_m(&here, &Vector3::new(xy.x, xy.y, 0.0));
                if close <= radius {
                    self.leg = Leg::Landing { xy, last: false };
                }
            }
            Leg::Landing { xy, last: false } => {
                if inp.landed || here.z >= -LAND_FINAL_ALT_M {
                    self.leg = Leg::Landing { xy, last: true };
                }
            }
            Leg::Landing { last: true, .. } => {}
        }
        if matches!(self.leg, Leg::Circle { .. })
            && self.hold_until_us.is_some_and(|t| inp.now_us >= t)
        {
            self.item_done(inp, events, "Loiter done");
        }
        // In AUTO a landing item is reached at touchdown (the vehicle then disarms itself).
        if inp.landed {
            self.landing_done(inp, events);
        }
        self.guidance(dt_s, inp)
    }

    /// A fixed-wing leg's step: a waypoint reached (inside its radius or passed), a loiter
    /// point reached (the circle starts), an approach close enough for the back transition (or,
    /// in RTL, for QRTL or the circle of `Q_RTL_MODE`).
    fn wing_leg_step(&mut self, inp: &NavInput<'_>, events: &mut Vec<NavEvent>, radius: f64) {
        let here = inp.pos_ned_m;
        match self.leg {
            Leg::Cruise { from, xy, z } => {
                let close = horizontal_distance_m(&here, &Vector3::new(xy.x, xy.y, 0.0));
                let loiter = inp.mission.get(self.current).map(|i| i.command)
                    == Some(MavCmd::MAV_CMD_NAV_LOITER_TIME as u16);
                if inp.mode == FlightMode::Guided {
                    // A GUIDED target on the wing is circled once reached (ArduPlane's guided
                    // loiter at WP_LOITER_RAD).
                    if close <= inp.fixed_wing.loiter_radius_m
                        || fixed_wing::passed(&from, &xy, &here.xy())
                    {
                        self.leg = Leg::Circle { xy, z };
                    }
                } else if inp.mode == FlightMode::Auto
                    && (close <= radius || fixed_wing::passed(&from, &xy, &here.xy()))
                {
                    if loiter {
                        let hold_s = self.item_hold_s(inp);
                        self.hold_until_us = Some(inp.now_us + (hold_s * 1e6) as u64);
                        self.leg = Leg::Circle { xy, z };
                    } else {
                        self.item_done(inp, events, "Reached waypoint");
                    }
                }
            }
            Leg::Approach { xy, z, .. } => {
                let fw = &inp.fixed_wing;
                let close = horizontal_distance_m(&here, &Vector3::new(xy.x, xy.y, 0.0));
                if fw.vtol != VtolState::Fw {
                    return;
                }
                if inp.mode != FlightMode::Rtl {
                    if close <= fixed_wing::APPROACH_DISTANCE_M {
                        events.push(NavEvent::Transition(false));
                    }
                } else if fw.rtl_vtol_land {
                    // Q_RTL_MODE 1: within the larger of the RTL radius and the stopping
                    // distance of home, land as QRTL does (ArduPlane's ModeRTL::switch_QRTL).
                    let stop = fixed_wing::stopping_distance_m(
                        fw.vel_ned_m_s.xy().norm(),
                        fw.trans_decel_m_s2,
                    );
                    if close <= fw.loiter_radius_m.max(stop) {
                        events.push(NavEvent::Info("RTL: switching to QRTL".into()));
                        events.push(NavEvent::SetMode(FlightMode::QRtl));
                    }
                } else if close <= fw.loiter_radius_m {
                    // Q_RTL_MODE 0: circle home on the wing.
                    self.leg = Leg::Circle { xy, z };
                }
            }
            _ => {}
        }
    }

    /// AUTO: the landing the current item asked for is over (touchdown or disarm).
    fn landing_done(&mut self, inp: &NavInput<'_>, events: &mut Vec<NavEvent>) {
        let landing_item = matches!(
            inp.mission.get(self.current).and_then(MissionItem::cmd),
            Some(
                MavCmd::MAV_CMD_NAV_LAND
                    | MavCmd::MAV_CMD_NAV_VTOL_LAND
                    | MavCmd::MAV_CMD_NAV_RETURN_TO_LAUNCH
            )
        );
        if matches!(self.leg, Leg::Landing { .. })
            && inp.mode == FlightMode::Auto
            && self.state == MissionState::Active
            && landing_item
        {
            events.push(NavEvent::Reached(self.current));
            events.push(NavEvent::Info(format!("Landed #{}", self.current)));
            self.state = MissionState::Complete;
            events.push(NavEvent::Info("Mission complete".into()));
        }
    }

    /// The radius an item is reached within: a waypoint's `param2`, else in a hover
    /// `Q_WP_RADIUS`, on the wing `WP_RADIUS` but at most the L1 distance (ArduPlane's
    /// `turn_distance` for a square turn).
    fn item_radius(&self, inp: &NavInput<'_>) -> f64 {
        let fw = &inp.fixed_wing;
        let default = if fw.on_the_wing() {
            let l1 = fw.l1.distance_m(fw.vel_ned_m_s.xy().norm());
            fw.wp_radius_m.min(l1)
        } else {
            inp.wp_radius_m
        };
        if inp.mode != FlightMode::Auto {
            return default;
        }
        match inp.mission.get(self.current) {
            Some(i) if i.command == MavCmd::MAV_CMD_NAV_WAYPOINT as u16 && i.params[1] > 0.0 => {
                f64::from(i.params[1])
            }
            _ => default,
        }
    }

    fn item_hold_s(&self, inp: &NavInput<'_>) -> f64 {
        match inp.mission.get(self.current) {
            Some(i)
                if i.command == MavCmd::MAV_CMD_NAV_WAYPOINT as u16
                    || i.command == MavCmd::MAV_CMD_NAV_LOITER_TIME as u16 =>
            {
                f64::from(i.params[0]).clamp(0.0, 3600.0)
            }
            _ => 0.0,
        }
    }

    /// The guidance for the current leg, moving the held altitude at the climb rates.
    fn guidance(&mut self, dt_s: f64, inp: &NavInput<'_>) -> Guidance {
        let (xy, z) = match self.leg {
            Leg::Idle => return Guidance::Idle,
            Leg::Landing { last: true, .. } => return Guidance::Land,
            // Down to the final height over the point, at the descent rate.
            Leg::Landing { xy, last: false } => (xy, 0.0),
            Leg::Takeoff { xy, z } | Leg::Goto { xy, z } | Leg::LandAt { xy, z } => (xy, z),
            Leg::Cruise { from, xy, z } | Leg::Approach { from, xy, z } => {
                return fixed_wing::track(&inp.fixed_wing, &inp.pos_ned_m, &from, &xy, z);
            }
            Leg::Circle { xy, z } => {
                return fixed_wing::loiter(&inp.fixed_wing, &inp.pos_ned_m, &xy, z);
            }
        };
        let dz = z - self.z_cmd;
        // NED: a negative dz is a climb.
        let max = if dz < 0.0 {
            inp.speed_up_m_s
        } else {
            inp.speed_dn_m_s
        } * dt_s;
        self.z_cmd += dz.clamp(-max, max);
        let ned = Vector3::new(xy.x, xy.y, self.z_cmd);
        Guidance::Position(ned_to_paper(&ned))
    }

    /// MISSION_SET_CURRENT / DO_SET_MISSION_CURRENT: the item AUTO flies next (0 means 1, as
    /// the home slot is never flown). In AUTO and armed the vehicle turns to it at once.
    ///
    /// # Errors
    /// The sequence number is past the end of the mission.
    pub fn set_current(
        &mut self,
        seq: u16,
        inp: &NavInput<'_>,
        events: &mut Vec<NavEvent>,
    ) -> Result<(), String> {
        self.sync(inp, events);
        let count = inp.mission.count();
        let seq = seq.max(1);
        if seq >= count {
            return Err(format!("Mission item {seq} does not exist ({count} items)"));
        }
        if inp.mode == FlightMode::Auto && inp.armed {
            self.state = MissionState::Active;
            self.start_item(seq, inp, events);
        } else {
            if self.state == MissionState::Complete {
                self.state = MissionState::NotStarted;
            }
            if seq != self.current {
                self.current = seq;
                events.push(NavEvent::Current(seq));
            }
        }
        Ok(())
    }

    /// The stored mission was replaced or cleared: the mission starts over at item 1 (and AUTO,
    /// if flying it, turns to the new item 1).
    pub fn mission_changed(&mut self, inp: &NavInput<'_>, events: &mut Vec<NavEvent>) {
        self.sync(inp, events);
        self.state = MissionState::NotStarted;
        if inp.mode == FlightMode::Auto && inp.armed {
            self.state = MissionState::Active;
            self.current = 0;
            self.start_item(1, inp, events);
        } else if self.current != 1 {
            self.current = 1;
            events.push(NavEvent::Current(1));
        }
    }
}

/// Where QLOITER holds when it is entered (local NED), as ArduPlane's QLOITER does: the
/// position and altitude at entry, on the ground the spot itself (the vehicle stays landed,
/// motors at idle, until the throttle stick asks for a climb: [`loiter_takeoff_point`]).
#[must_use]
pub fn loiter_entry_point(here: &Vector3<f64>) -> Vector3<f64> {
    *here
}

/// Where QLOITER climbs to from the ground when the throttle stick is above mid (local NED):
/// `hover_alt_m` above the spot.
#[must_use]
pub fn loiter_takeoff_point(here: &Vector3<f64>, hover_alt_m: f64) -> Vector3<f64> {
    Vector3::new(here.x, here.y, here.z - hover_alt_m)
}

/// A landing where the vehicle stands (already on the ground, or told to land here).
fn landing_here(here: &Vector3<f64>) -> Leg {
    Leg::Landing {
        xy: here.xy(),
        last: true,
    }
}

#[path = "navigation_guided.rs"]
mod guided;

#[cfg(test)]
#[path = "navigation_tests.rs"]
mod tests;
