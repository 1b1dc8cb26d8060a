//! The vehicle tracker task: applies every routed frame to a [`VehicleState`] and publishes it
//! on a `watch` channel for the terminal UI and the headless status line.

pub mod state;

use std::time::{Duration, Instant};

use tokio::sync::{mpsc, watch};
use tokio_util::sync::CancellationToken;

use crate::router::Tapped;
pub use state::{VehicleState, VehicleView};

/// Publishes at most this often, so a 10 kHz link does not wake the UI 10 000 times a second.
const PUBLISH_EVERY: Duration = Duration::from_millis(20);

/// Runs the tracker until the tap closes or `cancel` fires.
pub async fn run(
    mut tap: mpsc::Receiver<Tapped>,
    publish: watch::Sender<VehicleState>,
    cancel: CancellationToken,
) {
    let mut state = VehicleState::default();
    let mut last_publish = Instant::now();
    let mut dirty = false;
    let mut tick = tokio::time::interval(PUBLISH_EVERY);
    loop {
        tokio::select! {
            () = cancel.cancelled() => break,
            t = tap.recv() => {
                let Some(t) = t else { break };
                state.apply(t.link, t.side, &t.frame, Instant::now());
                dirty = true;
            }
            _ = tick.tick() => {}
        }
        if dirty && last_publish.elapsed() >= PUBLISH_EVERY {
            publish.send_replace(state.clone());
            last_publish = Instant::now();
            dirty = false;
        }
    }
    publish.send_replace(state);
}
