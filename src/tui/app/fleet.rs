//! The Fleet view's state and keys: every vehicle in one table, the lost ones first, searched
//! with `/`, scrolled with the arrows and PgUp/PgDn, Enter to show and command one.

use std::time::Instant;

use ratatui::crossterm::event::{KeyCode, KeyEvent};
use vtol_link::{ComponentId, SystemId};

use super::{App, Level, Request};
use crate::tracker::{VehicleState, VehicleView};

/// A vehicle's key.
pub type VehicleKey = (SystemId, ComponentId);

/// The Fleet view's state.
#[derive(Debug, Clone, Default)]
pub struct FleetState {
    /// Search typed after `/`: a number matches system ids that start with it, words match the
    /// state, mode and status (case-insensitive).
    pub filter: String,
    /// The vehicle under the cursor (it keeps its row as the order changes).
    pub cursor: Option<VehicleKey>,
    /// The vehicles as last listed, in order (so a key press knows its neighbours).
    pub listed: Vec<VehicleKey>,
    /// The first row on screen.
    pub first: usize,
}

/// How urgent a vehicle is: the list puts the smallest first.
#[must_use]
pub fn rank(v: &VehicleView, now: Instant) -> u8 {
    use vtol_link::dialect::MavState as S;
    if v.is_lost(now) {
        0
    } else if matches!(
        v.system_status,
        S::MAV_STATE_CRITICAL | S::MAV_STATE_EMERGENCY | S::MAV_STATE_FLIGHT_TERMINATION
    ) {
        1
    } else if v.armed {
        2
    } else {
        3
    }
}

/// The state word a row shows and the search matches.
#[must_use]
pub fn state_word(v: &VehicleView, now: Instant) -> &'static str {
    crate::words::vehicle_state(v.is_lost(now), v.armed)
}

/// Whether `v` matches the search `filter`.
#[must_use]
pub fn matches(v: &VehicleView, now: Instant, filter: &str) -> bool {
    let f = filter.trim();
    if f.is_empty() {
        return true;
    }
    if f.chars().all(|c| c.is_ascii_digit()) {
        return v.system_id.0.to_string().starts_with(f);
    }
    let f = f.to_ascii_uppercase();
    let words = format!(
        "{} {} {}",
        state_word(v, now),
        v.mode_name(),
        crate::words::mav_state(v.system_status)
    )
    .to_ascii_uppercase();
    f.split_whitespace().all(|w| words.contains(w))
}

/// The vehicles that match the search, the lost ones first, then in trouble, armed, the
/// rest; system id order within each.
#[must_use]
pub fn listing(state: &VehicleState, now: Instant, filter: &str) -> Vec<VehicleKey> {
    let mut rows: Vec<(u8, VehicleKey)> = state
        .vehicles
        .iter()
        .filter(|(_, v)| matches(v, now, filter))
        .map(|(k, v)| (rank(v, now), *k))
        .collect();
    rows.sort_unstable();
    rows.into_iter().map(|(_, k)| k).collect()
}

/// Rows one PgUp/PgDn moves.
const PAGE: usize = 20;

impl App {
    /// Keys of the Fleet view; `None` for a key it does not take.
    pub(super) fn on_fleet_key(&mut self, key: KeyEvent) -> Option<Vec<Request>> {
        let list = &self.fleet.listed;
        let at = self
            .fleet
            .cursor
            .and_then(|c| list.iter().position(|k| *k == c))
            .unwrap_or(0);
        let last = list.len().saturating_sub(1);
        let go = |i: usize| list.get(i.min(last)).copied();
        match key.code {
            KeyCode::Up => self.fleet.cursor = go(at.saturating_sub(1)),
            KeyCode::Down => self.fleet.cursor = go(at + 1),
            KeyCode::PageUp => self.fleet.cursor = go(at.saturating_sub(PAGE)),
            KeyCode::PageDown => self.fleet.cursor = go(at + PAGE),
            KeyCode::Home => self.fleet.cursor = go(0),
            KeyCode::End => self.fleet.cursor = go(last),
            KeyCode::Char('/') => {
                self.fleet.filter.clear();
                self.typing = true;
            }
            KeyCode::Esc => self.fleet.filter.clear(),
            KeyCode::Enter => {
                let Some(k) = go(at) else {
                    return Some(Vec::new());
                };
                if self.selected == Some(k) {
                    return Some(Vec::new());
                }
                self.selected = Some(k);
                self.note(
                    Level::Info,
                    format!("vehicle {} (component {}) selected", k.0, k.1),
                );
                return Some(self.vehicle_changed());
            }
            _ => return None,
        }
        Some(Vec::new())
    }
}
