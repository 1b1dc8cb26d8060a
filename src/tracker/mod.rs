//! The vehicle tracker task: applies every routed frame to a [`VehicleState`] and publishes it
//! on a `watch` channel for the terminal UI and the headless status line, records the recent
//! past in a [`History`] for the charts, and forgets links the router reports down.
//!
//! The state is published as an `Arc<VehicleState>`: publishing shares it, and every reader
//! (a redraw, a status line) borrows it. It is copied on write, by whoever applies the first
//! run of frames after a publish (this task or a link's thread): at most once per publish, and
//! not at all while nothing changes it.
//!
//! Locks, in the order they are taken: the tracker's state (`Core`), then its history, then
//! the tap's ([`crate::tap::queue`]); frames are decoded holding the first two only. The
//! router's lock is never held with any of them.
//!
//! Its clock is tokio's ([`now`]): under a paused tokio clock a test advances the tracker's
//! time (rates, link loss, "vehicle lost") instead of waiting for it. Readers of the state
//! compare it with the same [`now`].

pub mod history;
pub mod seq;
pub mod state;
pub mod window;

use std::sync::{Arc, Mutex, PoisonError};
use std::time::{Duration, Instant};

use tokio::sync::watch;
use tokio::time::Instant as TokioInstant;
use tokio_util::sync::CancellationToken;

use crate::links::LinkInfo;
use crate::tap::{Drain, TapReceiver, Tapped, Waiting};
pub use history::{History, SharedHistory};
pub use state::{Reboot, VehicleState, VehicleView};

/// How often the tracker reads its tap and publishes, at most, with a terminal UI: its frame
/// rate, so a 10 kHz link does not wake the UI 10 000 times a second.
pub const UI_PERIOD: Duration = Duration::from_millis(20);
/// The same for a headless daemon, whose status lines come once a second: each tick is a
/// wake-up of a runtime thread, so an idle bridge should not take fifty a second. Under
/// traffic the router's thread applies the frames itself, [`INLINE_RUN`] at a time, and when
/// it cannot (the state is busy) the tap wakes the tracker every [`TAP_RUN`] frames.
pub const HEADLESS_PERIOD: Duration = Duration::from_millis(100);
/// Frames applied per lock of the history, and how many waiting in the tap wake the tracker
/// before its tick.
pub const TAP_RUN: usize = 256;
/// The router's thread applies tapped frames itself once this many wait: in runs, so that the
/// tracker's maps and windows are warm for all but the first frame of a run. Fewer wait for a
/// later run or for the tracker's tick, which publishes no sooner either way.
pub const INLINE_RUN: usize = 32;

/// The tracker's clock as a `std` instant: the router's ([`crate::tap::clock`]), tokio's,
/// so a paused test clock moves it.
#[must_use]
pub fn now() -> Instant {
    crate::tap::clock()
}

/// The tracker's state, shared between its task and the router's thread (which applies
/// frames itself when the state is free, [`Drain`]).
struct Core {
    /// Shared with the last published snapshot until a frame changes it.
    state: Arc<VehicleState>,
    /// Changed since it was last published.
    dirty: bool,
    /// The frames taken from the tap, decoded after its lock is released (a buffer kept from
    /// one run to the next, traded with the tap's).
    taken: Vec<Tapped>,
}

/// What the router's thread needs to apply tapped frames itself.
struct Inline {
    core: Arc<Mutex<Core>>,
    history: SharedHistory,
}

impl Drain for Inline {
    fn try_apply(&self, waiting: &Waiting<'_>) -> bool {
        // Never wait: the tracker may be publishing, the terminal UI may be drawing from the
        // history. The frames then wait in the tap for the next run or the tracker's tick.
        let Ok(mut core) = self.core.try_lock() else {
            return false;
        };
        let Ok(mut history) = self.history.try_lock() else {
            return false;
        };
        // Taken holding the state, so no later frame is applied before these; decoded once
        // the tap's lock is released.
        let mut frames = std::mem::take(&mut core.taken);
        waiting.take(&mut frames);
        apply(&mut core, &mut history, &frames);
        frames.clear();
        core.taken = frames;
        true
    }
}

/// Applies `frames` to the state and the history, each at the time the router took it.
fn apply(core: &mut Core, history: &mut History, frames: &[Tapped]) {
    if frames.is_empty() {
        return;
    }
    // Copied here only if the published snapshot still shares it.
    let state = Arc::make_mut(&mut core.state);
    for t in frames {
        let stamp = state.stamp(t.at);
        let msg = state.apply_stamped(t.link, t.side, &t.frame, &stamp);
        history.record_stamped(&t.frame, msg.as_ref(), &stamp);
    }
    core.dirty = true;
}

/// Runs the tracker until the tap closes or `cancel` fires, publishing every `period`
/// ([`UI_PERIOD`], [`HEADLESS_PERIOD`]) when something changed. The frames are applied by the
/// router's thread in runs of [`INLINE_RUN`] as it routes them, whenever the state is free at
/// that instant, and otherwise by this task from the tap, on its tick or when [`TAP_RUN`] of
/// them wait; each at the time the router took it. `links` is the router's list of live
/// links: a link that leaves it is forgotten, so its health does not go stale on screen.
pub async fn run(
    period: Duration,
    tap: TapReceiver,
    mut links: watch::Receiver<Vec<LinkInfo>>,
    publish: watch::Sender<Arc<VehicleState>>,
    history: SharedHistory,
    cancel: CancellationToken,
) {
    let epoch = history.lock().map_or_else(|_| now(), |h| h.epoch);
    let core = Arc::new(Mutex::new(Core {
        state: Arc::new(VehicleState::new(epoch)),
        dirty: false,
        taken: Vec::new(),
    }));
    tap.drain_inline(
        Arc::new(Inline {
            core: Arc::clone(&core),
            history: Arc::clone(&history),
        }),
        INLINE_RUN,
    );
    // Plain data: a panic elsewhere leaves it usable.
    let lock_core = || core.lock().unwrap_or_else(PoisonError::into_inner);
    let mut last_publish = TokioInstant::now();
    let mut links_open = true;
    let mut tick = tokio::time::interval(period);
    let mut tap_open = true;
    while tap_open {
        // The tick is the publishing rate: publish what a tick found at once.
        let mut ticked = false;
        tokio::select! {
            () = cancel.cancelled() => break,
            r = links.changed(), if links_open => {
                if r.is_err() {
                    links_open = false;
                    continue;
                }
                let live: Vec<_> = links.borrow_and_update().iter().map(|l| l.id).collect();
                let mut c = lock_core();
                Arc::make_mut(&mut c.state).retain_links(&live);
                c.dirty = true;
            }
            // A tap filling up is taken at once.
            _ = async {
                tokio::select! {
                    _ = tick.tick() => {}
                    () = tap.filling() => {}
                }
            } => {
                ticked = true;
                let mut c = lock_core();
                // What the router could not apply itself, taken while holding the state (so
                // no later frame is applied before these) and decoded once the tap's lock is
                // released, in runs of at most TAP_RUN per lock of the history, which the UI
                // reads.
                let mut taken = std::mem::take(&mut c.taken);
                tap_open = tap.take(&mut taken);
                for run in taken.chunks(TAP_RUN) {
                    let Ok(mut h) = history.lock() else { break };
                    apply(&mut c, &mut h, run);
                }
                taken.clear();
                c.taken = taken;
                // Time alone changes rates and the lost state: publish once in a while even
                // when nothing arrives.
                if last_publish.elapsed() >= Duration::from_millis(500) {
                    c.dirty = true;
                }
            }
        }
        let mut c = lock_core();
        if c.dirty && (ticked || last_publish.elapsed() >= period) {
            publish.send_replace(Arc::clone(&c.state));
            c.dirty = false;
            drop(c);
            last_publish = TokioInstant::now();
        }
    }
    publish.send_replace(Arc::clone(&lock_core().state));
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::links::Side;
    use std::sync::{Arc, Mutex};
    use vtol_link::{Frame, LinkId, LinkStats};

    fn info(id: LinkId) -> LinkInfo {
        LinkInfo {
            id,
            side: Side::Vehicle,
            peer: "test".into(),
            stats: Arc::new(LinkStats::default()),
            policy: crate::trust::policy::EndpointPolicy::default(),
            policy_counters: Arc::default(),
        }
    }

    /// A tracker on one live link, ticking every `period`.
    struct Tracker {
        tap: crate::tap::TapSender,
        links: watch::Sender<Vec<LinkInfo>>,
        state: watch::Receiver<Arc<VehicleState>>,
        history: SharedHistory,
        cancel: CancellationToken,
        task: tokio::task::JoinHandle<()>,
    }

    fn tracker(period: Duration, link: LinkId) -> Tracker {
        let (tap, tap_rx) = crate::tap::tap(4 * TAP_RUN, TAP_RUN);
        let (links, links_rx) = watch::channel(vec![info(link)]);
        let (state_tx, state) = watch::channel(Arc::new(VehicleState::default()));
        let history = Arc::new(Mutex::new(History::new(now())));
        let cancel = CancellationToken::new();
        let task = tokio::spawn(run(
            period,
            tap_rx,
            links_rx,
            state_tx,
            Arc::clone(&history),
            cancel.clone(),
        ));
        Tracker {
            tap,
            links,
            state,
            history,
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
            ..
        } = tracker(UI_PERIOD, LinkId(7));
        let frame = Frame::encode_v2(
            vtol_link::SystemId(1),
            vtol_link::ComponentId(1),
            0,
            &vtol_link::gcs_heartbeat(),
        );
        tap_tx.send_run(&mut vec![Tapped {
            link: LinkId(7),
            side: Side::Vehicle,
            frame,
            at: now(),
        }]);
        let wait = |rx: &mut watch::Receiver<Arc<VehicleState>>, present: bool| {
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
        Frame::encode_v2(vtol_link::SystemId(1), vtol_link::ComponentId(1), 0, &hb)
    }

    #[tokio::test(start_paused = true)]
    async fn the_tracker_runs_on_tokio_time() {
        let Tracker {
            tap: tap_tx,
            links: _links_tx,
            state: mut state_rx,
            cancel,
            task,
            ..
        } = tracker(UI_PERIOD, LinkId(3));
        let beat = || Tapped {
            link: LinkId(3),
            side: Side::Vehicle,
            frame: vehicle_heartbeat(),
            at: now(),
        };
        // The state as published once its heartbeat time is later than `after`.
        let heard_after = |rx: &mut watch::Receiver<Arc<VehicleState>>, after: Option<Instant>| {
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

    /// Publishing shares the state: the half-second republish of a vehicle that sent nothing
    /// since is the same snapshot, and a frame after it gets a copy of its own.
    #[tokio::test(start_paused = true)]
    async fn an_unchanged_state_is_republished_without_a_copy() {
        let mut t = tracker(UI_PERIOD, LinkId(4));
        t.tap.send_run(&mut heartbeat_run(LinkId(4), 1));
        published(&mut t, 1, Duration::from_secs(5))
            .await
            .expect("the heartbeat published");
        let first = Arc::clone(&t.state.borrow_and_update());
        tokio::time::timeout(Duration::from_secs(5), t.state.changed())
            .await
            .expect("republished within the half second")
            .unwrap();
        let again = Arc::clone(&t.state.borrow_and_update());
        assert!(
            Arc::ptr_eq(&first, &again),
            "the unchanged state was copied"
        );
        t.tap
            .send_run(&mut heartbeat_run(LinkId(4), 2)[1..].to_vec());
        published(&mut t, 2, Duration::from_secs(5))
            .await
            .expect("the second heartbeat published");
        assert_eq!(
            first.messages.values().map(|m| m.count).sum::<u64>(),
            1,
            "a published snapshot changed after it was published"
        );
        stop(t).await;
    }

    /// Messages counted for sysid 1 compid 1, message 0, in the last published state.
    fn heartbeats_published(t: &mut Tracker) -> Option<u64> {
        let key = (vtol_link::SystemId(1), vtol_link::ComponentId(1), 0);
        t.state
            .borrow_and_update()
            .messages
            .get(&key)
            .map(|m| m.count)
    }

    /// Waits (on the tracker's clock) until `n` heartbeats are published.
    async fn published(
        t: &mut Tracker,
        n: u64,
        within: Duration,
    ) -> Result<(), tokio::time::error::Elapsed> {
        tokio::time::timeout(within, async {
            while heartbeats_published(t) != Some(n) {
                t.state.changed().await.unwrap();
            }
        })
        .await
    }

    async fn stop(t: Tracker) {
        drop(t.links);
        t.cancel.cancel();
        t.task.await.unwrap();
    }

    /// `n` heartbeats numbered in sequence (the same frame repeated would be one datagram
    /// repeated, counted once).
    fn heartbeat_run(link: LinkId, n: usize) -> Vec<Tapped> {
        (0..n)
            .map(|i| Tapped {
                link,
                side: Side::Vehicle,
                frame: Frame::encode_v2(
                    vtol_link::SystemId(1),
                    vtol_link::ComponentId(1),
                    (i % 256) as u8,
                    &vtol_link::gcs_heartbeat(),
                ),
                at: now(),
            })
            .collect()
    }

    /// A slow tick (a headless daemon's) does not hold frames back: when the router's thread
    /// cannot apply them itself (the history is busy, e.g. being drawn), [`TAP_RUN`] of them
    /// waiting wake the tracker at once.
    #[tokio::test(start_paused = true)]
    async fn a_run_of_frames_wakes_a_slow_tracker() {
        let mut t = tracker(Duration::from_secs(3600), LinkId(5));
        // A millisecond of the paused clock: the tracker's first tick (at once) is behind it,
        // and the next is an hour away. The clock only moves when every task waits, so the
        // 5 s timeout below comes first unless the run wakes the tracker.
        tokio::time::sleep(Duration::from_millis(1)).await;
        {
            let _drawing = t.history.lock().unwrap();
            t.tap.send_run(&mut heartbeat_run(LinkId(5), TAP_RUN));
        }
        published(&mut t, TAP_RUN as u64, Duration::from_secs(5))
            .await
            .expect("the tracker took the run long before its hour-long tick");
        stop(t).await;
    }

    /// Frames are applied by the thread that routes them when the tracker's state is free: the
    /// tracker is not woken for them, and publishes them on its next tick.
    #[tokio::test(start_paused = true)]
    async fn the_router_thread_applies_frames_and_the_tick_publishes_them() {
        let period = Duration::from_secs(1);
        let mut t = tracker(period, LinkId(6));
        tokio::time::sleep(Duration::from_millis(1)).await;
        t.state.borrow_and_update();
        t.tap.send_run(&mut heartbeat_run(LinkId(6), TAP_RUN));
        // Applied already: the history, written with the state in the same call, has them.
        let recorded: usize = t
            .history
            .lock()
            .unwrap()
            .frames
            .values()
            .map(history::FrameRing::len)
            .sum();
        assert_eq!(
            recorded, TAP_RUN,
            "the frames were left in the tap for the tracker"
        );
        // Nothing is published before the tick (the tracker was not woken)...
        tokio::time::sleep(period / 2).await;
        assert!(
            !t.state.has_changed().unwrap(),
            "published before the tick: something woke the tracker"
        );
        // ...and the run is on the next one.
        published(&mut t, TAP_RUN as u64, period)
            .await
            .expect("the tick published the frames the router's thread applied");
        stop(t).await;
    }
}
