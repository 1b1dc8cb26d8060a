//! The UI's requests carried out by the ground station's own client ([`ClientHandle`]):
//! commands with their ACKs, verified parameter writes, the table download and the gains-file
//! upload with its diff and progress; a mission file checked, uploaded and verified, the mission
//! downloaded into a file, started, its current item set. Holding a [`ClientControl`] marks an operator as present,
//! so the daemon's GCS heartbeat flows only while the UI is open.

use std::path::Path;
use std::sync::{Arc, Mutex};

use tokio::sync::{mpsc, watch};
use vtol_link::dialect::{self, MavFrame, MavMessage, MavMissionResult, PositionTargetTypemask};
use vtol_link::text_file;
use vtol_link::{ComponentId, SystemId};

use super::Control;
use super::app::{Outcome, Request};
use crate::client::mission::{UploadOutcome, result_words};
use crate::client::{ClientError, ClientHandle, OperatorGuard};
use crate::mission::file::{self, Format};
use crate::mission::{Item, Kind, verify};
use crate::params::file::ParamFile;
use crate::params::plan::PushResult;
use crate::params::{ParamSet, diff, unknown_names};

/// The client as the UI uses it, with the gains file loaded for upload.
#[derive(Debug, Clone)]
pub struct ClientControl {
    client: ClientHandle,
    loaded: Arc<Mutex<Option<ParamSet>>>,
    _operator: Arc<OperatorGuard>,
}

impl ClientControl {
    /// Wraps `client`; the operator counts as present until the last clone is dropped.
    #[must_use]
    pub fn new(client: ClientHandle) -> Self {
        let operator = Arc::new(client.operator_present());
        Self {
            client,
            loaded: Arc::new(Mutex::new(None)),
            _operator: operator,
        }
    }
}

fn reason(e: &ClientError) -> String {
    match e {
        ClientError::Refused { reason } => reason.clone(),
        other => other.to_string(),
    }
}

/// A watch of (done, total), and the future that forwards it as progress outcomes until the
/// sender is dropped. The caller runs that future beside the request it reports on (in the same
/// task of the UI's `JoinSet`), so it ends with it.
fn progress_forwarder(
    what: &str,
    out: mpsc::Sender<Outcome>,
) -> (
    watch::Sender<(usize, usize)>,
    impl std::future::Future<Output = ()> + use<>,
) {
    let (tx, mut rx) = watch::channel((0, 0));
    let what = what.to_owned();
    let forward = async move {
        while rx.changed().await.is_ok() {
            let (done, total) = *rx.borrow_and_update();
            let o = Outcome::Progress {
                what: what.clone(),
                done,
                total,
            };
            // Never waits for room: a progress report the UI has no room for yet is skipped
            // (the next one supersedes it), so the request beside it is never held up.
            if let Err(mpsc::error::TrySendError::Closed(_)) = out.try_send(o) {
                return;
            }
        }
    };
    (tx, forward)
}

fn table(set: &ParamSet) -> Vec<(String, f32)> {
    set.iter().map(|(n, p)| (n.clone(), p.value)).collect()
}

/// The frame that moves the QLOITER hold point: position only, in LOCAL_NED.
#[must_use]
pub fn position_target(target: (SystemId, ComponentId), ned: [f32; 3]) -> MavMessage {
    use PositionTargetTypemask as M;
    MavMessage::SET_POSITION_TARGET_LOCAL_NED(dialect::SET_POSITION_TARGET_LOCAL_NED_DATA {
        time_boot_ms: 0,
        x: ned[0],
        y: ned[1],
        z: ned[2],
        vx: 0.0,
        vy: 0.0,
        vz: 0.0,
        afx: 0.0,
        afy: 0.0,
        afz: 0.0,
        yaw: 0.0,
        yaw_rate: 0.0,
        type_mask: M::POSITION_TARGET_TYPEMASK_VX_IGNORE
            | M::POSITION_TARGET_TYPEMASK_VY_IGNORE
            | M::POSITION_TARGET_TYPEMASK_VZ_IGNORE
            | M::POSITION_TARGET_TYPEMASK_AX_IGNORE
            | M::POSITION_TARGET_TYPEMASK_AY_IGNORE
            | M::POSITION_TARGET_TYPEMASK_AZ_IGNORE
            | M::POSITION_TARGET_TYPEMASK_YAW_IGNORE
            | M::POSITION_TARGET_TYPEMASK_YAW_RATE_IGNORE,
        target_system: target.0.0,
        target_component: target.1.0,
        coordinate_frame: MavFrame::MAV_FRAME_LOCAL_NED,
    })
}

impl ClientControl {
    async fn pull(&self, out: &mpsc::Sender<Outcome>) -> Result<ParamSet, ClientError> {
        let (progress, forward) = progress_forwarder("download", out.clone());
        let (set, ()) = tokio::join!(self.client.params_pull(Some(progress)), forward);
        set
    }

    async fn load_gains(&self, path: &str) -> Result<Vec<(String, Option<f32>, f32)>, String> {
        let file = ParamFile::load(Path::new(path)).map_err(|e| e.to_string())?;
        let current = self
            .client
            .params_pull(None)
            .await
            .map_err(|e| reason(&e))?;
        let unknown = unknown_names(&current, &file.params);
        if !unknown.is_empty() {
            return Err(format!(
                "{path}: the vehicle has no parameter {}; nothing sent",
                unknown.join(", ")
            ));
        }
        let changes = diff(&current, &file.params)
            .into_iter()
            .map(|c| (c.name, Some(c.old), c.new))
            .collect();
        if let Ok(mut l) = self.loaded.lock() {
            *l = Some(file.params);
        }
        Ok(changes)
    }

    async fn push_gains(&self, out: &mpsc::Sender<Outcome>) -> Result<String, String> {
        let wanted = self
            .loaded
            .lock()
            .ok()
            .and_then(|mut l| l.take())
            .ok_or_else(|| "no gains file loaded".to_owned())?;
        let (progress, forward) = progress_forwarder("upload", out.clone());
        let (report, ()) = tokio::join!(self.client.params_push(&wanted, Some(progress)), forward);
        let report = report.map_err(|e| reason(&e))?;
        match report.result {
            PushResult::Applied => Ok(format!(
                "upload: {} changed, every value verified",
                report.changed
            )),
            PushResult::RolledBack { cause } => Err(format!(
                "upload refused, vehicle restored as it was: {cause}"
            )),
            PushResult::RollbackIncomplete { cause } => {
                let held: Vec<String> = report
                    .outcomes
                    .iter()
                    .filter_map(|(n, o)| match o {
                        crate::params::ParamOutcome::RollbackFailed { holds, .. } => {
                            Some(holds.map_or_else(|| format!("{n} = ?"), |v| format!("{n} = {v}")))
                        }
                        _ => None,
                    })
                    .collect();
                Err(format!(
                    "upload failed and the rollback did not complete ({cause}); the vehicle holds {}",
                    held.join(", ")
                ))
            }
        }
    }
}

/// A mission file read and checked as `vtol-gcs mission upload` checks it: (path, items), or
/// its first problem (and how many more).
fn check_mission(path: &str) -> Result<(String, Vec<Item>), String> {
    match verify::load(Path::new(path), Kind::Mission) {
        Ok(items) => Ok((path.to_owned(), items)),
        Err(problems) => {
            let first = problems.first().cloned().unwrap_or_default();
            let more = match problems.len() {
                0 | 1 => String::new(),
                n => format!(" (and {} more)", n - 1),
            };
            Err(format!("{first}{more}; nothing sent"))
        }
    }
}

impl ClientControl {
    /// Uploads `items`, then downloads the mission again and compares, as `vtol-gcs mission
    /// upload` does; the vehicle's mission goes to the map whatever it holds.
    async fn mission_upload(
        &self,
        path: &str,
        items: &[Item],
        out: &mpsc::Sender<Outcome>,
    ) -> Result<String, String> {
        let c = &self.client;
        let fail = |e: ClientError| format!("mission upload: {}", reason(&e));
        let outcome = c
            .mission_upload(items, Kind::Mission, |_, _| {})
            .await
            .map_err(fail)?;
        let acked = match outcome {
            UploadOutcome::Acked {
                result: MavMissionResult::MAV_MISSION_ACCEPTED,
                ..
            } => true,
            UploadOutcome::Acked { result, reason } => {
                return Err(format!(
                    "mission upload refused by the vehicle: {}{}",
                    result_words(result),
                    reason.map(|r| format!(": {r}")).unwrap_or_default(),
                ));
            }
            UploadOutcome::NoAck { .. } => false,
        };
        let back = c
            .mission_download(Kind::Mission, |_, _| {})
            .await
            .map_err(fail)?;
        let _ = out.send(Outcome::Mission(Ok(back.clone()))).await;
        if let Some(diff) = verify::difference(items, &back, Kind::Mission) {
            return Err(format!(
                "the vehicle {} the upload but holds another mission: {diff}",
                if acked {
                    "acknowledged"
                } else {
                    "did not acknowledge"
                }
            ));
        }
        Ok(format!(
            "uploaded {} mission items from {path} (verified by download)",
            items.len().saturating_sub(1)
        ))
    }

    /// Downloads the mission into `path` (`.plan` JSON, else QGC WPL 110), as `vtol-gcs
    /// mission download FILE` does; the map shows it too.
    async fn mission_save(
        &self,
        path: &str,
        out: &mpsc::Sender<Outcome>,
    ) -> Result<String, String> {
        let items = self
            .client
            .mission_download(Kind::Mission, |_, _| {})
            .await
            .map_err(|e| format!("mission download: {}", reason(&e)))?;
        let path_ref = Path::new(path);
        let text = file::write(&items, Kind::Mission, Format::for_path(path_ref));
        text_file::write_text(path_ref, &text).map_err(|e| e.to_string())?;
        let n = items.len().saturating_sub(1);
        let _ = out.send(Outcome::Mission(Ok(items))).await;
        Ok(format!("mission of {n} items written to {path}"))
    }
}

impl Control for ClientControl {
    async fn execute(&self, request: Request, out: mpsc::Sender<Outcome>) {
        let c = &self.client;
        let command = |what: String, r: Result<(), ClientError>| Outcome::Command {
            what,
            result: r.map_err(|e| reason(&e)),
        };
        let outcome = match request {
            Request::Arm { force } => command(
                if force { "force arm" } else { "arm" }.into(),
                c.arm(force).await,
            ),
            Request::Disarm => command("disarm".into(), c.disarm(false).await),
            Request::ForceDisarm => command("force disarm".into(), c.disarm(true).await),
            Request::Reboot => command("reboot".into(), crate::reboot::reboot(c).await),
            Request::SetMode(name) => command(format!("mode {name}"), c.set_mode(name).await),
            Request::PositionTarget(ned) => {
                let r = match c.target() {
                    Some(t) => c.send(position_target(t, ned)).await,
                    None => Err(ClientError::NoVehicle),
                };
                command(
                    format!(
                        "target N {:+.1} E {:+.1} alt {:.1} m",
                        ned[0], ned[1], -ned[2]
                    ),
                    r,
                )
            }
            Request::ParamSet { name, value } => {
                let result = c.param_set(&name, value).await.map_err(|e| reason(&e));
                Outcome::ParamSet { name, result }
            }
            Request::ParamsPull => match self.pull(&out).await {
                Ok(set) => Outcome::Params(table(&set)),
                Err(e) => command("parameter download".into(), Err(e)),
            },
            Request::LoadGains(path) => Outcome::GainsLoaded(self.load_gains(&path).await),
            Request::MissionDownload => Outcome::Mission(
                c.mission_download(crate::mission::Kind::Mission, |_, _| {})
                    .await
                    .map_err(|e| reason(&e)),
            ),
            Request::MissionCheck(path) => Outcome::MissionChecked(check_mission(&path)),
            Request::MissionUpload { path, items } => {
                Outcome::MissionDone(self.mission_upload(&path, &items, &out).await)
            }
            Request::MissionSave(path) => {
                Outcome::MissionDone(self.mission_save(&path, &out).await)
            }
            Request::MissionStart => command("mission start".into(), c.mission_start(None).await),
            Request::MissionSetCurrent(seq) => command(
                format!("current item {seq}"),
                c.mission_set_current(seq).await,
            ),
            Request::PushGains => {
                let result = self.push_gains(&out).await;
                // Show what the vehicle holds now, whatever happened.
                if let Ok(set) = c.params_pull(None).await {
                    let _ = out.send(Outcome::Params(table(&set))).await;
                }
                Outcome::GainsPushed(result)
            }
        };
        let _ = out.send(outcome).await;
    }

    fn select_vehicle(
        &self,
        system: vtol_link::SystemId,
        component: vtol_link::ComponentId,
    ) -> bool {
        let before = self.client.target();
        self.client.select_vehicle(system, component);
        before.is_some() && before != Some((system, component))
    }
}
