//! The vehicle tracker task: applies every routed frame to a [`VehicleState`] and publishes it
//! on a `watch` channel for the terminal UI and the headless status line, records the recent
//! past in a [`History`] for the charts, and forgets links the router reports down.
//!
//! Its clock is tokio's ([`now`]): under a paused tokio clock a test advances the tracker's
//! time (rates, link loss, "vehicle lost") instead of waiting for it. Readers of the state
//! compare it with the same [`now`].

pub mod history;
pub mod state;
pub mod window;

use std::time::{Duration, Instant};

use tokio::sync::watch;
use tokio::time::Instant as TokioInstant;
use tokio_util::sync::CancellationToken;

use crate::router::tap::TapReceiver;
use crate::router::{LinkInfo, Tapped};
pub use history::{History, SharedHistory};
pub use state::{Reboot, VehicleState, VehicleView};

/// How often the tracker reads its tap and publishes, at most, with a terminal UI: its frame
/// rate, so a 10 kHz link does not wake the UI 10 000 times a second.
pub const UI_PERIOD: Duration = Duration::from_millis(20);
/// The same for a headless daemon, whose status lines come once a second: each tick is a
/// wake-up of a runtime thread, so an idle bridge should not take fifty a second. Under
/// traffic the tap wakes the tracker every [`TAP_RUN`] frames instead.
pub const HEADLESS_PERIOD: Duration = Duration::from_millis(100);
/// Frames applied per lock of the history, and how many waiting in the tap wake the tracker
/// before its tick.
pub const TAP_RUN: usize = 256;

/// The tracker's clock as a `std` instant: tokio's, so a paused test clock moves it.
#[must_use]
pub fn now() -> Instant {
    TokioInstant::now().into_std()
}

/// Runs the tracker until the tap closes or `cancel` fires, reading the tap and publishing
/// every `period` ([`UI_PERIOD`], [`HEADLESS_PERIOD`]). `links` is the router's list of live
/// links: a link that leaves it is forgotten, so its health does not go stale on screen.
pub async fn run(
    period: Duration,
    tap: TapReceiver,
    mut links: watch::Receiver<Vec<LinkInfo>>,
    publish: watch::Sender<VehicleState>,
    history: SharedHistory,
    cancel: CancellationToken,
) {
    let epoch = history.lock().map_or_else(|_| now(), |h| h.epoch);
    let mut state = VehicleState::new(epoch);
    let mut last_publish = TokioInstant::now();
    let mut dirty = false;
    let mut links_open = true;
    let mut tick = tokio::time::interval(period);
    let mut tap_open = true;
    let mut taken: Vec<Tapped> = Vec::new();
    while tap_open {
        // The tick is the publishing rate: publish what a tick took at once.
        let mut ticked = false;
        tokio::select! {
            () = cancel.cancelled() => break,
            r = links.changed(), if links_open => {
                if r.is_err() {
                    links_open = false;
                    continue;
                }
                let live: Vec<_> = links.borrow_and_update().iter().map(|l| l.id).collect();
                state.retain_links(&live);
                dirty = true;
            }
            // A tap filling up is taken at once.
            _ = async {
                tokio::select! {
                    _ = tick.tick() => {}
                    () = tap.filling() => {}
                }
            } => {
                // The router fills the tap without waking this task (a wake-up per frame
                // would cost more than the frame's routing): take what came since the last
                // tick, under one lock.
                ticked = true;
                let at = now();
                tap_open = tap.take(&mut taken);
                dirty |= !taken.is_empty();
                // One lock of the history per run of frames, not per frame, and never held
                // for long (the UI reads it).
                for run in taken.chunks(TAP_RUN) {
                    let Ok(mut h) = history.lock() else { break };
                    for t in run {
                        let msg = state.apply(t.link, t.side, &t.frame, at);
                        h.record(&t.frame, msg.as_ref(), at);
                    }
                }
                taken.clear();
                // Time alone changes rates and the lost state: publish once in a while even
                // when nothing arrives.
                if last_publish.elapsed() >= Duration::from_millis(500) {
                    dirty = true;
                }
            }
        }
        if dirty && (ticked || last_publish.elapsed() >= period) {
            publish.send_replace(state.clone());
            last_publish = TokioInstant::now();
            dirty = false;
        }
    }
    publish.send_replace(state);
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::router::Side;
    use std::sync::{Arc, Mutex};
    use vtol_link::{Frame, LinkId, LinkStats};

    fn info(id: LinkId) -> LinkInfo {
        LinkInfo {
            id,
            side: Side::Vehicle,
            peer: "test".into(),
            stats: Arc::new(LinkStats::default()),
            policy: crate::router::policy::EndpointPolicy::default(),
            policy_counters: Arc::default(),
        }
    }

    /// A tracker on one live link, ticking every `period`.
    struct Tracker {
        tap: crate::router::tap::TapSender,
        links: watch::Sender<Vec<LinkInfo>>,
        state: watch::Receiver<VehicleState>,
        cancel: CancellationToken,
        task: tokio::task::JoinHandle<()>,
    }

    fn tracker(period: Duration, link: LinkId) -> Tracker {
        let (tap, tap_rx) = crate::router::tap::tap(4 * TAP_RUN, TAP_RUN);
        let (links, links_rx) = watch::channel(vec![info(link)]);
        let (state_tx, state) = watch::channel(VehicleState::default());
        let history = Arc::new(Mutex::new(History::new(now())));
        let cancel = CancellationToken::new();
        let task = tokio::spawn(run(
            period,
            tap_rx,
            links_rx,
            state_tx,
            history,
            cancel.clone(),
        ));
        Tracker {
            tap,
            links,
            state,
            cancel,
            task,
        }
    }

    #[tokio::test]
    async fn a_link_that_goes_down_leaves_the_state() {
        let Tracker {
            tap: tap_tx,
            links: links_tx,
            state: mut state_rx,
            cancel,
            task,
        } = tracker(UI_PERIOD, LinkId(7));
        let frame = Frame::encode_v2(1, 1, 0, &vtol_link::gcs_heartbeat());
        tap_tx.send_run(&mut vec![Tapped {
            link: LinkId(7),
            side: Side::Vehicle,
            frame,
        }]);
        let wait = |rx: &mut watch::Receiver<VehicleState>, present: bool| {
            let mut rx = rx.clone();
            async move {
                tokio::time::timeout(Duration::from_secs(5), async {
                    while rx.borrow_and_update().links.contains_key(&LinkId(7)) != present {
                        rx.changed().await.unwrap();
                    }
                })
                .await
                .expect("state published");
            }
        };
        wait(&mut state_rx, true).await;
        links_tx.send_replace(Vec::new());
        wait(&mut state_rx, false).await;
        cancel.cancel();
        task.await.unwrap();
    }

    fn vehicle_heartbeat() -> Frame {
        use vtol_link::dialect as apm;
        let hb = apm::MavMessage::HEARTBEAT(apm::HEARTBEAT_DATA {
            custom_mode: 18,
            mavtype: apm::MavType::MAV_TYPE_VTOL_TAILSITTER_DUOROTOR,
            autopilot: apm::MavAutopilot::MAV_AUTOPILOT_GENERIC,
            base_mode: apm::MavModeFlag::MAV_MODE_FLAG_CUSTOM_MODE_ENABLED,
            system_status: apm::MavState::MAV_STATE_STANDBY,
            mavlink_version: 3,
        });
        Frame::encode_v2(1, 1, 0, &hb)
    }

    #[tokio::test(start_paused = true)]
    async fn the_tracker_runs_on_tokio_time() {
        let Tracker {
            tap: tap_tx,
            links: _links_tx,
            state: mut state_rx,
            cancel,
            task,
        } = tracker(UI_PERIOD, LinkId(3));
        let beat = || Tapped {
            link: LinkId(3),
            side: Side::Vehicle,
            frame: vehicle_heartbeat(),
        };
        // The state as published once its heartbeat time is later than `after`.
        let heard_after = |rx: &mut watch::Receiver<VehicleState>, after: Option<Instant>| {
            let mut rx = rx.clone();
            async move {
                loop {
                    let t = rx
                        .borrow_and_update()
                        .vehicles
                        .get(&(vtol_link::SystemId(1), vtol_link::ComponentId(1)))
                        .map(|v| v.last_heartbeat);
                    if let Some(t) = t
                        && after.is_none_or(|a| t > a)
                    {
                        return t;
                    }
                    rx.changed().await.unwrap();
                }
            }
        };
        tap_tx.send_run(&mut vec![beat()]);
        let first = heard_after(&mut state_rx, None).await;
        assert!(!state_rx.borrow().vehicle_lost(now()));
        // A minute passes in no time at all: the vehicle is lost by the tracker's clock.
        tokio::time::advance(Duration::from_secs(60)).await;
        assert!(state_rx.borrow().vehicle_lost(now()));
        tap_tx.send_run(&mut vec![beat()]);
        let second = heard_after(&mut state_rx, Some(first)).await;
        assert!(
            second.duration_since(first) >= Duration::from_secs(60),
            "the tracker stamped {:?} between the heartbeats",
            second.duration_since(first)
        );
        assert!(!state_rx.borrow().vehicle_lost(now()));
        cancel.cancel();
        task.await.unwrap();
    }

    /// A slow tick (a headless daemon's) does not hold frames back: [`TAP_RUN`] of them
    /// waiting wake the tracker at once.
    #[tokio::test(start_paused = true)]
    async fn a_run_of_frames_wakes_a_slow_tracker() {
        let mut t = tracker(Duration::from_secs(3600), LinkId(5));
        // A millisecond of the paused clock: the tracker's first tick (at once) is behind it,
        // and the next is an hour away. The clock only moves when every task waits, so the
        // 5 s timeout below comes first unless the run wakes the tracker.
        tokio::time::sleep(Duration::from_millis(1)).await;
        let hb = Frame::encode_v2(1, 1, 0, &vtol_link::gcs_heartbeat());
        let key = (vtol_link::SystemId(1), vtol_link::ComponentId(1), 0);
        let mut run: Vec<Tapped> = (0..TAP_RUN)
            .map(|_| Tapped {
                link: LinkId(5),
                side: Side::Vehicle,
                frame: hb.clone(),
            })
            .collect();
        t.tap.send_run(&mut run);
        tokio::time::timeout(Duration::from_secs(5), async {
            while t
                .state
                .borrow_and_update()
                .messages
                .get(&key)
                .map(|m| m.count)
                != Some(TAP_RUN as u64)
            {
                t.state.changed().await.unwrap();
            }
        })
        .await
        .expect("the tracker took the run long before its hour-long tick");
        drop(t.links);
        t.cancel.cancel();
        t.task.await.unwrap();
    }
}
