//! The Map view's mission keys: `u` uploads a file (checked first, as `vtol-gcs mission upload`
//! checks it, then `y`), `w` downloads the vehicle's mission into a file, `g` starts the
//! mission (`y` first), `n` makes an item current (`y` first while the vehicle flies the
//! mission). Each path or number is typed on a one-line prompt; on a replay none is offered.

use ratatui::crossterm::event::{KeyCode, KeyEvent};
use vtol_link::dialect::MavMessage;
use vtol_link::protocol::id::MISSION_CURRENT;

use super::{App, Confirm, Level, Request};
use crate::mission::Item;
use crate::tracker::VehicleState;
use crate::tui::map::PAN_CELLS;
use crate::vitals::vitals;

/// The file a mission prompt offers first.
pub const DEFAULT_MISSION_FILE: &str = "mission.waypoints";

/// A mission prompt being typed in the Map view.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum MissionPrompt {
    /// The file to upload.
    Upload(String),
    /// The file to download into.
    Save(String),
    /// The item to make current.
    Current(String),
}

impl MissionPrompt {
    /// What the prompt asks for, and what Enter does.
    #[must_use]
    pub fn title(&self) -> &'static str {
        match self {
            MissionPrompt::Upload(_) => " Upload a mission file (Enter checks it, Esc cancels) ",
            MissionPrompt::Save(_) => " Download the mission into a file (Enter, Esc cancels) ",
            MissionPrompt::Current(_) => " Make an item current (its number, Enter, Esc cancels) ",
        }
    }

    /// The text typed so far.
    #[must_use]
    pub fn text(&self) -> &str {
        match self {
            MissionPrompt::Upload(s) | MissionPrompt::Save(s) | MissionPrompt::Current(s) => s,
        }
    }

    fn text_mut(&mut self) -> &mut String {
        match self {
            MissionPrompt::Upload(s) | MissionPrompt::Save(s) | MissionPrompt::Current(s) => s,
        }
    }
}

/// MISSION_CURRENT's seq and total of the shown vehicle, as last heard.
fn mission_current(app: &App, state: &VehicleState) -> Option<(u16, u16)> {
    let v = app.vehicle(state)?;
    let s = state
        .messages
        .get(&(v.system_id, v.component_id, MISSION_CURRENT))?;
    match s.last.decode_lenient().ok()?.msg {
        MavMessage::MISSION_CURRENT(m) => Some((m.seq, m.total)),
        _ => None,
    }
}

impl App {
    /// The Map view's keys: the mission keys here, the camera's in [`App::on_camera_key`].
    pub(super) fn on_map_key(
        &mut self,
        key: KeyEvent,
        state: &VehicleState,
    ) -> Option<Vec<Request>> {
        let KeyCode::Char(c @ ('u' | 'w' | 'g' | 'n')) = key.code else {
            return self.on_camera_key(key.code);
        };
        if self.replay {
            self.refuse_on_replay();
            return Some(Vec::new());
        }
        match c {
            'u' => self.mission_prompt = Some(MissionPrompt::Upload(self.mission_file.clone())),
            'w' => self.mission_prompt = Some(MissionPrompt::Save(self.mission_file.clone())),
            'n' => {
                // The next item, to step through the mission with `n` Enter.
                let next = match (mission_current(self, state), self.last_item(state)) {
                    (Some((seq, _)), Some(last)) if seq < last => seq + 1,
                    (Some((seq, _)), _) => seq.max(1),
                    (None, _) => 1,
                };
                self.mission_prompt = Some(MissionPrompt::Current(next.to_string()));
            }
            _ => {
                let v = self.vehicle(state);
                let (armed, airborne) =
                    v.map_or((false, false), |v| (v.armed, vitals(state, v).airborne));
                let from = mission_current(self, state).map(|(seq, _)| seq);
                self.confirm = Some(Confirm::MissionStart {
                    from,
                    armed,
                    airborne,
                });
                return Some(Vec::new());
            }
        }
        self.typing = true;
        Some(Vec::new())
    }

    /// The Map view's camera keys: `+`/`-` zoom, arrows pan, `f` or `0` follow the vehicle
    /// again, `r` downloads the mission again. `None` for a key it does not take.
    fn on_camera_key(&mut self, code: KeyCode) -> Option<Vec<Request>> {
        let c = &mut self.map.camera;
        match code {
            KeyCode::Char('+' | '=') => c.zoom_in(),
            KeyCode::Char('-') => c.zoom_out(),
            KeyCode::Up => c.pan(PAN_CELLS, 0.0),
            KeyCode::Down => c.pan(-PAN_CELLS, 0.0),
            KeyCode::Right => c.pan(0.0, PAN_CELLS),
            KeyCode::Left => c.pan(0.0, -PAN_CELLS),
            KeyCode::Char('f' | '0') => c.follow(),
            KeyCode::Char('r') => {
                self.map.requested = true;
                return Some(vec![Request::MissionDownload]);
            }
            _ => return None,
        }
        Some(Vec::new())
    }

    /// The last item's number: MISSION_CURRENT's `total` when the vehicle sends it, else the
    /// downloaded mission's.
    fn last_item(&self, state: &VehicleState) -> Option<u16> {
        mission_current(self, state)
            .map(|(_, t)| t)
            .filter(|t| *t != 0 && *t != u16::MAX)
            .or_else(|| {
                let m = self.map.mission.as_ref()?;
                u16::try_from(m.len().checked_sub(1)?).ok()
            })
    }

    /// A key on the mission prompt.
    pub(super) fn on_mission_prompt_key(
        &mut self,
        key: KeyEvent,
        state: &VehicleState,
    ) -> Vec<Request> {
        let Some(prompt) = self.mission_prompt.as_mut() else {
            return Vec::new();
        };
        match key.code {
            KeyCode::Char(c) => prompt.text_mut().push(c),
            KeyCode::Backspace => {
                prompt.text_mut().pop();
            }
            KeyCode::Esc => {
                self.mission_prompt = None;
                self.typing = false;
            }
            KeyCode::Enter => {
                self.typing = false;
                if let Some(p) = self.mission_prompt.take() {
                    return self.submit_mission_prompt(p, state);
                }
            }
            _ => {}
        }
        Vec::new()
    }

    fn submit_mission_prompt(&mut self, p: MissionPrompt, state: &VehicleState) -> Vec<Request> {
        let text = p.text().trim().to_owned();
        if text.is_empty() {
            return Vec::new();
        }
        match p {
            MissionPrompt::Upload(_) => {
                self.mission_file.clone_from(&text);
                self.note(Level::Info, format!("checking {text}"));
                vec![Request::MissionCheck(text)]
            }
            MissionPrompt::Save(_) => {
                self.mission_file.clone_from(&text);
                self.note(Level::Info, format!("downloading the mission into {text}"));
                vec![Request::MissionSave(text)]
            }
            MissionPrompt::Current(_) => {
                let Ok(seq) = text.parse::<u16>() else {
                    self.note(
                        Level::Error,
                        format!("set current: {text:?} is not an item number; nothing sent"),
                    );
                    return Vec::new();
                };
                if let Some(last) = self.last_item(state)
                    && (seq == 0 || seq > last)
                {
                    self.note(
                        Level::Error,
                        format!("set current: the mission has items 1 to {last}; nothing sent"),
                    );
                    return Vec::new();
                }
                let flying = self
                    .vehicle(state)
                    .is_some_and(|v| v.armed && v.mode_name() == "AUTO");
                if flying {
                    self.confirm = Some(Confirm::MissionSetCurrent { seq });
                    return Vec::new();
                }
                self.note(Level::Info, format!("current item {seq} sent"));
                vec![Request::MissionSetCurrent(seq)]
            }
        }
    }

    /// A checked file came back: its items wait for `y`, or its first problem is shown.
    pub(super) fn on_mission_checked(&mut self, checked: Result<(String, Vec<Item>), String>) {
        match checked {
            Ok((path, items)) => self.confirm = Some(Confirm::MissionUpload { path, items }),
            Err(e) => self.note(Level::Error, e),
        }
    }

    /// `y` or not on a mission step.
    pub(super) fn on_mission_confirm(&mut self, c: Confirm, yes: bool) -> Vec<Request> {
        match (c, yes) {
            (Confirm::MissionUpload { path, items }, true) => {
                self.note(Level::Info, format!("uploading {path}"));
                vec![Request::MissionUpload { path, items }]
            }
            (Confirm::MissionStart { .. }, true) => {
                self.note(Level::Info, "mission start sent");
                vec![Request::MissionStart]
            }
            (Confirm::MissionSetCurrent { seq }, true) => {
                self.note(Level::Info, format!("current item {seq} sent"));
                vec![Request::MissionSetCurrent(seq)]
            }
            (Confirm::MissionUpload { .. }, false) => {
                self.note(Level::Info, "mission upload cancelled: nothing sent");
                Vec::new()
            }
            _ => {
                self.note(Level::Info, "cancelled");
                Vec::new()
            }
        }
    }
}

impl Confirm {
    /// The question and what it will do, for the mission's steps.
    pub(super) fn mission_text(&self) -> (String, Option<String>) {
        match self {
            Confirm::MissionUpload { path, items } => (
                format!(
                    "Upload {} mission items from {path}?",
                    items.len().saturating_sub(1)
                ),
                Some(
                    "It replaces the vehicle's mission; in AUTO the vehicle flies the new one \
                     from its current item."
                        .into(),
                ),
            ),
            Confirm::MissionStart {
                from,
                armed,
                airborne,
            } => {
                let item = from.map_or_else(String::new, |s| format!(" from item {s}"));
                (
                    "Start the mission (AUTO)?".into(),
                    Some(if *airborne {
                        format!(
                            "The vehicle is IN THE AIR: it leaves what it does and flies the \
                             mission{item}."
                        )
                    } else if *armed {
                        format!("The vehicle is ARMED: it flies the mission{item}, taking off.")
                    } else {
                        "The vehicle switches to AUTO; it does not arm.".into()
                    }),
                )
            }
            Confirm::MissionSetCurrent { seq } => (
                format!("Fly to item {seq} now?"),
                Some(format!(
                    "The vehicle flies the mission in AUTO: it turns for item {seq} at once."
                )),
            ),
            _ => (String::new(), None),
        }
    }
}
