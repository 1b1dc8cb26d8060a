//! The terminal ground station: ratatui over crossterm. [`app`] holds the UI state, turns keys
//! into [`app::Request`]s and follows the tracker between frames ([`observe`]), all pure;
//! [`view`] draws a [`view::Snapshot`] as the [`app::App`] shows it, reading the app and writing
//! only its own [`view::RenderState`]; and [`run`] is the thin shell: terminal set-up and
//! restore, input on its own thread, redraws capped at 30 fps and only when something changed,
//! requests handed to a [`Control`] (the client) as tasks of one `JoinSet`, aborted on the way
//! out.
//!
//! The terminal is restored on every way out: a normal return, an error, a panic (ratatui's
//! hook), and SIGTERM/Ctrl-C (the caller's cancellation token ends the loop).

pub mod air;
pub mod app;
pub mod attitude;
pub mod client_control;
pub mod map;
pub mod progress;
pub mod view;

use std::future::Future;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

use ratatui::crossterm::event::{self, Event, KeyEventKind};
use tokio::sync::mpsc;
use tokio::task::JoinSet;
use tokio_util::sync::CancellationToken;
use vtol_link::{ComponentId, SystemId};

use crate::daemon::{OWN_TRAFFIC_PEER, Running, describe};
use crate::reboot::{RebootsSeen, Refetch};
use crate::tracker::VehicleState;
use crate::trust::policy::EndpointPolicy;
use app::{App, Outcome, Request};
use view::{LinkRow, RenderState, RouterCounters, Snapshot, TlogInfo};

/// Shortest time between two redraws driven by vehicle data (30 fps). Keys redraw at once.
pub const FRAME_INTERVAL: Duration = Duration::from_millis(33);
/// Redraw at least this often, so ages and the lost state move on a silent link.
const IDLE_REDRAW: Duration = Duration::from_millis(500);

/// Carries out the UI's requests (the ground station's client) and reports what came of them.
pub trait Control: Clone + Send + Sync + 'static {
    /// Carries out one request, sending its outcome(s) on `out`.
    fn execute(
        &self,
        request: Request,
        out: mpsc::Sender<Outcome>,
    ) -> impl Future<Output = ()> + Send;

    /// Makes `system`/`component` the vehicle later requests go to; true when that changed
    /// the client's vehicle. Called before the requests of the same key are carried out.
    fn select_vehicle(&self, system: SystemId, component: ComponentId) -> bool {
        let _ = (system, component);
        false
    }
}

/// Keeps the client on the vehicle the UI shows (the operator's choice, else the first one
/// listed). True when the client had to change vehicle.
fn sync_selection<C: Control>(
    app: &mut App,
    state: &VehicleState,
    control: &C,
    sent: &mut Option<(SystemId, ComponentId)>,
) -> bool {
    let Some(v) = app.vehicle(state) else {
        return false;
    };
    let key = (v.system_id, v.component_id);
    if app.selected.is_none() {
        app.selected = Some(key);
    }
    if *sent == Some(key) {
        return false;
    }
    *sent = Some(key);
    control.select_vehicle(key.0, key.1)
}

/// Whether the vehicle `app` shows comes over a replay link (a recorded log).
#[must_use]
pub fn is_replay(app: &App, state: &VehicleState, links: &[LinkRow]) -> bool {
    app.vehicle(state).is_some_and(|v| {
        links
            .iter()
            .any(|l| l.id == v.link && l.peer == crate::daemon::REPLAY_PEER)
    })
}

/// Brings `app` up to date with what `snap` shows, before [`view::draw`] draws it: whether the
/// shown vehicle is a replay, and what [`App::observe`] follows.
pub fn observe(app: &mut App, snap: &Snapshot<'_>) {
    app.observe(snap.state, snap.now);
    app.replay = is_replay(app, snap.state, &snap.links);
}

/// Builds what one frame shows from the running daemon.
#[must_use]
pub fn links_and_counters(running: &Running) -> (Vec<LinkRow>, RouterCounters, Option<TlogInfo>) {
    let links = running
        .router
        .links
        .borrow()
        .iter()
        .map(|l| LinkRow {
            id: l.id,
            side: l.side,
            peer: l.peer.clone(),
            own: l.peer == OWN_TRAFFIC_PEER,
            stats: l.stats.snapshot(),
            policy: (l.policy != EndpointPolicy::default() && l.peer != OWN_TRAFFIC_PEER)
                .then(|| (l.policy, l.policy_counters.snapshot())),
        })
        .collect();
    let s = &running.router.stats;
    let counters = RouterCounters {
        frames_in: s.frames_in.load(Ordering::Relaxed),
        frames_out: s.frames_out.load(Ordering::Relaxed),
        unroutable: s.unroutable.load(Ordering::Relaxed),
        withheld_signing: s.withheld_signing.load(Ordering::Relaxed),
        dropped_link_closed: s.dropped_link_closed.load(Ordering::Relaxed),
        dropped_tap: s.dropped_tap.load(Ordering::Relaxed),
        signing_refused: running
            .router
            .signing
            .as_ref()
            .map_or(0, |c| c.snapshot().refused()),
        sysid_conflicts: s.sysid_conflicts.load(Ordering::Relaxed),
        conflict: running.router.conflicts.borrow().first().copied(),
    };
    let tlog = running.tlog_path.as_ref().map(|p| {
        let st = running.tlog_stats.as_deref();
        let get = |f: fn(&crate::tlog::TlogStats) -> &std::sync::atomic::AtomicU64| {
            st.map_or(0, |s| f(s).load(Ordering::Relaxed))
        };
        TlogInfo {
            path: p.display().to_string(),
            bytes: get(|s| &s.bytes),
            records: get(|s| &s.records),
            dropped: get(|s| &s.dropped_queue_full),
            errors: get(|s| &s.write_errors),
            failing: st.and_then(crate::tlog::TlogStats::failing),
        }
    });
    (links, counters, tlog)
}

/// One frame of the running daemon's state on any ratatui backend: the app observes it
/// ([`observe`]), then the view draws it.
///
/// # Errors
/// The backend's write error.
pub fn draw_running<B: ratatui::backend::Backend>(
    terminal: &mut ratatui::Terminal<B>,
    app: &mut App,
    running: &Running,
    render: &mut RenderState,
    now: Instant,
) -> Result<(), B::Error> {
    let state = running.state.borrow().clone();
    let (links, router, tlog) = links_and_counters(running);
    let serving = running
        .serving
        .iter()
        .map(|(u, a, p)| format!("{}{}", describe(u, *a), p.query()))
        .collect();
    let history = running
        .history
        .lock()
        .unwrap_or_else(std::sync::PoisonError::into_inner);
    let snap = Snapshot {
        now,
        state: &state,
        history: &history,
        links,
        router,
        tlog,
        serving,
    };
    observe(app, &snap);
    terminal.draw(|f| view::draw(f, app, render, &snap))?;
    Ok(())
}

/// Reads terminal events on a plain thread (crossterm's read blocks) until `stop` is set.
fn spawn_input(tx: mpsc::Sender<Event>, stop: Arc<AtomicBool>) -> std::thread::JoinHandle<()> {
    std::thread::spawn(move || {
        while !stop.load(Ordering::Relaxed) {
            match event::poll(Duration::from_millis(100)) {
                Ok(true) => match event::read() {
                    Ok(ev) => {
                        if tx.blocking_send(ev).is_err() {
                            return;
                        }
                    }
                    Err(_) => return,
                },
                Ok(false) => {}
                Err(_) => return,
            }
        }
    })
}

/// Runs the UI on the terminal until `q` or `cancel`; restores the terminal on the way out.
///
/// # Errors
/// The terminal could not be set up or written.
pub async fn run<C: Control>(
    running: &Running,
    control: C,
    cancel: CancellationToken,
) -> std::io::Result<()> {
    let mut terminal = ratatui::try_init()?;
    let stop = Arc::new(AtomicBool::new(false));
    let (key_tx, keys) = mpsc::channel(64);
    let input = spawn_input(key_tx, Arc::clone(&stop));
    let result = event_loop(&mut terminal, running, control, keys, cancel).await;
    stop.store(true, Ordering::Relaxed);
    let _ = tokio::task::spawn_blocking(move || input.join()).await;
    ratatui::try_restore()?;
    result
}

/// Carries out `request` with `control` as one of the loop's `tasks`; its outcomes come back
/// on `out`.
fn spawn_request<C: Control>(
    tasks: &mut JoinSet<()>,
    control: &C,
    out: &mpsc::Sender<Outcome>,
    request: Request,
) {
    let c = control.clone();
    let out = out.clone();
    tasks.spawn(async move { c.execute(request, out).await });
}

/// The UI's loop on any backend and any event source (the terminal's, or a benchmark's):
/// keys become requests carried out by `control` as tasks, outcomes update the state, and the
/// screen is redrawn at once after a key or an outcome, and at most every [`FRAME_INTERVAL`]
/// for vehicle data; before each frame the app observes the state ([`observe`]). Returns on
/// `q`, when `events` closes, or when `cancel` fires; the requests still running are aborted.
///
/// # Errors
/// The backend's write error.
pub async fn event_loop<B: ratatui::backend::Backend, C: Control>(
    terminal: &mut ratatui::Terminal<B>,
    running: &Running,
    control: C,
    mut events: mpsc::Receiver<Event>,
    cancel: CancellationToken,
) -> Result<(), B::Error> {
    let (out_tx, mut outcomes) = mpsc::channel(64);
    // Every request's task; dropping the set (any way out of the loop) aborts those left.
    let mut tasks = JoinSet::new();
    let mut app = App::default();
    let mut render = RenderState::default();
    let mut state_rx = running.state.clone();
    let mut tick = tokio::time::interval(FRAME_INTERVAL);
    tick.set_missed_tick_behavior(tokio::time::MissedTickBehavior::Skip);
    let mut dirty = true;
    let mut selected = None;
    let mut last_draw = Instant::now()
        .checked_sub(IDLE_REDRAW)
        .unwrap_or_else(Instant::now);
    // The shown vehicle's reboots already answered with a fresh table.
    let mut reboots = RebootsSeen::default();
    // The table names the outputs and holds HOVER_ALT: fetch it at start (and after a reboot).
    app.params.progress = Some(("download".into(), 0, 0));
    spawn_request(&mut tasks, &control, &out_tx, Request::ParamsPull);
    loop {
        let mut now_draw = false;
        tokio::select! {
            () = cancel.cancelled() => return Ok(()),
            // Finished requests leave the set (their outcomes came on `outcomes`).
            Some(_) = tasks.join_next(), if !tasks.is_empty() => {}
            ev = events.recv() => {
                let Some(ev) = ev else { return Ok(()) };
                match ev {
                    Event::Key(k) if k.kind != KeyEventKind::Release => {
                        let state = running.state.borrow().clone();
                        let (links, _, _) = links_and_counters(running);
                        app.replay = is_replay(&app, &state, &links);
                        let reqs = app.on_key(k, &state, crate::tracker::now());
                        sync_selection(&mut app, &state, &control, &mut selected);
                        for req in reqs {
                            spawn_request(&mut tasks, &control, &out_tx, req);
                        }
                        if app.quit {
                            return Ok(());
                        }
                        now_draw = true;
                    }
                    Event::Resize(_, _) => now_draw = true,
                    _ => {}
                }
            }
            o = outcomes.recv() => {
                if let Some(o) = o {
                    app.on_outcome(o);
                    now_draw = true;
                }
            }
            r = state_rx.changed() => {
                if r.is_err() {
                    return Ok(());
                }
                dirty = true;
                let (changed, shown) = {
                    let state = state_rx.borrow_and_update();
                    let changed = sync_selection(&mut app, &state, &control, &mut selected);
                    let shown = app
                        .vehicle(&state)
                        .map(|v| ((v.system_id, v.component_id), v.reboots));
                    (changed, shown)
                };
                let refetch = shown.map(|(key, n)| reboots.update(key, n));
                if changed {
                    // The client was on another vehicle: its table is not this one's.
                    for req in app.vehicle_changed() {
                        spawn_request(&mut tasks, &control, &out_tx, req);
                    }
                } else if refetch == Some(Refetch::AfterReboot) {
                    // A vehicle that rebooted may hold other values now: fetch the table again.
                    app.params.progress = Some(("download after reboot".into(), 0, 0));
                    spawn_request(&mut tasks, &control, &out_tx, Request::ParamsPull);
                }
            }
            _ = tick.tick() => {
                if last_draw.elapsed() >= IDLE_REDRAW {
                    dirty = true;
                }
            }
        }
        // Keys and outcomes draw at once (a person is waiting); vehicle data at most at 30 fps.
        if now_draw || (dirty && last_draw.elapsed() >= FRAME_INTERVAL) {
            draw_running(
                terminal,
                &mut app,
                running,
                &mut render,
                crate::tracker::now(),
            )?;
            last_draw = Instant::now();
            dirty = false;
        }
    }
}
