//! A mission's progress as the Flight view shows it, in one line: the current item of
//! MISSION_CURRENT out of the mission's last, what it is, the distance and the time to it, and
//! the items left after it (`Mission 3/5 WAYPOINT 182 m 15 s, 2 left`). Pure, like
//! [`super::air`]: read from the last message of each kind the tracker kept.
//!
//! - The count: MISSION_CURRENT's `total` (a MAVLink 2 extension: the last item's number, home
//!   left out; `UINT16_MAX` when the vehicle has no mission), else the downloaded mission's.
//! - The distance: NAV_CONTROLLER_OUTPUT's `wp_dist` while it is fresh and the vehicle flies
//!   the mission (AUTO: elsewhere it is the distance to another point), else from the item's
//!   place and GLOBAL_POSITION_INT.
//! - The time: the distance over the ground speed (VFR_HUD's, else GLOBAL_POSITION_INT's
//!   velocity), `-` below [`MIN_SPEED_M_S`].

use std::time::{Duration, Instant};

use vtol_link::dialect::MavMessage;
use vtol_link::protocol::id::{
    GLOBAL_POSITION_INT, MISSION_CURRENT, NAV_CONTROLLER_OUTPUT, VFR_HUD,
};

use crate::mission::Item;
use crate::tracker::state::{VehicleState, VehicleView};

/// A message older than this is no longer streamed: its figures are not used.
pub const FRESH: Duration = Duration::from_secs(3);
/// Below this ground speed no time to the item is given, m/s.
pub const MIN_SPEED_M_S: f32 = 0.5;

/// Where the vehicle stands in its mission.
#[derive(Debug, Clone, PartialEq)]
pub struct Progress {
    /// The current item's number (MISSION_CURRENT's `seq`).
    pub seq: u16,
    /// The last item's number (the count without home), when known.
    pub total: Option<u16>,
    /// The current item's command without `MAV_CMD_NAV_` (`WAYPOINT`), when the mission is known.
    pub name: Option<String>,
    /// Horizontal distance to the item, m.
    pub distance_m: Option<f64>,
    /// Ground speed, m/s.
    pub speed_m_s: Option<f32>,
}

/// What the Flight view says of the mission.
#[derive(Debug, Clone, PartialEq)]
pub enum MissionLine {
    /// The vehicle streams its current item and a mission is known.
    Progress(Progress),
    /// In AUTO, without a mission to show: why.
    Missing(&'static str),
}

fn last(state: &VehicleState, v: &VehicleView, id: u32, now: Instant) -> Option<MavMessage> {
    let s = state.messages.get(&(v.system_id, v.component_id, id))?;
    if now.saturating_duration_since(s.last_at) > FRESH {
        return None;
    }
    s.last.decode_lenient().ok().map(|l| l.msg)
}

/// A place in 1e-7 degree from an item with a position.
fn place(item: &Item) -> Option<(i32, i32)> {
    item.has_position()
        .then(|| ((item.x * 1e7).round() as i32, (item.y * 1e7).round() as i32))
}

/// The mission line of `v` at `now`; `mission` is the downloaded mission (item 0 home), if any.
/// `None` when there is nothing to say: no fresh MISSION_CURRENT with a known mission, and not
/// in AUTO.
#[must_use]
pub fn mission_line(
    state: &VehicleState,
    v: &VehicleView,
    mission: Option<&[Item]>,
    now: Instant,
) -> Option<MissionLine> {
    let auto = v.mode_name() == "AUTO";
    let Some(MavMessage::MISSION_CURRENT(mc)) = last(state, v, MISSION_CURRENT, now) else {
        return auto.then_some(MissionLine::Missing("no MISSION_CURRENT"));
    };
    let downloaded = mission
        .filter(|m| m.len() > 1)
        .and_then(|m| u16::try_from(m.len() - 1).ok());
    let total = match mc.total {
        u16::MAX => None,
        0 => downloaded,
        t => Some(t),
    };
    let Some(total) = total else {
        return auto.then_some(MissionLine::Missing(if mc.total == u16::MAX {
            "none on the vehicle"
        } else {
            "not downloaded (Map view: r)"
        }));
    };
    // The downloaded items describe the vehicle's mission only while their count matches.
    let item = mission
        .filter(|m| m.len() == usize::from(total) + 1)
        .and_then(|m| m.get(usize::from(mc.seq)));
    let name = item.map(|i| {
        let n = crate::mission::command_name(i.command);
        n.strip_prefix("NAV_").map_or(n.clone(), str::to_owned)
    });
    let position = last(state, v, GLOBAL_POSITION_INT, now);
    let nav_dist = match last(state, v, NAV_CONTROLLER_OUTPUT, now) {
        Some(MavMessage::NAV_CONTROLLER_OUTPUT(n)) if auto => Some(f64::from(n.wp_dist)),
        _ => None,
    };
    let distance_m = nav_dist.or_else(|| {
        let Some(MavMessage::GLOBAL_POSITION_INT(g)) = &position else {
            return None;
        };
        let to = item.and_then(place)?;
        let (e, n) = crate::tui::map::east_north_m((g.lat, g.lon), to);
        Some(e.hypot(n))
    });
    let speed_m_s = match last(state, v, VFR_HUD, now) {
        Some(MavMessage::VFR_HUD(h)) if h.groundspeed.is_finite() => Some(h.groundspeed),
        _ => match position {
            Some(MavMessage::GLOBAL_POSITION_INT(g)) => {
                Some((f32::from(g.vx) / 100.0).hypot(f32::from(g.vy) / 100.0))
            }
            _ => None,
        },
    };
    Some(MissionLine::Progress(Progress {
        seq: mc.seq,
        total: Some(total),
        name,
        distance_m,
        speed_m_s,
    }))
}

fn distance_text(m: f64) -> String {
    if m >= 10_000.0 {
        format!("{:.1} km", m / 1000.0)
    } else {
        format!("{m:.0} m")
    }
}

fn time_text(s: f64) -> String {
    let s = s.round() as u64;
    if s < 100 {
        format!("{s} s")
    } else {
        format!("{}:{:02}", s / 60, s % 60)
    }
}

impl Progress {
    /// Seconds to the item at the ground speed; `None` below [`MIN_SPEED_M_S`].
    #[must_use]
    pub fn time_s(&self) -> Option<f64> {
        let speed = self.speed_m_s.filter(|s| *s >= MIN_SPEED_M_S)?;
        Some(self.distance_m? / f64::from(speed))
    }

    /// The items after the current one.
    #[must_use]
    pub fn left(&self) -> Option<u16> {
        self.total.map(|t| t.saturating_sub(self.seq))
    }
}

impl MissionLine {
    /// The line in at most `width` characters where it can: the command's name goes first
    /// when it does not fit.
    #[must_use]
    pub fn text(&self, width: usize) -> String {
        let p = match self {
            MissionLine::Missing(why) => return format!("Mission  - {why}"),
            MissionLine::Progress(p) => p,
        };
        let total = p.total.map_or("?".to_owned(), |t| t.to_string());
        let distance = p.distance_m.map_or("- m".to_owned(), distance_text);
        let time = p.time_s().map_or("-".to_owned(), time_text);
        let left = p.left().map_or(String::new(), |l| format!(", {l} left"));
        let with = |name: &str| format!("Mission {}/{total} {name}{distance} {time}{left}", p.seq);
        let full = with(&p.name.as_ref().map_or(String::new(), |n| format!("{n} ")));
        if full.chars().count() <= width {
            full
        } else {
            with("")
        }
    }
}
