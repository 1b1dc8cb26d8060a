//! The mode picker (`m`): every mode the shown vehicle has — the hover (Q) modes, the
//! fixed-wing ones, AUTO and RTL — listed by name and number. ↑↓ (PgUp/PgDn, Home/End) move,
//! letters filter, Enter switches through the same guard as the mode keys (a mode that leaves
//! altitude to a throttle nobody holds asks first in the air), Esc closes with nothing sent.
//!
//! Commands of every kind (arm, disarm, modes, the twin's push keys, parameter writes) are not
//! offered when the vehicle is a replayed log: the key says so and nothing is sent.

use ratatui::crossterm::event::{KeyCode, KeyEvent};

use super::{App, Level, Request};
use crate::tracker::{VehicleState, VehicleView};

/// The picker's state while it is open.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct Picker {
    /// Typed letters: modes whose name contains them (case-insensitive).
    pub filter: String,
    /// Selected row among the filtered modes.
    pub selected: usize,
}

/// Modes a vehicle reports but does not take from a ground station (ArduPlane's start-up
/// state and its ADS-B avoidance).
const NOT_OFFERED: [&str; 2] = ["INITIALISING", "AVOID_ADSB"];

/// The modes `v` has, in its own numbering ([`crate::modes::modes_for`]: ArduPlane's with the
/// Q modes for an ArduPilot plane or VTOL); none before a vehicle is heard.
#[must_use]
pub fn vehicle_modes(v: Option<&VehicleView>) -> Vec<(&'static str, u32)> {
    let Some(v) = v else {
        return Vec::new();
    };
    crate::modes::modes_for(v.autopilot, v.mav_type)
        .iter()
        .filter(|(n, _)| !NOT_OFFERED.contains(n))
        .copied()
        .collect()
}

impl Picker {
    /// The modes of `v` that match the filter: the one named exactly first, then those that
    /// start with it, then the rest, each in the vehicle's order.
    #[must_use]
    pub fn listed(&self, v: Option<&VehicleView>) -> Vec<(&'static str, u32)> {
        let f = self.filter.to_ascii_uppercase();
        let mut out: Vec<_> = vehicle_modes(v)
            .into_iter()
            .filter(|(n, _)| n.contains(&f))
            .collect();
        if !f.is_empty() {
            out.sort_by_key(|(n, _)| (*n != f, !n.starts_with(&f)));
        }
        out
    }
}

impl App {
    /// Opens the picker on the vehicle's current mode.
    pub(super) fn open_picker(&mut self, state: &VehicleState) {
        let v = self.vehicle(state);
        let mut p = Picker::default();
        if let Some(v) = v {
            let current = v.custom_mode;
            if let Some(i) = p.listed(Some(v)).iter().position(|(_, n)| *n == current) {
                p.selected = i;
            }
        }
        self.picker = Some(p);
    }

    /// A key while the picker is open.
    pub(super) fn on_picker_key(
        &mut self,
        mut p: Picker,
        key: KeyEvent,
        state: &VehicleState,
    ) -> Vec<Request> {
        let listed = p.listed(self.vehicle(state));
        let last = listed.len().saturating_sub(1);
        match key.code {
            KeyCode::Esc => {
                self.note(Level::Info, "mode picker closed: nothing sent");
                return Vec::new();
            }
            KeyCode::Enter => {
                let Some(&(name, _)) = listed.get(p.selected) else {
                    self.picker = Some(p);
                    return Vec::new();
                };
                return self.guarded_mode(name, state);
            }
            KeyCode::Up => p.selected = p.selected.saturating_sub(1),
            KeyCode::Down => p.selected = (p.selected + 1).min(last),
            KeyCode::PageUp => p.selected = p.selected.saturating_sub(8),
            KeyCode::PageDown => p.selected = (p.selected + 8).min(last),
            KeyCode::Home => p.selected = 0,
            KeyCode::End => p.selected = last,
            KeyCode::Backspace => {
                p.filter.pop();
                p.selected = 0;
            }
            KeyCode::Char(c) if c.is_ascii_alphanumeric() => {
                p.filter.push(c.to_ascii_uppercase());
                p.selected = 0;
            }
            _ => {}
        }
        let n = p.listed(self.vehicle(state)).len();
        p.selected = p.selected.min(n.saturating_sub(1));
        self.picker = Some(p);
        Vec::new()
    }

    /// Whether `key` would command the vehicle (and is refused on a replay).
    pub(super) fn is_command_key(key: KeyEvent) -> bool {
        matches!(
            key.code,
            KeyCode::Char(
                'a' | 'A'
                    | 'd'
                    | 'D'
                    | 'R'
                    | 't'
                    | 'l'
                    | 'p'
                    | 's'
                    | 'm'
                    | 'x'
                    | 'X'
                    | 'c'
                    | 'C'
                    | 'z'
                    | 'Z'
            ) | KeyCode::Up
                | KeyCode::Down
                | KeyCode::Left
                | KeyCode::Right
                | KeyCode::PageUp
                | KeyCode::PageDown
        )
    }

    /// What a command key on a replay says.
    pub(super) fn refuse_on_replay(&mut self) {
        self.note(
            Level::Info,
            "replay: the vehicle is a recorded log; commands are not offered",
        );
    }
}
