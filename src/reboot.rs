//! What the daemon does when the vehicle restarts. The tracker sees a reboot as ATTITUDE's
//! `time_boot_ms` going back ([`crate::tracker::VehicleView::reboots`]); a reboot command, a
//! power cycle and a new twin process on the same port all look alike. After one, parameters
//! the daemon knew may no longer hold (a vehicle re-reads its table at boot, and some values
//! only take effect then), so with `fetch_params` on the daemon's own client downloads the
//! whole table again, as it did when it first heard the vehicle.
//!
//! Every reboot is logged (`warn`) with the boot times either side; every download is logged
//! (`info`) with its size, and its outcome is kept in [`ParamFetches`] for the status line. The
//! download is off by default when headless: its PARAM_VALUEs are broadcasts, so every client
//! of the daemon would receive a second copy of the table in the middle of its own download.

use std::sync::{Arc, Mutex, PoisonError};

use tokio::sync::watch;
use tokio_util::sync::CancellationToken;
use vtol_link::{ComponentId, SystemId};

use vtol_link::dialect::{MavCmd, MavResult};

use crate::client::{ClientError, ClientHandle};
use crate::tracker::VehicleState;

/// Asks the vehicle's autopilot to restart (MAV_CMD_PREFLIGHT_REBOOT_SHUTDOWN, p1 = 1), which
/// is also how a crashed vehicle is cleared. ArduPilot accepts it only disarmed.
///
/// # Errors
/// [`ClientError::Refused`] with the reason (armed, unsupported), or a link error.
pub async fn reboot(client: &ClientHandle) -> Result<(), ClientError> {
    let o = client
        .command_long(
            MavCmd::MAV_CMD_PREFLIGHT_REBOOT_SHUTDOWN,
            [1.0, 0., 0., 0., 0., 0., 0.],
        )
        .await?;
    if o.accepted() {
        return Ok(());
    }
    let what = match o.result {
        MavResult::MAV_RESULT_DENIED => "denied (a vehicle reboots only disarmed)",
        MavResult::MAV_RESULT_UNSUPPORTED => "unsupported",
        MavResult::MAV_RESULT_TEMPORARILY_REJECTED => "temporarily rejected",
        _ => "failed",
    };
    Err(ClientError::Refused {
        reason: match o.reason {
            Some(r) => format!("reboot {what}: {r}"),
            None => format!("reboot {what}"),
        },
    })
}

/// The daemon's parameter downloads, as the status line shows them.
#[derive(Debug, Default)]
pub struct ParamFetches {
    inner: Mutex<FetchStatus>,
}

/// A snapshot of [`ParamFetches`].
#[derive(Debug, Default, Clone, PartialEq, Eq)]
pub struct FetchStatus {
    /// Downloads completed (the first one, then one per reboot).
    pub completed: u32,
    /// Values in the last completed download.
    pub values: usize,
    /// Reboots that caused a download.
    pub after_reboots: u32,
    /// The last failed download's error, cleared by the next success.
    pub error: Option<String>,
}

impl ParamFetches {
    /// The current figures.
    #[must_use]
    pub fn status(&self) -> FetchStatus {
        self.inner
            .lock()
            .unwrap_or_else(PoisonError::into_inner)
            .clone()
    }

    fn update(&self, f: impl FnOnce(&mut FetchStatus)) {
        f(&mut self.inner.lock().unwrap_or_else(PoisonError::into_inner));
    }
}

/// What a vehicle's parameter table needs after the tracker moved on.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Refetch {
    /// Nothing: the same vehicle, no new reboot.
    Nothing,
    /// The vehicle is heard for the first time, or is another one than before.
    First,
    /// The same vehicle rebooted since it was last looked at: its table may hold other values.
    AfterReboot,
}

/// The reboots of the vehicle one client follows, as last looked at: tells a reboot to answer
/// with a fresh table from a vehicle newly heard or switched to. The daemon's own client
/// ([`watch`]) and the terminal UI follow their vehicle with it.
#[derive(Debug, Clone, Copy, Default)]
pub struct RebootsSeen {
    seen: Option<((SystemId, ComponentId), u32)>,
}

impl RebootsSeen {
    /// Records that `key` has rebooted `reboots` times ([`crate::tracker::VehicleView::reboots`])
    /// and says what its table needs.
    pub fn update(&mut self, key: (SystemId, ComponentId), reboots: u32) -> Refetch {
        let before = self.seen.replace((key, reboots));
        match before {
            Some((k, n)) if k == key && reboots > n => Refetch::AfterReboot,
            Some((k, _)) if k == key => Refetch::Nothing,
            _ => Refetch::First,
        }
    }
}

/// Watches the tracker for the client's vehicle. With `fetch_params`, downloads the table when
/// the vehicle is first heard and again after every reboot; without it, only logs reboots.
/// Runs until `cancel` fires or the tracker stops.
pub async fn watch(
    mut state: watch::Receiver<Arc<VehicleState>>,
    client: ClientHandle,
    fetch_params: bool,
    fetches: Arc<ParamFetches>,
    cancel: CancellationToken,
) {
    let mut seen = RebootsSeen::default();
    loop {
        tokio::select! {
            () = cancel.cancelled() => return,
            r = state.changed() => if r.is_err() { return },
        }
        let found = {
            let s = state.borrow_and_update();
            let key = client
                .target()
                .or_else(|| s.vehicles.keys().next().copied());
            key.and_then(|k| s.vehicles.get(&k).map(|v| (k, v.reboots, v.last_reboot)))
        };
        let Some((key, reboots, last)) = found else {
            continue;
        };
        let refetch = seen.update(key, reboots);
        let rebooted = refetch == Refetch::AfterReboot;
        let first = refetch == Refetch::First;
        if rebooted && let Some(r) = last {
            tracing::warn!(
                "vehicle {}:{} rebooted (time_boot_ms {} -> {})",
                key.0,
                key.1,
                r.before_ms,
                r.after_ms
            );
        }
        if !fetch_params || !(first || rebooted) {
            continue;
        }
        let why = if rebooted {
            "again after the reboot"
        } else {
            "from the vehicle"
        };
        let result = tokio::select! {
            () = cancel.cancelled() => return,
            r = client.params_pull(None) => r,
        };
        match result {
            Ok(set) => {
                tracing::info!(
                    "parameters fetched {why}: {} values from {}:{}",
                    set.len(),
                    key.0,
                    key.1
                );
                fetches.update(|f| {
                    f.completed += 1;
                    f.values = set.len();
                    f.after_reboots += u32::from(rebooted);
                    f.error = None;
                });
            }
            Err(e) => {
                tracing::error!("parameter download {why} failed: {e}");
                fetches.update(|f| f.error = Some(e.to_string()));
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::{RebootsSeen, Refetch};
    use vtol_link::{ComponentId, SystemId};

    #[test]
    fn a_reboot_counts_only_for_the_vehicle_already_followed() {
        let a = (SystemId(1), ComponentId(1));
        let b = (SystemId(2), ComponentId(1));
        let mut seen = RebootsSeen::default();
        assert_eq!(seen.update(a, 0), Refetch::First);
        assert_eq!(seen.update(a, 0), Refetch::Nothing);
        assert_eq!(seen.update(a, 1), Refetch::AfterReboot);
        assert_eq!(seen.update(a, 1), Refetch::Nothing);
        // Another vehicle, even one that rebooted before, is new; so is the first one again.
        assert_eq!(seen.update(b, 3), Refetch::First);
        assert_eq!(seen.update(a, 2), Refetch::First);
    }
}
