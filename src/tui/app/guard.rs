//! Guarded actions: what a key would do to a flying vehicle is named before it is sent. A
//! mode that leaves altitude control to a throttle nobody holds (QSTABILIZE with no RC
//! receiver), a disarm in the air, a forced disarm and a reboot each wait for `y`; any other
//! key (`n`) cancels and the vehicle carries on as it was.

use ratatui::crossterm::event::{KeyCode, KeyEvent};

use super::{App, Confirm, Level, Request};
use crate::tracker::{VehicleState, VehicleView};
use crate::vitals::{Vitals, vitals};

/// Modes whose throttle comes from the RC receiver: with no receiver they hold no altitude.
/// The hover ones first, then ArduPlane's fixed-wing ones (the throttle stick is the throttle).
const MANUAL_THROTTLE: [&str; 8] = [
    "QSTABILIZE",
    "QACRO",
    "MANUAL",
    "STABILIZE",
    "TRAINING",
    "ACRO",
    "FBWA",
    "AUTOTUNE",
];

impl App {
    fn vitals_of(&self, state: &VehicleState) -> Option<(Vitals, &'static str)> {
        let v: &VehicleView = self.vehicle(state)?;
        Some((vitals(state, v), if v.armed { "armed" } else { "disarmed" }))
    }

    /// A mode key: sent at once, unless it would drop altitude control in the air.
    pub(super) fn guarded_mode(
        &mut self,
        name: &'static str,
        state: &VehicleState,
    ) -> Vec<Request> {
        let Some((vit, _)) = self.vitals_of(state) else {
            return self.mode(name);
        };
        if MANUAL_THROTTLE.contains(&name) && vit.airborne && vit.rc != Some(true) {
            let consequence = if name.starts_with('Q') {
                "no RC receiver gives a throttle: the motors go to zero and the vehicle falls"
            } else {
                "no RC receiver gives a throttle: the motors go to zero; in forward flight the \
                 vehicle glides down, from a hover it falls"
            };
            self.confirm = Some(Confirm::Mode {
                name,
                consequence: consequence.into(),
            });
            return Vec::new();
        }
        self.mode(name)
    }

    /// `d`: disarm; in the air the prompt says what happens.
    pub(super) fn guarded_disarm(&mut self, state: &VehicleState) {
        let airborne = self.vitals_of(state).is_some_and(|(v, _)| v.airborne);
        self.confirm = Some(if airborne {
            Confirm::DisarmInAir
        } else {
            Confirm::Disarm
        });
    }

    /// `D`: force disarm, always behind its own prompt.
    pub(super) fn guarded_force_disarm(&mut self, state: &VehicleState) {
        let airborne = self.vitals_of(state).is_some_and(|(v, _)| v.airborne);
        self.confirm = Some(Confirm::ForceDisarm { airborne });
    }

    /// `R`: reboot the autopilot, disarmed only (the vehicle refuses it armed, as ArduPilot does).
    pub(super) fn guarded_reboot(&mut self, state: &VehicleState) {
        match self.vitals_of(state) {
            None => self.note(Level::Error, "reboot: no vehicle"),
            Some((_, "armed")) => self.note(
                Level::Error,
                "reboot: disarm first (a vehicle reboots only disarmed)",
            ),
            Some(_) => self.confirm = Some(Confirm::Reboot),
        }
    }

    pub(super) fn on_confirm(&mut self, c: Confirm, key: KeyEvent) -> Vec<Request> {
        let yes = matches!(key.code, KeyCode::Char('y' | 'Y'));
        match (c, yes) {
            (
                c @ (Confirm::MissionUpload { .. }
                | Confirm::MissionStart { .. }
                | Confirm::MissionSetCurrent { .. }),
                _,
            ) => self.on_mission_confirm(c, yes),
            (Confirm::Arm { force }, true) => {
                self.note(
                    Level::Info,
                    if force { "force arm sent" } else { "arm sent" },
                );
                vec![Request::Arm { force }]
            }
            (Confirm::Disarm | Confirm::DisarmInAir, true) => {
                self.note(Level::Info, "disarm sent");
                vec![Request::Disarm]
            }
            (Confirm::ForceDisarm { .. }, true) => {
                self.note(Level::Info, "force disarm sent");
                vec![Request::ForceDisarm]
            }
            (Confirm::Mode { name, .. }, true) => self.mode(name),
            (Confirm::Reboot, true) => {
                self.note(Level::Info, "reboot sent");
                vec![Request::Reboot]
            }
            (Confirm::Upload, true) => {
                self.params.progress = Some(("upload".into(), 0, 0));
                vec![Request::PushGains]
            }
            (Confirm::Upload, false) => {
                self.params.diff = None;
                self.note(Level::Info, "upload cancelled");
                Vec::new()
            }
            (Confirm::Mode { name, .. }, false) => {
                self.note(Level::Info, format!("mode {name} cancelled: nothing sent"));
                Vec::new()
            }
            (_, false) => {
                self.note(Level::Info, "cancelled");
                Vec::new()
            }
        }
    }
}

impl Confirm {
    /// The question and what it will do, as the prompt shows them.
    #[must_use]
    pub fn text(&self) -> (String, Option<String>) {
        match self {
            Confirm::Arm { force: false } => ("Arm the vehicle?".into(), None),
            Confirm::Arm { force: true } => ("FORCE arm (skip pre-arm checks)?".into(), None),
            Confirm::Disarm => ("Disarm the vehicle (on the ground)?".into(), None),
            Confirm::DisarmInAir => (
                "Disarm IN THE AIR?".into(),
                Some(
                    "The vehicle refuses a disarm in flight, as ArduPlane does. Land first (l); \
                     D forces it and the vehicle falls."
                        .into(),
                ),
            ),
            Confirm::ForceDisarm { airborne } => (
                "FORCE disarm: the motors stop at once?".into(),
                Some(if *airborne {
                    "The vehicle is IN THE AIR: it will fall.".into()
                } else {
                    "Skips the vehicle's checks.".into()
                }),
            ),
            Confirm::Mode { name, consequence } => (
                format!("Switch to {name} in the air?"),
                Some(format!("{consequence}. n keeps the current mode.")),
            ),
            Confirm::Reboot => (
                "Reboot the autopilot?".into(),
                Some(
                    "The link goes quiet for a moment; a crash is cleared and the parameters \
                     are read again."
                        .into(),
                ),
            ),
            Confirm::Upload => ("Upload these gains as one transaction?".into(), None),
            Confirm::MissionUpload { .. }
            | Confirm::MissionStart { .. }
            | Confirm::MissionSetCurrent { .. } => self.mission_text(),
        }
    }
}
