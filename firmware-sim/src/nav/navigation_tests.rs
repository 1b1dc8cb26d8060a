//! The navigator's unit tests: take-off, AUTO missions, landing items, GUIDED holds.

use super::*;
use crate::nav::mission::MissionItem;
use crate::nav::mission::test_items::{self, limits};
use mavlink::dialects::ardupilotmega::MavFrame;

struct World {
    nav: Navigator,
    mission: Mission,
    limits: Limits,
    mode: FlightMode,
    armed: bool,
    pos: Vector3<f64>,
    now_us: u64,
    events: Vec<NavEvent>,
    vtol_auto: bool,
}

impl World {
    fn new(mission: Mission) -> Self {
        Self {
            nav: Navigator::new(),
            mission,
            limits: limits(),
            mode: FlightMode::QStabilize,
            armed: false,
            pos: Vector3::zeros(),
            now_us: 0,
            events: Vec::new(),
            vtol_auto: false,
        }
    }

    fn input(&self) -> NavInput<'_> {
        NavInput {
            now_us: self.now_us,
            mode: self.mode,
            armed: self.armed,
            landed: self.pos.z >= 0.0,
            pos_ned_m: self.pos,
            mission: &self.mission,
            limits: &self.limits,
            wp_radius_m: 0.3,
            speed_up_m_s: 1.0,
            speed_dn_m_s: 0.5,
            fixed_wing: crate::nav::fixed_wing::FixedWingInput {
                vtol_auto: self.vtol_auto,
                ..Default::default()
            },
        }
    }

    /// Flies `seconds` with a perfect vehicle: it is wherever the guidance says (a landing
    /// sinks at 0.5 m/s and disarms on touchdown, as the vehicle's QLAND does).
    fn fly(&mut self, seconds: f64) -> Vec<Guidance> {
        let mut out = Vec::new();
        let steps = (seconds * 1e6 / NAV_PERIOD_US as f64) as usize;
        for _ in 0..steps {
            self.now_us += NAV_PERIOD_US;
            let mut ev = Vec::new();
            let inp = self.input();
            let mut nav = self.nav.clone();
            let g = nav.step(&inp, &mut ev);
            self.nav = nav;
            for e in &ev {
                if let NavEvent::SetMode(m) = e {
                    self.mode = *m;
                }
            }
            self.events.extend(ev);
            match g {
                Guidance::Position(p) => self.pos = crate::model::frames::paper_to_ned(&p),
                Guidance::Land => {
                    self.pos.z = (self.pos.z + 0.5 * NAV_PERIOD_US as f64 * 1e-6).min(0.0);
                    if self.pos.z >= 0.0 {
                        self.armed = false;
                    }
                }
                Guidance::Idle | Guidance::Forward(_) => {}
            }
            out.push(g);
        }
        out
    }

    /// Calls the navigator as the endpoint does (a command between steps).
    fn call<R>(
        &mut self,
        f: impl FnOnce(&mut Navigator, &NavInput<'_>, &mut Vec<NavEvent>) -> R,
    ) -> R {
        let mut nav = self.nav.clone();
        let mut ev = Vec::new();
        let r = f(&mut nav, &self.input(), &mut ev);
        self.nav = nav;
        self.events.extend(ev);
        r
    }

    fn reached(&self) -> Vec<u16> {
        self.events
            .iter()
            .filter_map(|e| match e {
                NavEvent::Reached(s) => Some(*s),
                _ => None,
            })
            .collect()
    }
}

fn item(command: u16, north_m: f64, alt: f32, hold: f32) -> MissionItem {
    let l = limits();
    let p = l.origin.to_global(&Vector3::new(north_m, 0.0, 0.0));
    let (x, y) = if north_m == 0.0 {
        (0, 0)
    } else {
        (p.lat_e7, p.lon_e7)
    };
    test_items::item(command, [hold, 0.0, 0.0, 0.0], x, y, alt)
}

#[test]
fn guided_takeoff_climbs_at_the_climb_rate_then_holds() {
    let mut w = World::new(Mission::default());
    w.mode = FlightMode::Guided;
    let e = w.call(|n, i, e| n.takeoff(2.0, i, e)).unwrap_err();
    assert_eq!(e, Refused::NotNow("Takeoff: must be armed".into()));
    w.armed = true;
    assert_eq!(w.fly(0.1), vec![Guidance::Idle; 5], "idle until take-off");
    let e = w.call(|n, i, e| n.takeoff(60.0, i, e)).unwrap_err();
    assert!(
        matches!(&e, Refused::Invalid(t) if t.contains("NAV_ALT_MAX")),
        "{e}"
    );
    w.call(|n, i, e| n.takeoff(2.0, i, e)).unwrap();
    w.fly(1.0);
    assert!((w.pos.z + 1.0).abs() < 0.03, "1 m/s climb: {}", w.pos.z);
    w.fly(1.5);
    assert!((w.pos.z + 2.0).abs() < 1e-9, "{}", w.pos.z);
    assert!(
        w.events
            .iter()
            .any(|e| matches!(e, NavEvent::Info(t) if t.starts_with("Takeoff complete")))
    );
    let flying = w.call(|n, i, e| n.takeoff(2.0, i, e));
    assert!(flying.is_err(), "already flying");
    // Reposition 5 m north, then a refused one 150 m away.
    w.call(|n, i, e| n.reposition(Vector3::new(5.0, 0.0, -2.0), i, e))
        .unwrap();
    w.fly(0.1);
    assert_eq!(w.pos, Vector3::new(5.0, 0.0, -2.0));
    let e = w
        .call(|n, i, e| n.reposition(Vector3::new(150.0, 0.0, -2.0), i, e))
        .unwrap_err();
    assert_eq!(
        e.to_string(),
        "Reposition refused: 150.0 m from home, beyond NAV_RADIUS_MAX 100 m"
    );
    assert!(e.to_string().len() > 60);
}

#[test]
fn auto_flies_each_item_then_qrtl_lands_home() {
    let m = Mission::new(vec![
        item(MavCmd::MAV_CMD_NAV_WAYPOINT as u16, 0.0, 0.0, 0.0), // home slot
        item(MavCmd::MAV_CMD_NAV_VTOL_TAKEOFF as u16, 0.0, 3.0, 0.0),
        item(MavCmd::MAV_CMD_NAV_WAYPOINT as u16, 4.0, 3.0, 0.0),
        item(MavCmd::MAV_CMD_NAV_LOITER_TIME as u16, 8.0, 2.0, 2.0),
        item(MavCmd::MAV_CMD_NAV_WAYPOINT as u16, 6.0, 2.5, 0.0),
    ]);
    let mut w = World::new(m);
    w.mode = FlightMode::Auto;
    w.fly(0.5);
    assert!(w.reached().is_empty(), "nothing happens disarmed");
    w.armed = true;
    w.fly(4.0);
    assert_eq!(w.reached(), vec![1, 2], "take-off, then the first waypoint");
    w.fly(1.0);
    assert_eq!(w.reached(), vec![1, 2], "holding 2 s at the loiter point");
    w.fly(1.5);
    assert_eq!(w.reached(), vec![1, 2, 3, 4]);
    assert_eq!(w.mode, FlightMode::Rtl, "mission complete in the air");
    assert!(w.events.contains(&NavEvent::Info(
        "Mission complete, changing mode to RTL".into()
    )));
    // The endpoint flies RTL as QRTL where it must (Q_RTL_MODE 3, the paper model).
    w.mode = FlightMode::QRtl;
    w.fly(10.0);
    assert!(!w.armed, "landed and disarmed");
    assert!(w.pos.xy().norm() < 1e-9, "at home: {}", w.pos);
    assert_eq!(
        w.nav.mission_state(w.mission.count()),
        MissionState::Complete
    );
}

#[test]
fn landing_items_and_current_item() {
    let m = Mission::new(vec![
        item(MavCmd::MAV_CMD_NAV_WAYPOINT as u16, 0.0, 0.0, 0.0),
        item(MavCmd::MAV_CMD_NAV_VTOL_TAKEOFF as u16, 0.0, 2.0, 0.0),
        item(MavCmd::MAV_CMD_NAV_WAYPOINT as u16, 3.0, 2.0, 0.0),
        item(MavCmd::MAV_CMD_NAV_VTOL_LAND as u16, 5.0, 0.0, 0.0),
    ]);
    let mut w = World::new(m);
    assert!(w.call(|n, i, e| n.set_current(9, i, e)).is_err());
    w.call(|n, i, e| n.set_current(2, i, e)).unwrap();
    assert_eq!(w.events, vec![NavEvent::Current(2)]);
    w.mode = FlightMode::Auto;
    w.armed = true;
    w.fly(20.0);
    assert_eq!(
        w.reached(),
        vec![2, 3],
        "started at item 2, landed at item 3"
    );
    assert!(!w.armed);
    assert!(
        (w.pos.x - 5.0).abs() < 0.02,
        "landed at the item's point: {}",
        w.pos
    );
    assert_eq!(w.mode, FlightMode::Auto, "a landed mission stays in AUTO");
}

#[test]
fn guided_entered_in_flight_holds_and_empty_auto_returns() {
    let mut w = World::new(Mission::default());
    w.armed = true;
    w.pos = Vector3::new(1.0, 2.0, -3.0);
    w.mode = FlightMode::Guided;
    let g = w.fly(0.04);
    assert_eq!(
        g.last(),
        Some(&Guidance::Position(ned_to_paper(&Vector3::new(
            1.0, 2.0, -3.0
        ))))
    );
    w.mode = FlightMode::Auto;
    w.fly(0.04);
    assert_eq!(w.mode, FlightMode::Rtl, "nothing to fly: home");
}

fn transitions(w: &World) -> Vec<bool> {
    w.events
        .iter()
        .filter_map(|e| match e {
            NavEvent::Transition(f) => Some(*f),
            _ => None,
        })
        .collect()
}

/// ArduPlane's AUTO flies the position items after a VTOL take-off on the wing: the navigator
/// asks for the forward transition when the first waypoint starts, not before.
#[test]
fn auto_goes_to_the_wing_for_the_waypoints_after_a_vtol_take_off() {
    let m = Mission::new(vec![
        item(MavCmd::MAV_CMD_NAV_WAYPOINT as u16, 0.0, 0.0, 0.0),
        item(MavCmd::MAV_CMD_NAV_VTOL_TAKEOFF as u16, 0.0, 3.0, 0.0),
        item(MavCmd::MAV_CMD_NAV_WAYPOINT as u16, 4.0, 3.0, 0.0),
    ]);
    let mut w = World::new(m);
    w.mode = FlightMode::Auto;
    w.armed = true;
    w.fly(2.9);
    assert!(transitions(&w).is_empty(), "the take-off climbs in a hover");
    assert!(w.reached().is_empty());
    w.fly(0.2);
    assert_eq!(w.reached()[0], 1);
    // Item 2 starts: to the wing (then the end of the mission, RTL, asks again).
    assert_eq!(transitions(&w).first(), Some(&true));
}

/// With `Q_ENABLE` 2 (VTOL AUTO) AUTO starts in VTOL mode: no transition for the waypoints.
#[test]
fn with_vtol_auto_the_waypoints_stay_in_a_hover() {
    let m = Mission::new(vec![
        item(MavCmd::MAV_CMD_NAV_WAYPOINT as u16, 0.0, 0.0, 0.0),
        item(MavCmd::MAV_CMD_NAV_VTOL_TAKEOFF as u16, 0.0, 3.0, 0.0),
        item(MavCmd::MAV_CMD_NAV_WAYPOINT as u16, 4.0, 3.0, 0.0),
    ]);
    let mut w = World::new(m);
    w.vtol_auto = true;
    w.mode = FlightMode::Auto;
    w.armed = true;
    w.fly(4.0);
    assert_eq!(w.reached()[..2], [1, 2]);
    // Only the end of the mission (RTL) asks for the wing.
    let end = w
        .events
        .iter()
        .position(|e| matches!(e, NavEvent::Info(t) if t.starts_with("Mission complete")))
        .expect("mission complete");
    assert!(
        !w.events[..end].contains(&NavEvent::Transition(true)),
        "{:?}",
        w.events
    );
}

/// A DO_VTOL_TRANSITION to MC puts AUTO in VTOL mode: the waypoints after it are flown in a
/// hover, with no transition asked for; entering AUTO again clears it.
#[test]
fn a_transition_to_mc_item_keeps_the_waypoints_in_a_hover() {
    let mut to_mc = item(MavCmd::MAV_CMD_DO_VTOL_TRANSITION as u16, 0.0, 0.0, 3.0);
    to_mc.frame = MavFrame::MAV_FRAME_MISSION as u8;
    let m = Mission::new(vec![
        item(MavCmd::MAV_CMD_NAV_WAYPOINT as u16, 0.0, 0.0, 0.0),
        item(MavCmd::MAV_CMD_NAV_VTOL_TAKEOFF as u16, 0.0, 3.0, 0.0),
        to_mc,
        item(MavCmd::MAV_CMD_NAV_WAYPOINT as u16, 4.0, 3.0, 10.0),
        item(MavCmd::MAV_CMD_NAV_WAYPOINT as u16, 8.0, 3.0, 0.0),
    ]);
    let mut w = World::new(m);
    w.mode = FlightMode::Auto;
    w.armed = true;
    w.fly(5.0);
    assert_eq!(w.reached(), vec![1, 2], "holding 10 s at item 3");
    assert_eq!(
        transitions(&w),
        vec![false],
        "only the item's own (already MC)"
    );
    w.mode = FlightMode::Guided;
    w.fly(0.1);
    w.mode = FlightMode::Auto;
    w.fly(0.1);
    assert_eq!(
        transitions(&w),
        vec![false, true],
        "AUTO entered again: item 3 on the wing"
    );
}

/// A VTOL landing point farther than 1.5 stopping distances at the cruise airspeed (18 m at
/// 12 m/s and 6 m/s²) is approached on the wing, a nearer one in a hover.
#[test]
fn a_far_vtol_landing_is_approached_on_the_wing() {
    for (north, wing) in [(20.0, true), (16.0, false)] {
        let mut to_mc = item(MavCmd::MAV_CMD_DO_VTOL_TRANSITION as u16, 0.0, 0.0, 3.0);
        to_mc.frame = MavFrame::MAV_FRAME_MISSION as u8;
        let m = Mission::new(vec![
            item(MavCmd::MAV_CMD_NAV_WAYPOINT as u16, 0.0, 0.0, 0.0),
            item(MavCmd::MAV_CMD_NAV_VTOL_TAKEOFF as u16, 0.0, 3.0, 0.0),
            to_mc,
            item(MavCmd::MAV_CMD_NAV_VTOL_LAND as u16, north, 0.0, 0.0),
        ]);
        let mut w = World::new(m);
        w.mode = FlightMode::Auto;
        w.armed = true;
        w.fly(3.5);
        let text = if wing {
            format!("VTOL approach d={north:.1}")
        } else {
            format!("VTOL Position1 d={north:.1}")
        };
        assert!(w.events.contains(&NavEvent::Info(text)), "{:?}", w.events);
        assert_eq!(transitions(&w).contains(&true), wing, "{north} m");
    }
}

/// RTL is a fixed-wing mode: entered in a hover it asks for the forward transition; QRTL
/// does not.
#[test]
fn rtl_in_a_hover_goes_to_the_wing_and_qrtl_does_not() {
    for (mode, wing) in [(FlightMode::Rtl, true), (FlightMode::QRtl, false)] {
        let mut w = World::new(Mission::default());
        w.armed = true;
        w.pos = Vector3::new(30.0, 0.0, -10.0);
        w.mode = mode;
        w.fly(0.1);
        assert_eq!(transitions(&w), if wing { vec![true] } else { vec![] });
    }
}
