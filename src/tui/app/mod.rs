//! The UI's own state and the key → action logic, pure: a key and the current vehicle
//! snapshot go in, the state changes and zero or more [`Request`]s for the client come out.
//! Outcomes of requests come back through [`App::on_outcome`]. Nothing here touches a terminal
//! or a socket, so it tests on its own.

use std::collections::{BTreeMap, VecDeque};
use std::time::Instant;

use ratatui::crossterm::event::{KeyCode, KeyEvent, KeyEventKind, KeyModifiers};

use vtol_link::{ComponentId, SystemId};

use crate::tracker::{VehicleState, VehicleView};
use crate::vitals::with_recovery;

pub mod fleet;
mod guard;
mod lists;
pub mod mission_keys;
mod observe;
pub mod picker;

/// Step of the QLOITER position target per arrow key, m.
pub const TARGET_STEP_M: f32 = 0.5;
/// Torque of a push (`SIM_PUSH_*`), N·m: a clear, recoverable disturbance of the twin in
/// hover (about 20° of roll for the default 200 ms; 0.2 N·m reaches about 50°).
pub const PUSH_NM: f32 = 0.1;
/// Chart window bounds and step, s.
pub const WINDOW_MIN_S: f64 = 5.0;
/// Longest chart window (the history keeps 120 s).
pub const WINDOW_MAX_S: f64 = 120.0;
/// Default chart window.
pub const WINDOW_DEFAULT_S: f64 = 30.0;
/// Lines kept in the event log.
const LOG_KEPT: usize = 64;

/// The views, in tab order.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum View {
    /// Horizon, attitude, altitude, PWM bars, messages.
    Flight,
    /// Roll/pitch/yaw, PWM and position over time.
    Charts,
    /// Links, router counters, tlog.
    Links,
    /// Every message id with its rate and fields; field charts.
    Messages,
    /// The parameter table.
    Params,
    /// Every vehicle, the lost ones first, searchable.
    Fleet,
    /// Mission, home, track, vehicle and target on a map.
    Map,
}

impl View {
    const ALL: [View; 7] = [
        View::Flight,
        View::Charts,
        View::Links,
        View::Messages,
        View::Params,
        View::Fleet,
        View::Map,
    ];

    /// Tab title.
    #[must_use]
    pub fn title(self) -> &'static str {
        match self {
            View::Flight => "Flight",
            View::Charts => "Charts",
            View::Links => "Links",
            View::Messages => "Messages",
            View::Params => "Params",
            View::Fleet => "Fleet",
            View::Map => "Map",
        }
    }

    fn index(self) -> usize {
        View::ALL.iter().position(|v| *v == self).unwrap_or(0)
    }

    /// All views in tab order.
    #[must_use]
    pub fn all() -> &'static [View] {
        &View::ALL
    }
}

/// A step waiting for `y`.
#[derive(Debug, Clone, PartialEq)]
pub enum Confirm {
    /// Arm (force skips the pre-arm checks).
    Arm {
        /// Force.
        force: bool,
    },
    /// Disarm on the ground.
    Disarm,
    /// Disarm while the vehicle reports it is in the air (it will refuse).
    DisarmInAir,
    /// Force disarm: the motors stop, in the air too.
    ForceDisarm {
        /// The vehicle was in the air when asked.
        airborne: bool,
    },
    /// A mode that drops altitude control in the air.
    Mode {
        /// The mode.
        name: &'static str,
        /// What it would do, in words.
        consequence: String,
    },
    /// Reboot the autopilot (disarmed only).
    Reboot,
    /// Upload the loaded gains file (the diff is shown).
    Upload,
    /// Upload a checked mission file.
    MissionUpload {
        /// The file.
        path: String,
        /// Its items (item 0 home).
        items: Vec<crate::mission::Item>,
    },
    /// Start the mission (MAV_CMD_MISSION_START).
    MissionStart {
        /// The current item, as MISSION_CURRENT said.
        from: Option<u16>,
        /// The vehicle was armed when asked.
        armed: bool,
        /// The vehicle was in the air when asked.
        airborne: bool,
    },
    /// Make an item current while the vehicle flies the mission.
    MissionSetCurrent {
        /// The item.
        seq: u16,
    },
}

/// What the UI asks the client to do.
#[derive(Debug, Clone, PartialEq)]
pub enum Request {
    /// Arm the vehicle.
    Arm {
        /// Skip pre-arm checks.
        force: bool,
    },
    /// Disarm the vehicle.
    Disarm,
    /// Disarm even in flight.
    ForceDisarm,
    /// Reboot the autopilot.
    Reboot,
    /// Switch mode by name.
    SetMode(&'static str),
    /// SET_POSITION_TARGET_LOCAL_NED to this north, east, down position, m.
    PositionTarget([f32; 3]),
    /// Write one parameter (SIM_PUSH_* included), shown confirmed only on a matching echo.
    ParamSet {
        /// Name.
        name: String,
        /// Value.
        value: f32,
    },
    /// Download the parameter table.
    ParamsPull,
    /// Read a gains file and compute its diff against the vehicle.
    LoadGains(String),
    /// Upload the loaded gains as one transaction.
    PushGains,
    /// Download the vehicle's mission, for the Map view.
    MissionDownload,
    /// Read a mission file and check it as `vtol-gcs mission upload` does.
    MissionCheck(String),
    /// Upload checked items, then download them again to verify.
    MissionUpload {
        /// The file they came from.
        path: String,
        /// The items (item 0 home).
        items: Vec<crate::mission::Item>,
    },
    /// Download the vehicle's mission into this file.
    MissionSave(String),
    /// MAV_CMD_MISSION_START.
    MissionStart,
    /// MAV_CMD_DO_SET_MISSION_CURRENT.
    MissionSetCurrent(u16),
}

/// What came back from a request.
#[derive(Debug, Clone, PartialEq)]
pub enum Outcome {
    /// A command finished: what it was, and Ok or the vehicle's reason.
    Command {
        /// What was asked ("arm", "mode QHOVER" …).
        what: String,
        /// Ok, or why not.
        result: Result<(), String>,
    },
    /// The table arrived (name, value), in the vehicle's order.
    Params(Vec<(String, f32)>),
    /// Progress of a pull or a push: (done, total).
    Progress {
        /// What is in progress.
        what: String,
        /// Done so far.
        done: usize,
        /// Total.
        total: usize,
    },
    /// A parameter write finished: Ok(the value the vehicle confirmed) or its reason.
    ParamSet {
        /// Name.
        name: String,
        /// Confirmed value or refusal reason.
        result: Result<f32, String>,
    },
    /// A gains file was read: the changes it would make (name, now, wanted), or why not.
    GainsLoaded(Result<Vec<(String, Option<f32>, f32)>, String>),
    /// The upload finished: a summary line, Ok when every value was verified.
    GainsPushed(Result<String, String>),
    /// The vehicle's mission arrived (item 0 is home), or why not.
    Mission(Result<Vec<crate::mission::Item>, String>),
    /// A mission file was read and checked: (path, items), or its first problem.
    MissionChecked(Result<(String, Vec<crate::mission::Item>), String>),
    /// A mission upload or a download into a file finished: a summary line, or why not.
    MissionDone(Result<String, String>),
}

/// Where a parameter stands in the UI.
#[derive(Debug, Clone, PartialEq)]
pub enum ParamStatus {
    /// Sent, no echo yet.
    Pending(f32),
    /// The vehicle's echo matched.
    Confirmed,
    /// The vehicle refused, with its reason.
    Refused(String),
    /// Typed here and rejected before sending (not a number): the vehicle was not asked.
    NotSent(String),
}

/// Severity of an event-log line (colours like STATUSTEXT).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Level {
    /// Informational.
    Info,
    /// Done.
    Ok,
    /// Refused or failed.
    Error,
}

/// The parameter view's state.
#[derive(Debug, Clone, Default)]
pub struct ParamsState {
    /// The vehicle's table in its order (empty until pulled).
    pub table: Vec<(String, f32)>,
    /// Filter typed after `/`.
    pub filter: String,
    /// Selected row among the filtered ones.
    pub selected: usize,
    /// The value being typed for the selected parameter.
    pub edit: Option<String>,
    /// The gains-file path being typed.
    pub file_prompt: Option<String>,
    /// Per-parameter status of the last writes.
    pub status: BTreeMap<String, ParamStatus>,
    /// The loaded gains file's changes (name, now, wanted), waiting for the upload.
    pub diff: Option<Vec<(String, Option<f32>, f32)>>,
    /// Progress of a pull or push: (what, done, total).
    pub progress: Option<(String, usize, usize)>,
    /// PARAM_VALUEs counted when the UI last looked (to follow the vehicle's word).
    pub seen_values: Option<u64>,
}

impl ParamsState {
    /// Rows that match the filter (case-insensitive substring), with their table index.
    #[must_use]
    pub fn filtered(&self) -> Vec<(usize, &(String, f32))> {
        let f = self.filter.to_ascii_uppercase();
        self.table
            .iter()
            .enumerate()
            .filter(|(_, (n, _))| n.contains(&f))
            .collect()
    }

    /// Value of a parameter in the table.
    #[must_use]
    pub fn value(&self, name: &str) -> Option<f32> {
        self.table.iter().find(|(n, _)| n == name).map(|(_, v)| *v)
    }
}

/// A chart series: one numeric field of one message from one sender.
#[derive(Debug, Clone, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub struct SeriesKey {
    /// Sender system id.
    pub system: SystemId,
    /// Sender component id.
    pub component: ComponentId,
    /// Message id.
    pub message: u32,
    /// Field path (`roll`, `q[2]`).
    pub path: String,
}

/// The message inspector's state.
#[derive(Debug, Clone, Default)]
pub struct MessagesState {
    /// Filter typed after `/` (message names, case-insensitive).
    pub filter: String,
    /// Selected message row.
    pub selected: usize,
    /// Selected field row of the selected message.
    pub field: usize,
    /// Whether the arrow keys move in the field list.
    pub in_fields: bool,
    /// Charts of chosen fields: each a list of series, no fixed cap.
    pub charts: Vec<Vec<SeriesKey>>,
    /// The message keys as last listed (so a key press knows what is selected).
    pub listed: Vec<(SystemId, ComponentId, u32)>,
    /// The selected message's numeric field paths as last listed.
    pub listed_fields: Vec<String>,
}

/// The whole UI state.
#[derive(Debug, Clone)]
pub struct App {
    /// Current view.
    pub view: View,
    /// `?` overlay.
    pub help: bool,
    /// A step waiting for `y`.
    pub confirm: Option<Confirm>,
    /// Whether a text field has the keyboard (filters, values, paths).
    pub typing: bool,
    /// Chart window, s.
    pub window_s: f64,
    /// Parameters.
    pub params: ParamsState,
    /// Message inspector.
    pub messages: MessagesState,
    /// The vehicle list.
    pub fleet: fleet::FleetState,
    /// QLOITER position target (north, east, down), once one was sent.
    pub target_ned: Option<[f32; 3]>,
    /// What the operator did and what came of it, newest last.
    pub log: VecDeque<(Level, String)>,
    /// The shown vehicle's mode at the last frame (to see QLOITER being entered).
    pub last_mode: Option<String>,
    /// The vehicle the UI shows and commands (`v`/`V` switch); `None` = the first listed.
    pub selected: Option<(SystemId, ComponentId)>,
    /// The mode picker, while open (`m`).
    pub picker: Option<picker::Picker>,
    /// The shown vehicle is a replayed log: no commands are offered.
    pub replay: bool,
    /// The Map view's camera and mission.
    pub map: crate::tui::map::MapState,
    /// The Map view's mission prompt, while typed.
    pub mission_prompt: Option<mission_keys::MissionPrompt>,
    /// The mission file last named (the prompts offer it).
    pub mission_file: String,
    /// Set by `q`.
    pub quit: bool,
}

impl Default for App {
    fn default() -> Self {
        Self {
            view: View::Flight,
            help: false,
            confirm: None,
            typing: false,
            window_s: WINDOW_DEFAULT_S,
            params: ParamsState::default(),
            messages: MessagesState::default(),
            fleet: fleet::FleetState::default(),
            target_ned: None,
            last_mode: None,
            log: VecDeque::new(),
            selected: None,
            picker: None,
            replay: false,
            map: Default::default(),
            mission_prompt: None,
            mission_file: mission_keys::DEFAULT_MISSION_FILE.to_owned(),
            quit: false,
        }
    }
}

impl App {
    /// The vehicle the UI shows and commands: the selected one while it is listed, else the
    /// first (lowest system id).
    #[must_use]
    pub fn vehicle<'a>(&self, state: &'a VehicleState) -> Option<&'a VehicleView> {
        self.selected
            .and_then(|k| state.vehicles.get(&k))
            .or_else(|| state.vehicles.values().next())
    }

    /// Selects the next (`step` 1) or previous (`step` -1) vehicle in system id order; the
    /// parameter view empties and the new vehicle's table is asked for.
    fn switch_vehicle(&mut self, state: &VehicleState, step: isize) -> Vec<Request> {
        let keys: Vec<_> = state.vehicles.keys().copied().collect();
        if keys.len() < 2 {
            self.note(Level::Info, "only one vehicle");
            return Vec::new();
        }
        let now = self
            .vehicle(state)
            .map(|v| (v.system_id, v.component_id))
            .and_then(|k| keys.iter().position(|x| *x == k))
            .unwrap_or(0);
        let n = keys.len() as isize;
        let next = keys[(now as isize + step).rem_euclid(n) as usize];
        self.selected = Some(next);
        self.note(
            Level::Info,
            format!("vehicle {} (component {}) selected", next.0, next.1),
        );
        self.vehicle_changed()
    }

    /// The client now commands another vehicle: forget what belonged to the last one and ask
    /// for the new one's parameter table.
    pub fn vehicle_changed(&mut self) -> Vec<Request> {
        self.params.table.clear();
        self.params.status.clear();
        self.params.diff = None;
        self.params.selected = 0;
        self.params.progress = Some(("download".into(), 0, 0));
        self.target_ned = None;
        self.last_mode = None;
        vec![Request::ParamsPull]
    }

    /// Adds a line to the event log.
    pub fn note(&mut self, level: Level, text: impl Into<String>) {
        if self.log.len() == LOG_KEPT {
            self.log.pop_front();
        }
        self.log.push_back((level, text.into()));
    }

    /// Applies one key; returns the requests it makes.
    pub fn on_key(&mut self, key: KeyEvent, state: &VehicleState, now: Instant) -> Vec<Request> {
        let _ = now;
        if key.kind == KeyEventKind::Release {
            return Vec::new();
        }
        let ctrl = key.modifiers.contains(KeyModifiers::CONTROL);
        if ctrl && key.code == KeyCode::Char('c') {
            self.quit = true;
            return Vec::new();
        }
        if let Some(c) = self.confirm.take() {
            return self.on_confirm(c, key);
        }
        if let Some(p) = self.picker.take() {
            return self.on_picker_key(p, key, state);
        }
        if self.typing && self.mission_prompt.is_some() {
            return self.on_mission_prompt_key(key, state);
        }
        if self.typing {
            return self.on_text(key);
        }
        if self.help {
            // Any key closes the overlay; `q` still quits.
            self.help = false;
            if key.code == KeyCode::Char('q') {
                self.quit = true;
            }
            return Vec::new();
        }
        match key.code {
            KeyCode::Char('q') => {
                self.quit = true;
                return Vec::new();
            }
            KeyCode::Char('?') => {
                self.help = true;
                return Vec::new();
            }
            KeyCode::Tab => {
                self.view = View::ALL[(self.view.index() + 1) % View::ALL.len()];
                return self.entered_view();
            }
            KeyCode::BackTab => {
                self.view = View::ALL[(self.view.index() + View::ALL.len() - 1) % View::ALL.len()];
                return self.entered_view();
            }
            KeyCode::Char('v') => return self.switch_vehicle(state, 1),
            KeyCode::Char('V') => return self.switch_vehicle(state, -1),
            _ => {}
        }
        // View keys first (lists take the arrows), then the flight commands.
        if let Some(reqs) = match self.view {
            View::Messages => self.on_messages_key(key),
            View::Params => self.on_params_key(key),
            View::Fleet => self.on_fleet_key(key),
            View::Map => self.on_map_key(key, state),
            View::Flight | View::Charts | View::Links => None,
        } {
            return reqs;
        }
        self.on_command_key(key, state)
    }

    /// Flight commands: arm, modes, QLOITER target, pushes, chart window.
    fn on_command_key(&mut self, key: KeyEvent, state: &VehicleState) -> Vec<Request> {
        if self.replay && Self::is_command_key(key) {
            self.refuse_on_replay();
            return Vec::new();
        }
        let vehicle = self.vehicle(state);
        match key.code {
            KeyCode::Char('a') => self.confirm = Some(Confirm::Arm { force: false }),
            KeyCode::Char('A') => self.confirm = Some(Confirm::Arm { force: true }),
            KeyCode::Char('d') => self.guarded_disarm(state),
            KeyCode::Char('D') => self.guarded_force_disarm(state),
            KeyCode::Char('R') => self.guarded_reboot(state),
            KeyCode::Char('t') => return self.guarded_mode("QHOVER", state),
            KeyCode::Char('l') => return self.guarded_mode("QLAND", state),
            KeyCode::Char('p') => return self.guarded_mode("QLOITER", state),
            KeyCode::Char('s') => return self.guarded_mode("QSTABILIZE", state),
            KeyCode::Char('m') => self.open_picker(state),
            KeyCode::Char(c @ ('x' | 'X' | 'c' | 'C' | 'z' | 'Z')) => {
                let (axis, sign) = match c {
                    'x' => ("ROLL", 1.0),
                    'X' => ("ROLL", -1.0),
                    'c' => ("PITCH", 1.0),
                    'C' => ("PITCH", -1.0),
                    'z' => ("YAW", 1.0),
                    _ => ("YAW", -1.0),
                };
                let name = format!("SIM_PUSH_{axis}");
                let value = sign * PUSH_NM;
                self.note(Level::Info, format!("push {name} = {value:+} N·m"));
                return vec![Request::ParamSet { name, value }];
            }
            KeyCode::Char('+' | '=') => self.window_s = (self.window_s * 2.0).min(WINDOW_MAX_S),
            KeyCode::Char('-') => self.window_s = (self.window_s / 2.0).max(WINDOW_MIN_S),
            KeyCode::Up | KeyCode::Down | KeyCode::Left | KeyCode::Right => {
                let (dn, de) = match key.code {
                    KeyCode::Up => (TARGET_STEP_M, 0.0),
                    KeyCode::Down => (-TARGET_STEP_M, 0.0),
                    KeyCode::Right => (0.0, TARGET_STEP_M),
                    _ => (0.0, -TARGET_STEP_M),
                };
                return self.move_target(vehicle, dn, de, 0.0);
            }
            KeyCode::PageUp => return self.move_target(vehicle, 0.0, 0.0, -TARGET_STEP_M),
            KeyCode::PageDown => return self.move_target(vehicle, 0.0, 0.0, TARGET_STEP_M),
            _ => {}
        }
        Vec::new()
    }

    fn mode(&mut self, name: &'static str) -> Vec<Request> {
        self.note(Level::Info, format!("mode {name} sent"));
        if name != "QLOITER" {
            self.target_ned = None;
        }
        vec![Request::SetMode(name)]
    }

    /// Moves the QLOITER target; the first move starts from where the vehicle is.
    fn move_target(
        &mut self,
        vehicle: Option<&VehicleView>,
        dn: f32,
        de: f32,
        dd: f32,
    ) -> Vec<Request> {
        let Some(v) = vehicle else {
            self.note(Level::Error, "no vehicle");
            return Vec::new();
        };
        if v.mode_name() != "QLOITER" {
            self.note(
                Level::Error,
                "arrows and PgUp/PgDn move the target in QLOITER only (p)",
            );
            return Vec::new();
        }
        let start = self.target_ned.or_else(|| v.position.map(|p| p.pos_ned_m));
        let Some(mut t) = start else {
            self.note(Level::Error, "no position from the vehicle yet");
            return Vec::new();
        };
        t[0] += dn;
        t[1] += de;
        // Down is negative up; never below the ground (z = 0).
        t[2] = (t[2] + dd).min(0.0);
        self.target_ned = Some(t);
        vec![Request::PositionTarget(t)]
    }

    /// Applies what came back from the client.
    pub fn on_outcome(&mut self, outcome: Outcome) {
        match outcome {
            Outcome::Command { what, result } => match result {
                Ok(()) => self.note(Level::Ok, format!("{what}: done")),
                Err(e) => self.note(Level::Error, format!("{what}: {}", with_recovery(&e))),
            },
            Outcome::Params(table) => {
                self.params.table = table;
                // Fresh values from the vehicle: a local typing error is history.
                self.params
                    .status
                    .retain(|_, s| !matches!(s, ParamStatus::NotSent(_)));
                self.params.progress = None;
                let n = self.params.table.len();
                self.note(Level::Ok, format!("{n} parameters"));
            }
            Outcome::Progress { what, done, total } => {
                // The last step of a transfer may come after its result (the progress has a
                // task of its own): a finished one shows nothing.
                self.params.progress = (total == 0 || done < total).then_some((what, done, total));
            }
            Outcome::ParamSet { name, result } => match result {
                Ok(v) => {
                    if let Some(row) = self.params.table.iter_mut().find(|(n, _)| *n == name) {
                        row.1 = v;
                    }
                    // A push resets itself; the log says it went out.
                    if !name.starts_with("SIM_PUSH_") {
                        self.note(Level::Ok, format!("{name} = {v} confirmed"));
                    }
                    self.params.status.insert(name, ParamStatus::Confirmed);
                }
                Err(reason) => {
                    self.note(Level::Error, format!("{name} refused: {reason}"));
                    self.params
                        .status
                        .insert(name, ParamStatus::Refused(reason));
                }
            },
            Outcome::GainsLoaded(Ok(diff)) => {
                if diff.is_empty() {
                    self.note(
                        Level::Ok,
                        "the vehicle already holds every value in the file",
                    );
                    self.params.diff = None;
                } else {
                    self.params.diff = Some(diff);
                    self.confirm = Some(Confirm::Upload);
                }
            }
            Outcome::GainsLoaded(Err(e)) => self.note(Level::Error, e),
            Outcome::Mission(Ok(items)) => {
                let radius = self.param("WP_LOITER_RAD").unwrap_or(60.0);
                self.map.items = crate::tui::map::items_from_mission(&items, radius);
                let n = items.len().saturating_sub(1);
                self.map.mission = Some(items);
                self.note(
                    Level::Ok,
                    format!("mission of {n} items (r: download again)"),
                );
            }
            Outcome::Mission(Err(e)) => self.note(Level::Error, format!("mission download: {e}")),
            Outcome::MissionChecked(checked) => self.on_mission_checked(checked),
            Outcome::MissionDone(Ok(s)) => self.note(Level::Ok, s),
            Outcome::MissionDone(Err(e)) => self.note(Level::Error, e),
            Outcome::GainsPushed(result) => {
                self.params.progress = None;
                if result.is_ok() {
                    // Every value of the upload was read back: confirmed, as a single write is.
                    for (name, _, _) in self.params.diff.take().unwrap_or_default() {
                        self.params.status.insert(name, ParamStatus::Confirmed);
                    }
                }
                self.params.diff = None;
                match result {
                    Ok(s) => self.note(Level::Ok, s),
                    Err(e) => self.note(Level::Error, e),
                }
            }
        }
    }

    /// What entering a view asks for: the Map view downloads the mission the first time (a
    /// replayed log has no vehicle to ask).
    fn entered_view(&mut self) -> Vec<Request> {
        if self.view == View::Map && !self.map.requested && !self.replay {
            self.map.requested = true;
            self.note(Level::Info, "downloading the mission");
            return vec![Request::MissionDownload];
        }
        Vec::new()
    }

    /// A parameter's value from the pulled table.
    fn param(&self, name: &str) -> Option<f32> {
        self.params
            .table
            .iter()
            .find(|(n, _)| n == name)
            .map(|(_, v)| *v)
    }
}
