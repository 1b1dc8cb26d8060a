//! What the terminal UI's tests against the embedded twin share: the daemon they start, the
//! requests they carry out and feed back, the tracker states they wait for, the keys they type.
// Each test crate uses some of these.
#![allow(dead_code)]

pub mod recording;

use std::sync::Arc;
use std::time::{Duration, Instant};

use ratatui::crossterm::event::{KeyCode, KeyEvent, KeyModifiers};
use tokio::sync::mpsc;
use tokio_util::sync::CancellationToken;
use vtol_gcs::config::Config;
use vtol_gcs::daemon::{self, Running};
use vtol_gcs::tracker::VehicleState;
use vtol_gcs::tui::Control;
use vtol_gcs::tui::app::{App, Outcome, Request};
use vtol_gcs::tui::client_control::ClientControl;
use vtol_link::dialect::MavState;

/// Types `s` into `app`, one key a character, and returns the requests the keys make.
pub fn chars(app: &mut App, state: &VehicleState, s: &str) -> Vec<Request> {
    s.chars()
        .flat_map(|c| {
            let k = KeyEvent::new(KeyCode::Char(c), KeyModifiers::NONE);
            app.on_key(k, state, Instant::now())
        })
        .collect()
}

/// The daemon with the embedded twin (serving nothing, logging nothing) once its client has
/// found the vehicle (15 s at most), and the UI's control over that client.
pub async fn start() -> (
    Running,
    CancellationToken,
    tokio::task::JoinSet<()>,
    ClientControl,
) {
    let config = Config {
        serve: Vec::new(),
        log_dir: None,
        ..Config::default()
    };
    let cancel = CancellationToken::new();
    let mut tasks = tokio::task::JoinSet::new();
    let running = daemon::start(&config, &cancel, &mut tasks)
        .await
        .expect("daemon starts");
    let control = ClientControl::new(running.client.clone());
    running
        .client
        .wait_target(Duration::from_secs(15))
        .await
        .expect("vehicle found");
    (running, cancel, tasks, control)
}

/// Waits until a vehicle reports STANDBY (ready to arm) and returns the tracker's state.
pub async fn wait_standby(running: &Running) -> Arc<VehicleState> {
    wait_state(running, "STANDBY", |s| {
        s.vehicles
            .values()
            .any(|v| v.system_status == MavState::MAV_STATE_STANDBY)
    })
    .await
}

/// Carries out `reqs` and feeds every outcome back into `app`, returning them.
pub async fn run(app: &mut App, control: &ClientControl, reqs: Vec<Request>) -> Vec<Outcome> {
    let mut all = Vec::new();
    for r in reqs {
        // Drained while the request runs, as the UI's event loop does: a request whose
        // outcomes outnumber the channel (a download's progress reports) would otherwise wait
        // for room forever.
        let (tx, mut rx) = mpsc::channel(64);
        let drain = async {
            let mut got = Vec::new();
            while let Some(o) = rx.recv().await {
                got.push(o);
            }
            got
        };
        let ((), got) = tokio::join!(control.execute(r, tx), drain);
        for o in got {
            app.on_outcome(o.clone());
            all.push(o);
        }
    }
    all
}

/// Waits (60 s at most) until `ok` holds for the tracker's state and returns that state.
pub async fn wait_state(
    running: &Running,
    what: &str,
    ok: impl Fn(&VehicleState) -> bool,
) -> Arc<VehicleState> {
    let mut rx = running.state.clone();
    tokio::time::timeout(Duration::from_secs(60), async {
        loop {
            {
                let s = rx.borrow_and_update();
                if ok(&s) {
                    return s.clone();
                }
            }
            rx.changed().await.expect("tracker running");
        }
    })
    .await
    .unwrap_or_else(|_| panic!("timed out waiting for {what}"))
}
