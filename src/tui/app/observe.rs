//! What the app learns from the tracker between frames: the shown vehicle's mode and
//! parameter values, the rows of the list views and the map's centre. The event loop calls
//! [`App::observe`] before each frame; the view draws what it left.

use std::time::Instant;

use vtol_link::protocol::id::PARAM_VALUE;

use super::{App, ParamStatus, View};
use crate::fields;
use crate::tracker::{VehicleState, VehicleView};
use crate::tui::map::{MapScene, scene_parts};

/// Horizontal speed under which a vehicle entering QLOITER holds where it was, m/s.
const SETTLED_M_S: f32 = 1.0;

/// Whether `v` hovers slowly: EXTENDED_SYS_STATE says hover (or is not sent) and it moves
/// less than [`SETTLED_M_S`] across the ground.
fn settled_hover(
    state: &VehicleState,
    v: &VehicleView,
    p: &crate::tracker::state::LocalPosition,
) -> bool {
    let air = crate::tui::air::air(state, v, None, false);
    let hovering = matches!(air.vtol, None | Some(crate::tui::air::Vtol::Mc));
    hovering && p.vel_ned_m_s[0].hypot(p.vel_ned_m_s[1]) < SETTLED_M_S
}

impl App {
    /// Brings the app up to date with `state` before a frame shows it (the event loop calls
    /// it; the view only reads): follows the shown vehicle ([`App::follow_vehicle`]) and the
    /// vehicle's word on parameters, lists the rows of the Fleet or Messages view on screen and
    /// keeps their cursors on them, and keeps the Map view's centre (where a pan starts).
    pub fn observe(&mut self, state: &VehicleState, now: Instant) {
        self.follow_vehicle(state);
        self.follow_param_values(state);
        match self.view {
            View::Fleet => self.list_fleet(state, now),
            View::Messages => self.list_messages(state),
            View::Map => self.center_map(state),
            _ => {}
        }
    }

    /// Follows the shown vehicle between frames: entering QLOITER, it holds where it was
    /// entered (at `HOVER_ALT` when on the ground), so that is the target shown and the one the
    /// arrows move; another mode drops the target.
    fn follow_vehicle(&mut self, state: &VehicleState) {
        let Some(v) = self.vehicle(state) else {
            return;
        };
        let mode = v.mode_name();
        let entered = self.last_mode.as_deref() != Some(mode.as_str());
        if entered {
            self.target_ned = match (mode.as_str(), v.position) {
                // Entered from a hover the vehicle holds where it was. Entered at speed (from
                // forward flight, through a back transition) it holds where it stops, which
                // the UI does not know: no setpoint rather than a wrong one.
                ("QLOITER", Some(p)) if settled_hover(state, v, &p) => {
                    let airborne = crate::vitals::vitals(state, v).airborne;
                    let hover = self.params.value("HOVER_ALT").unwrap_or(1.0);
                    let [n, e, d] = p.pos_ned_m;
                    Some([n, e, if airborne { d } else { -hover }])
                }
                ("QLOITER", None) => self.target_ned,
                _ => None,
            };
        }
        self.last_mode = Some(mode);
    }

    /// The vehicle's last word on a parameter wins: a PARAM_VALUE heard since the last frame
    /// (an echo, a reset such as `SIM_PUSH_*` going back to 0, another client's write) sets the
    /// table's value; a status it contradicts goes (a confirmation of another value, a local
    /// error, a refusal once the value moved), a pending write it matches is left to its
    /// outcome.
    fn follow_param_values(&mut self, state: &VehicleState) {
        let Some(v) = self.vehicle(state) else {
            return;
        };
        let Some(s) = state
            .messages
            .get(&(v.system_id, v.component_id, PARAM_VALUE))
        else {
            return;
        };
        if self.params.seen_values == Some(s.count) {
            return;
        }
        self.params.seen_values = Some(s.count);
        let Ok(vtol_link::dialect::MavMessage::PARAM_VALUE(pv)) = s.last.decode() else {
            return;
        };
        let name = pv.param_id.to_str().unwrap_or("").to_owned();
        let value = pv.param_value;
        let Some(row) = self.params.table.iter_mut().find(|(n, _)| *n == name) else {
            return;
        };
        let moved = row.1.to_bits() != value.to_bits();
        row.1 = value;
        let drop = match self.params.status.get(&name) {
            Some(ParamStatus::Pending(_)) | None => false,
            Some(ParamStatus::NotSent(_)) => true,
            Some(ParamStatus::Confirmed | ParamStatus::Refused(_)) => moved,
        };
        if drop {
            self.params.status.remove(&name);
        }
    }

    /// The Fleet view's rows in order, the cursor on its vehicle (the first row when that one
    /// is gone from the list).
    fn list_fleet(&mut self, state: &VehicleState, now: Instant) {
        let listed = super::fleet::listing(state, now, &self.fleet.filter);
        let at = self
            .fleet
            .cursor
            .and_then(|c| listed.iter().position(|k| *k == c))
            .unwrap_or(0);
        self.fleet.cursor = listed.get(at).copied();
        self.fleet.listed = listed;
    }

    /// The Messages view's rows (those the filter names), the selection kept on the list, and
    /// the selected message's numeric fields with the field cursor kept on them.
    fn list_messages(&mut self, state: &VehicleState) {
        let m = &mut self.messages;
        let filter = m.filter.to_ascii_uppercase();
        m.listed = state
            .messages
            .iter()
            .filter(|(_, s)| {
                filter.is_empty() || s.last.message_name().unwrap_or("").contains(&filter)
            })
            .map(|(k, _)| *k)
            .collect();
        m.selected = m.selected.min(m.listed.len().saturating_sub(1));
        let decoded = m
            .listed
            .get(m.selected)
            .and_then(|k| state.messages.get(k))
            .and_then(|s| s.last.decode_lenient().ok());
        m.listed_fields = Vec::new();
        // A message that does not decode shows no fields and keeps its field cursor.
        if let Some(l) = decoded {
            m.listed_fields = fields::fields(&l.msg)
                .into_iter()
                .filter(|f| f.value.is_some())
                .map(|f| f.path)
                .collect();
            m.field = m.field.min(m.listed_fields.len().saturating_sub(1));
        }
    }

    /// The Map view's centre for the shown vehicle: where the frame is drawn and a pan starts.
    fn center_map(&mut self, state: &VehicleState) {
        let (vehicle, home, target, current_seq) = self
            .vehicle(state)
            .map(|v| scene_parts(state, v))
            .unwrap_or_default();
        let scene = MapScene {
            home,
            vehicle,
            target,
            items: &self.map.items,
            current_seq,
            track: &[],
        };
        self.map.camera.shown = self.map.camera.center_for(&scene);
    }
}
