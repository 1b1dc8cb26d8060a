//! Missions, fences and rally points as the ground station holds them: a list of items as the
//! MAVLink mission protocol carries them (MISSION_ITEM_INT), where each came from in its file,
//! and the checks made before anything is sent.
//!
//! - [`file`](mod@file): QGroundControl's `QGC WPL 110` text and `.plan` JSON, read and written.
//! - [`check`]: what is refused before an upload (unknown command or frame, a NaN position,
//!   latitude or longitude out of range, a VTOL landing approach ArduPlane refuses).
//! - [`verify`]: a file read and checked for an upload, and the list held afterwards compared.

pub mod check;
pub mod file;
pub mod verify;

use std::fmt;

/// Which list of the vehicle: MAV_MISSION_TYPE.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Kind {
    /// The mission (item 0 is home on ArduPilot).
    #[default]
    Mission,
    /// The geofence.
    Fence,
    /// Rally points.
    Rally,
}

impl Kind {
    /// The MAV_MISSION_TYPE number.
    #[must_use]
    pub fn number(self) -> u8 {
        match self {
            Kind::Mission => 0,
            Kind::Fence => 1,
            Kind::Rally => 2,
        }
    }

    /// Its name on the command line and in messages.
    #[must_use]
    pub fn name(self) -> &'static str {
        match self {
            Kind::Mission => "mission",
            Kind::Fence => "fence",
            Kind::Rally => "rally",
        }
    }
}

impl std::str::FromStr for Kind {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        match s.to_ascii_lowercase().as_str() {
            "mission" => Ok(Kind::Mission),
            "fence" => Ok(Kind::Fence),
            "rally" => Ok(Kind::Rally),
            _ => Err(format!("'{s}' is not mission, fence or rally")),
        }
    }
}

/// One item, as MISSION_ITEM_INT carries it, with x and y in their file units: degrees for a
/// global frame, metres for a local one, the plain number otherwise.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Item {
    /// MAV_FRAME.
    pub frame: u8,
    /// MAV_CMD.
    pub command: u16,
    /// The `current` flag.
    pub current: bool,
    /// Continue to the next item when this one is done.
    pub autocontinue: bool,
    /// param1..param4 (NaN means "unchanged" or "default" for some commands).
    pub params: [f32; 4],
    /// Latitude (degrees), local x (m) or param5.
    pub x: f64,
    /// Longitude (degrees), local y (m) or param6.
    pub y: f64,
    /// Altitude (m) or param7.
    pub z: f32,
}

/// Where an item came from, for the messages that name it.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Origin {
    /// A line of a text file (1-based).
    Line(usize),
    /// An entry of a list in a `.plan` (0-based index in `mission.items`, or home).
    PlanItem(usize),
    /// The `.plan`'s plannedHomePosition.
    PlanHome,
    /// A fence or rally entry of a `.plan`, described.
    PlanEntry(&'static str, usize),
    /// Downloaded from the vehicle.
    Vehicle,
}

impl fmt::Display for Origin {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Origin::Line(n) => write!(f, "line {n}"),
            Origin::PlanItem(i) => write!(f, "mission.items[{i}]"),
            Origin::PlanHome => write!(f, "mission.plannedHomePosition"),
            Origin::PlanEntry(what, i) => write!(f, "{what}[{i}]"),
            Origin::Vehicle => write!(f, "the vehicle"),
        }
    }
}

/// An item and where it came from.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Located {
    /// The item.
    pub item: Item,
    /// Its place in the file.
    pub origin: Origin,
}

/// The MAV_FRAMEs whose x and y are latitude and longitude.
#[must_use]
pub fn is_global(frame: u8) -> bool {
    matches!(frame, 0 | 3 | 5 | 6 | 10 | 11)
}

/// The MAV_FRAMEs whose x and y are metres.
#[must_use]
pub fn is_local(frame: u8) -> bool {
    matches!(frame, 1 | 7 | 8 | 9 | 12..=21)
}

impl Item {
    /// x and y as MISSION_ITEM_INT carries them: degrees × 1e7 for a global frame, metres ×
    /// 1e4 for a local one, the number rounded otherwise.
    #[must_use]
    pub fn wire_xy(&self) -> (i32, i32) {
        let scale = self.scale();
        #[allow(clippy::cast_possible_truncation)]
        let to = |v: f64| {
            (v * scale)
                .round()
                .clamp(f64::from(i32::MIN), f64::from(i32::MAX)) as i32
        };
        (to(self.x), to(self.y))
    }

    /// x and y from MISSION_ITEM_INT's integers.
    pub fn set_wire_xy(&mut self, x: i32, y: i32) {
        let scale = self.scale();
        self.x = f64::from(x) / scale;
        self.y = f64::from(y) / scale;
    }

    fn scale(&self) -> f64 {
        if is_global(self.frame) {
            1e7
        } else if is_local(self.frame) {
            1e4
        } else {
            1.0
        }
    }

    /// Whether x and y are a position (a global frame, not 0, 0 which means "here").
    #[must_use]
    pub fn has_position(&self) -> bool {
        is_global(self.frame) && (self.x != 0.0 || self.y != 0.0)
    }

    /// The same item as the vehicle would hold it: within float32 and 1e-7 degree.
    #[must_use]
    pub fn same_as(&self, other: &Item) -> bool {
        let same_f = |a: f32, b: f32| {
            (a.is_nan() && b.is_nan()) || a == b || (a - b).abs() <= 1e-6 * a.abs().max(b.abs())
        };
        self.frame == other.frame
            && self.command == other.command
            && self.autocontinue == other.autocontinue
            && self
                .params
                .iter()
                .zip(&other.params)
                .all(|(a, b)| same_f(*a, *b))
            && self.wire_xy() == other.wire_xy()
            && same_f(self.z, other.z)
    }
}

impl Item {
    /// Whether `back`, downloaded after this item was uploaded, is what the vehicle keeps of
    /// it: [`Item::same_as`], except that a NaN parameter may come back as anything (ArduPilot
    /// stores none) and a command without a position (MAV_CMD_CONDITION_*, MAV_CMD_DO_*) may
    /// come back in another frame (ArduPilot reports MAV_FRAME_GLOBAL for them).
    #[must_use]
    pub fn held_as(&self, back: &Item) -> bool {
        let mut sent = *self;
        for (p, b) in sent.params.iter_mut().zip(back.params) {
            if p.is_nan() {
                *p = b;
            }
        }
        if (100..5000).contains(&sent.command) {
            sent.frame = back.frame;
        }
        sent.same_as(back)
    }
}

/// The command's MAVLink name without its `MAV_CMD_` prefix, or its number.
#[must_use]
pub fn command_name(command: u16) -> String {
    use num_traits::FromPrimitive;
    match vtol_link::dialect::MavCmd::from_u16(command) {
        Some(c) => format!("{c:?}").trim_start_matches("MAV_CMD_").to_owned(),
        None => command.to_string(),
    }
}

/// The frame's MAVLink name without its `MAV_FRAME_` prefix, or its number.
#[must_use]
pub fn frame_name(frame: u8) -> String {
    use num_traits::FromPrimitive;
    match vtol_link::dialect::MavFrame::from_u8(frame) {
        Some(f) => format!("{f:?}").trim_start_matches("MAV_FRAME_").to_owned(),
        None => frame.to_string(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn what_ardupilot_keeps_of_an_item_is_held_as_sent() {
        let sent = Item {
            frame: 2,
            command: 177,
            current: false,
            autocontinue: true,
            params: [3.0, 2.0, 0.0, f32::NAN],
            x: 0.0,
            y: 0.0,
            z: 0.0,
        };
        let back = Item {
            frame: 0,
            params: [3.0, 2.0, 0.0, 0.0],
            ..sent
        };
        assert!(sent.held_as(&back) && !sent.same_as(&back));
        let takeoff = Item {
            frame: 3,
            command: 84,
            ..sent
        };
        let moved = Item { frame: 0, ..back };
        assert!(
            !takeoff.held_as(&Item {
                command: 84,
                ..moved
            }),
            "a NAV item keeps its frame"
        );
        assert!(!sent.held_as(&Item {
            params: [4.0, 2.0, 0.0, 0.0],
            ..back
        }));
    }
}
