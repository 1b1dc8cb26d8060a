//! Terminal UI benchmark (prints tables; figures in BENCHMARKS.md):
//!
//! 1. Render cost per frame of each view, 120×40, from a recorded 30 s hover, through the real
//!    crossterm backend writing its escape sequences into a sink: CPU time per frame.
//! 2. The live UI on the embedded twin (daemon in this process) at 50 Hz ATTITUDE and 10 Hz
//!    SERVO_OUTPUT_RAW: the UI's own thread CPU (its event loop on its own thread) as % of one
//!    core, and the rest of the process (twin, router, tracker) separately.
//! 3. Keypress to redrawn screen while 5 000 frames/s arrive on a client link: `?` is sent,
//!    the time until a frame with the help overlay is flushed; p50/p99/max.
//! 4. The Fleet view with 250 vehicles: CPU time per frame at 120×40 and 200×50.
//! 5. The Map view with a mission of 50 items and a track of 3 000 points, following the
//!    vehicle: CPU time per frame at 80×24, 120×40 and 200×50; on the live twin (the same
//!    mission uploaded, the track loaded into the history as two minutes of flight would leave
//!    it, GLOBAL_POSITION_INT at 50 Hz) the UI thread's CPU and keypress to redraw.
//!
//! CPU times come from `/proc` (thread: `schedstat`, ns; process: `stat`, clock ticks), so they
//! are less disturbed by other load than wall time. Run: `cargo bench --bench tui` (`-- map`
//! for one part: `render`, `fleet`, `map` or `live`). Under `cargo test` (no `--bench`
//! argument) it runs a short smoke version.

use std::io::Write;
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use ratatui::Terminal;
use ratatui::backend::CrosstermBackend;
use ratatui::crossterm::event::{Event, KeyCode, KeyEvent, KeyModifiers};
use ratatui::layout::Rect;
use ratatui::{TerminalOptions, Viewport};
use tokio::io::AsyncWriteExt;
use tokio::sync::mpsc;
use tokio_util::sync::CancellationToken;
use vtol_gcs::config::Config;
use vtol_gcs::links::Side;
use vtol_gcs::tracker::{History, VehicleState};
use vtol_gcs::tui::app::{App, Outcome, View};
use vtol_gcs::tui::client_control::ClientControl;
use vtol_gcs::tui::view::{self, RenderState, RouterCounters, Snapshot};
use vtol_link::dialect::{self, MavAutopilot, MavMessage, MavModeFlag, MavState, MavType};
use vtol_link::{Frame, LinkId, LinkUrl};

const W: u16 = 120;
const H: u16 = 40;

/// CPU time of the calling thread, ns.
fn thread_cpu_ns() -> u64 {
    std::fs::read_to_string("/proc/thread-self/schedstat")
        .ok()
        .and_then(|s| s.split_whitespace().next()?.parse().ok())
        .unwrap_or(0)
}

/// CPU time of the whole process, s (utime + stime).
fn process_cpu_s() -> f64 {
    let stat = std::fs::read_to_string("/proc/self/stat").unwrap_or_default();
    // Fields after the command name (which may hold spaces) start after the last ')'.
    let rest = stat.rsplit_once(')').map_or("", |(_, r)| r);
    let f: Vec<&str> = rest.split_whitespace().collect();
    let ticks = |i: usize| f.get(i).and_then(|v| v.parse::<f64>().ok()).unwrap_or(0.0);
    // utime and stime are fields 14 and 15 (1-based); here 0 is field 3.
    (ticks(11) + ticks(12)) / 100.0
}

/// A writer that records when each frame is flushed and whether it drew the help overlay.
#[derive(Clone, Default)]
struct TimedSink {
    pending: Arc<Mutex<Vec<u8>>>,
    flushes: Arc<Mutex<Vec<(Instant, bool)>>>,
    /// Whether a frame drew the mission's last item (`L50`): the Map view has its mission.
    landing_drawn: Arc<std::sync::atomic::AtomicBool>,
}

impl Write for TimedSink {
    fn write(&mut self, buf: &[u8]) -> std::io::Result<usize> {
        if let Ok(mut p) = self.pending.lock() {
            p.extend_from_slice(buf);
        }
        Ok(buf.len())
    }
    fn flush(&mut self) -> std::io::Result<()> {
        let now = Instant::now();
        if let (Ok(mut p), Ok(mut f)) = (self.pending.lock(), self.flushes.lock()) {
            // A draw flushes the frame, then hides the cursor with a flush of its own: count
            // frames, not cursor writes.
            if p.as_slice() != b"\x1b[?25l" && !p.is_empty() {
                let help = p.windows(4).any(|w| w == b"Keys");
                if std::env::var_os("DUMP_MAP").is_some() {
                    let mut f = std::fs::OpenOptions::new()
                        .append(true)
                        .create(true)
                        .open("/tmp/mission-ui-dump.bin")
                        .unwrap();
                    f.write_all(&p).unwrap();
                }
                if p.windows(3).any(|w| w == b"L50") {
                    self.landing_drawn
                        .store(true, std::sync::atomic::Ordering::Relaxed);
                }
                f.push((now, help));
            }
            p.clear();
        }
        Ok(())
    }
}

fn terminal<W2: Write>(w: W2) -> Terminal<CrosstermBackend<W2>> {
    terminal_sized(w, (W, H))
}

fn terminal_sized<W2: Write>(w: W2, (width, height): (u16, u16)) -> Terminal<CrosstermBackend<W2>> {
    Terminal::with_options(
        CrosstermBackend::new(w),
        TerminalOptions {
            viewport: Viewport::Fixed(Rect::new(0, 0, width, height)),
        },
    )
    .expect("terminal")
}

/// Draws `frames` frames of `app` on a `size` terminal, frame `i` at `now_of(i)`: the CPU per
/// frame in µs of this thread and the bytes per frame written to the terminal.
fn draw_cost(
    app: &mut App,
    size: (u16, u16),
    state: &VehicleState,
    history: &History,
    frames: usize,
    now_of: impl Fn(usize) -> Instant,
) -> (f64, usize) {
    let bytes = Arc::new(Mutex::new(0usize));
    let mut term = terminal_sized(CountingSink(Arc::clone(&bytes)), size);
    let mut render = RenderState::default();
    let cpu0 = thread_cpu_ns();
    for i in 0..frames {
        let snap = Snapshot {
            now: now_of(i),
            state,
            history,
            links: Vec::new(),
            router: RouterCounters::default(),
            tlog: None,
            serving: Vec::new(),
        };
        vtol_gcs::tui::observe(app, &snap);
        term.draw(|f| view::draw(f, app, &mut render, &snap))
            .expect("draw");
    }
    let cpu = (thread_cpu_ns() - cpu0) as f64 / frames as f64 / 1000.0;
    (cpu, *bytes.lock().unwrap() / frames)
}

/// 30 s of hover: 50 Hz attitude, 10 Hz outputs and position, 1 Hz heartbeat.
fn recording() -> (Instant, VehicleState, History) {
    let t0 = Instant::now();
    let mut state = VehicleState::new(t0);
    let mut history = History::new(t0);
    let mut seq = 0u8;
    let mut feed = |ms: u64, msg: &MavMessage, state: &mut VehicleState, history: &mut History| {
        let f = Frame::encode_v2(vtol_link::SystemId(1), vtol_link::ComponentId(1), seq, msg);
        seq = seq.wrapping_add(1);
        let now = t0 + Duration::from_millis(ms);
        let d = state.apply(LinkId(1), Side::Vehicle, &f, now);
        history.record(&f, d.as_ref(), now);
    };
    for ms in (0..30_000u64).step_by(20) {
        let t = ms as f64 / 1000.0;
        if ms.is_multiple_of(1000) {
            let hb = MavMessage::HEARTBEAT(dialect::HEARTBEAT_DATA {
                custom_mode: 18,
                mavtype: MavType::MAV_TYPE_VTOL_TAILSITTER_DUOROTOR,
                autopilot: MavAutopilot::MAV_AUTOPILOT_ARDUPILOTMEGA,
                base_mode: MavModeFlag::MAV_MODE_FLAG_CUSTOM_MODE_ENABLED
                    | MavModeFlag::MAV_MODE_FLAG_SAFETY_ARMED,
                system_status: MavState::MAV_STATE_ACTIVE,
                mavlink_version: 3,
            });
            feed(ms, &hb, &mut state, &mut history);
        }
        let att = MavMessage::ATTITUDE(dialect::ATTITUDE_DATA {
            time_boot_ms: ms as u32,
            roll: 0.05 * (t * 2.0).sin() as f32,
            pitch: -0.03 * (t * 1.3).sin() as f32,
            yaw: 0.3,
            rollspeed: 0.1,
            pitchspeed: 0.0,
            yawspeed: 0.0,
        });
        feed(ms, &att, &mut state, &mut history);
        if ms.is_multiple_of(100) {
            let s = MavMessage::SERVO_OUTPUT_RAW(dialect::SERVO_OUTPUT_RAW_DATA {
                servo1_raw: 1600 + (t * 7.0) as u16 % 50,
                servo2_raw: 1590,
                servo3_raw: 1500,
                servo4_raw: 1510,
                servo5_raw: 1490,
                ..Default::default()
            });
            feed(ms, &s, &mut state, &mut history);
            let p = MavMessage::LOCAL_POSITION_NED(dialect::LOCAL_POSITION_NED_DATA {
                z: -1.0 - 0.01 * (t.sin() as f32),
                ..Default::default()
            });
            feed(ms, &p, &mut state, &mut history);
        }
    }
    (t0, state, history)
}

fn render_cost(frames: usize) {
    let (t0, state, history) = recording();
    println!(
        "render cost per frame, {W}x{H}, crossterm backend into a sink, {frames} frames per view"
    );
    println!(
        "{:<10} {:>12} {:>12}",
        "view", "CPU µs/frame", "bytes/frame"
    );
    for v in View::all() {
        let mut app = App::default();
        app.on_outcome(Outcome::Params(vec![("HOVER_ALT".into(), 1.0)]));
        app.view = *v;
        if *v == View::Messages {
            // One chart of three fields from two messages.
            app.messages.charts = vec![vec![
                vtol_gcs::tui::app::SeriesKey {
                    system: vtol_link::SystemId(1),
                    component: vtol_link::ComponentId(1),
                    message: 30,
                    path: "roll".into(),
                },
                vtol_gcs::tui::app::SeriesKey {
                    system: vtol_link::SystemId(1),
                    component: vtol_link::ComponentId(1),
                    message: 30,
                    path: "pitch".into(),
                },
                vtol_gcs::tui::app::SeriesKey {
                    system: vtol_link::SystemId(1),
                    component: vtol_link::ComponentId(1),
                    message: 36,
                    path: "servo1_raw".into(),
                },
            ]];
        }
        // The clock moves a frame (33 ms) each time, so every frame differs like live ones.
        let (cpu, b) = draw_cost(&mut app, (W, H), &state, &history, frames, |i| {
            t0 + Duration::from_millis(29_000 + (i as u64 * 33) % 1000)
        });
        println!("{:<10} {cpu:>12.0} {b:>12}", v.title());
    }
}

/// The Fleet view with 250 vehicles (each heard at 1 Hz for 10 s, a battery report each, every
/// 25th silent for the last 6 s): CPU per frame, 120×40 and 200×50.
fn fleet_render_cost(frames: usize) {
    let t0 = Instant::now();
    let mut state = VehicleState::new(t0);
    let history = History::new(t0);
    for s in 0..10u64 {
        for sys in 1..=250u8 {
            if sys % 25 == 0 && s >= 4 {
                continue;
            }
            let hb = MavMessage::HEARTBEAT(dialect::HEARTBEAT_DATA {
                custom_mode: 19,
                mavtype: MavType::MAV_TYPE_VTOL_TAILSITTER_DUOROTOR,
                autopilot: MavAutopilot::MAV_AUTOPILOT_ARDUPILOTMEGA,
                base_mode: MavModeFlag::MAV_MODE_FLAG_CUSTOM_MODE_ENABLED,
                system_status: MavState::MAV_STATE_STANDBY,
                mavlink_version: 3,
            });
            let bat = MavMessage::SYS_STATUS(dialect::SYS_STATUS_DATA {
                voltage_battery: 11_100,
                battery_remaining: 64,
                ..Default::default()
            });
            for (k, m) in [hb, bat].iter().enumerate() {
                let f = Frame::encode_v2(
                    vtol_link::SystemId(sys),
                    vtol_link::ComponentId(1),
                    (s * 2 + k as u64) as u8,
                    m,
                );
                state.apply(LinkId(1), Side::Vehicle, &f, t0 + Duration::from_secs(s));
            }
        }
    }
    println!("Fleet view, 250 vehicles, {frames} frames");
    for (w, h) in [(W, H), (200, 50)] {
        let mut app = App {
            view: View::Fleet,
            ..App::default()
        };
        let (cpu, b) = draw_cost(&mut app, (w, h), &state, &history, frames, |i| {
            t0 + Duration::from_millis(9_500 + (i as u64 * 33) % 400)
        });
        println!("{:<10} {cpu:>12.0} {b:>12}", format!("{w}x{h}"));
    }
}

/// The twin's home, 1e-7 degree.
const HOME: (i32, i32) = (-353_632_610, 1_491_652_300);
/// Points of the track (the Map view keeps at most 3 000).
const TRACK_POINTS: usize = 3000;

fn offset(north_m: f64, east_m: f64) -> (i32, i32) {
    let o = firmware_sim::nav::globe::Origin(firmware_sim::nav::globe::GeoPoint {
        lat_e7: HOME.0,
        lon_e7: HOME.1,
        alt_amsl_m: 0.0,
    });
    let p = o.to_global(&nalgebra::Vector3::new(north_m, east_m, 0.0));
    (p.lat_e7, p.lon_e7)
}

/// A mission of home and 50 items around the twin's home: a VTOL take-off, waypoints on a
/// star out to 450 m with a loiter every tenth item, a VTOL landing at home.
fn map_mission() -> Vec<vtol_gcs::mission::Item> {
    let item = |command: u16, at: (i32, i32), radius: f32| vtol_gcs::mission::Item {
        frame: 3,
        command,
        current: false,
        autocontinue: true,
        params: [0.0, 0.0, radius, 0.0],
        x: f64::from(at.0) / 1e7,
        y: f64::from(at.1) / 1e7,
        z: 40.0,
    };
    let mut items = vec![vtol_gcs::mission::Item {
        frame: 0,
        ..item(16, HOME, 0.0)
    }];
    items.push(item(84, (0, 0), 0.0));
    for k in 2..50u32 {
        let a = f64::from(k) * 2.4;
        let r = 150.0 + 300.0 * f64::from(k % 2);
        let at = offset(r * a.cos(), r * a.sin());
        if k % 10 == 0 {
            items.push(item(19, at, 60.0));
        } else {
            items.push(item(16, at, 0.0));
        }
    }
    items.push(item(85, HOME, 0.0));
    items
}

/// The track: a spiral from 150 m to 250 m around home flown at 25 m/s, one point every 20 ms
/// (each 0.5 m from the last, so every one is kept), ending at home; frame `i` at `t(i)`.
fn track_frames(t: impl Fn(usize) -> Instant) -> Vec<(Frame, MavMessage, Instant)> {
    (0..TRACK_POINTS)
        .map(|i| {
            let left = (TRACK_POINTS - 1 - i) as f64;
            let (n, e) = if left == 0.0 {
                (0.0, 0.0)
            } else {
                let r = 150.0 + 100.0 * left / TRACK_POINTS as f64;
                let a = left * 0.5 / r;
                (r * a.cos(), r * a.sin())
            };
            let (lat, lon) = offset(n, e);
            let msg = MavMessage::GLOBAL_POSITION_INT(dialect::GLOBAL_POSITION_INT_DATA {
                lat,
                lon,
                alt: 624_000,
                relative_alt: 40_000,
                vx: 1500,
                vy: 2000,
                hdg: 5300,
                ..Default::default()
            });
            let f = Frame::encode_v2(
                vtol_link::SystemId(1),
                vtol_link::ComponentId(1),
                i as u8,
                &msg,
            );
            (f, msg, t(i))
        })
        .collect()
}

/// The Map view following the vehicle with the 50-item mission and a 3 000-point track: CPU
/// per frame at 80×24, 120×40 and 200×50.
fn map_render_cost(frames: usize) {
    let (t0, mut state, mut history) = recording();
    // The 60 s of track end at 29 s of the hover recording's clock.
    let start = t0 + Duration::from_secs(29);
    for (f, msg, at) in
        track_frames(|i| start - Duration::from_millis(20 * (TRACK_POINTS - i) as u64))
    {
        state.apply(LinkId(1), Side::Vehicle, &f, at);
        history.record(&f, Some(&msg), at);
    }
    let extra = [
        MavMessage::HOME_POSITION(dialect::HOME_POSITION_DATA {
            latitude: HOME.0,
            longitude: HOME.1,
            ..Default::default()
        }),
        MavMessage::MISSION_CURRENT(dialect::MISSION_CURRENT_DATA {
            seq: 10,
            total: 50,
            ..Default::default()
        }),
    ];
    for (k, m) in extra.iter().enumerate() {
        let f = Frame::encode_v2(
            vtol_link::SystemId(1),
            vtol_link::ComponentId(1),
            k as u8,
            m,
        );
        state.apply(LinkId(1), Side::Vehicle, &f, start);
    }
    let mission = map_mission();
    println!(
        "Map view, {} items, {} track points, following, {frames} frames",
        mission.len() - 1,
        TRACK_POINTS
    );
    for (w, h) in [(80, 24), (W, H), (200, 50)] {
        let mut app = App {
            view: View::Map,
            ..App::default()
        };
        app.on_outcome(Outcome::Mission(Ok(mission.clone())));
        let (cpu, b) = draw_cost(&mut app, (w, h), &state, &history, frames, |i| {
            start + Duration::from_millis((i as u64 * 33) % 1000)
        });
        println!("{:<10} {cpu:>12.0} {b:>12}", format!("{w}x{h}"));
    }
}

struct CountingSink(Arc<Mutex<usize>>);

impl Write for CountingSink {
    fn write(&mut self, buf: &[u8]) -> std::io::Result<usize> {
        *self.0.lock().unwrap() += buf.len();
        Ok(buf.len())
    }
    fn flush(&mut self) -> std::io::Result<()> {
        Ok(())
    }
}

/// Frames per second from a client link (a flood of ATTITUDE from system 2), paced per ms.
async fn flood(addr: std::net::SocketAddr, per_s: u32, cancel: CancellationToken) {
    let Ok(mut s) = tokio::net::TcpStream::connect(addr).await else {
        return;
    };
    let msg = MavMessage::ATTITUDE(dialect::ATTITUDE_DATA::default());
    let per_tick = (per_s / 1000).max(1);
    let mut tick = tokio::time::interval(Duration::from_millis(1));
    let mut seq = 0u8;
    let mut buf = Vec::new();
    loop {
        tokio::select! {
            () = cancel.cancelled() => return,
            _ = tick.tick() => {
                buf.clear();
                for _ in 0..per_tick {
                    buf.extend_from_slice(Frame::encode_v2(vtol_link::SystemId(2), vtol_link::ComponentId(1), seq, &msg).as_bytes());
                    seq = seq.wrapping_add(1);
                }
                if s.write_all(&buf).await.is_err() { return; }
            }
        }
    }
}

fn live(seconds: f64, keypresses: usize) {
    let rt = tokio::runtime::Runtime::new().expect("runtime");
    let cancel = CancellationToken::new();
    let mut tasks = tokio::task::JoinSet::new();
    let config = Config {
        serve: vec!["tcpin:127.0.0.1:0".parse::<LinkUrl>().expect("url").into()],
        log_dir: None,
        ..Config::default()
    };
    let running = rt.block_on(async {
        let r = vtol_gcs::daemon::start(&config, &cancel, &mut tasks)
            .await
            .expect("daemon");
        r.client
            .wait_target(Duration::from_secs(15))
            .await
            .expect("vehicle");
        for (name, hz) in [("SR0_EXTRA1", 50.0), ("SR0_RC_CHAN", 10.0)] {
            r.client.param_set(name, hz).await.expect("stream rate");
        }
        r
    });
    let map_setup = || {
        rt.block_on(async {
            let c = &running.client;
            c.param_set("SR0_POSITION", 50.0)
                .await
                .expect("stream rate");
            let done = c
                .mission_upload(&map_mission(), vtol_gcs::mission::Kind::Mission, |_, _| {})
                .await
                .expect("mission upload");
            assert!(
                matches!(
                    done,
                    vtol_gcs::client::mission::UploadOutcome::Acked {
                        result: dialect::MavMissionResult::MAV_MISSION_ACCEPTED,
                        ..
                    }
                ),
                "mission upload: {done:?}"
            );
        });
        // Two minutes of flight's track, ending at home where the twin stands, as the history
        // would hold it.
        let now = Instant::now();
        let mut h = running.history.lock().expect("history");
        for (f, msg, at) in
            track_frames(|i| now - Duration::from_millis(20 * (TRACK_POINTS - i) as u64))
        {
            h.record(&f, Some(&msg), at);
        }
    };
    let serve_addr = running.serving[0].1.expect("bound");
    let control = rt.block_on(async { ClientControl::new(running.client.clone()) });

    // The UI's event loop on its own thread and runtime, so its CPU is its own.
    let run_ui = |view_key: Option<KeyCode>, keys: Option<(usize, f64)>| {
        let sink = TimedSink::default();
        let flushes = Arc::clone(&sink.flushes);
        let landing = Arc::clone(&sink.landing_drawn);
        let (ev_tx, ev_rx) = mpsc::channel(64);
        let ui_cancel = CancellationToken::new();
        let running2 = running.clone();
        let control2 = control.clone();
        let c2 = ui_cancel.clone();
        let ui = std::thread::spawn(move || {
            let rt = tokio::runtime::Builder::new_current_thread()
                .enable_all()
                .build()
                .expect("rt");
            let mut term = terminal(sink);
            let cpu0 = thread_cpu_ns();
            let t0 = Instant::now();
            rt.block_on(vtol_gcs::tui::event_loop(
                &mut term, &running2, control2, ev_rx, c2,
            ))
            .expect("ui");
            (
                (thread_cpu_ns() - cpu0) as f64 / 1e9,
                t0.elapsed().as_secs_f64(),
            )
        });
        let key = |c| Event::Key(KeyEvent::new(c, KeyModifiers::NONE));
        if let Some(k) = view_key {
            ev_tx.blocking_send(key(k)).expect("key");
        }
        if view_key == Some(KeyCode::BackTab) {
            // The Map view has downloaded and drawn its mission before anything is measured.
            let deadline = Instant::now() + Duration::from_secs(30);
            while !landing.load(std::sync::atomic::Ordering::Relaxed) {
                assert!(
                    Instant::now() < deadline,
                    "the Map view never drew the mission"
                );
                std::thread::sleep(Duration::from_millis(10));
            }
        }
        let mut latencies = Vec::new();
        let cpu0 = process_cpu_s();
        let start = Instant::now();
        match keys {
            None => std::thread::sleep(Duration::from_secs_f64(seconds)),
            Some((n, _)) => {
                for _ in 0..n {
                    let sent = Instant::now();
                    ev_tx.blocking_send(key(KeyCode::Char('?'))).expect("key");
                    let shown = loop {
                        let hit = flushes
                            .lock()
                            .unwrap()
                            .iter()
                            .find(|(t, help)| *help && *t >= sent)
                            .map(|(t, _)| *t);
                        if let Some(t) = hit {
                            break t;
                        }
                        std::thread::sleep(Duration::from_micros(200));
                    };
                    latencies.push(shown - sent);
                    ev_tx.blocking_send(key(KeyCode::Esc)).expect("key");
                    // Space the presses like a person typing fast (about 20 a second).
                    std::thread::sleep(Duration::from_millis(50));
                }
            }
        }
        let wall = start.elapsed().as_secs_f64();
        let proc_cpu = process_cpu_s() - cpu0;
        ui_cancel.cancel();
        let (ui_cpu, ui_wall) = ui.join().expect("ui thread");
        let frames = flushes.lock().unwrap().len();
        (
            ui_cpu / ui_wall * 100.0,
            (proc_cpu - ui_cpu).max(0.0) / wall * 100.0,
            frames as f64 / ui_wall,
            latencies,
        )
    };

    println!(
        "\nlive UI on the embedded twin, ATTITUDE 50 Hz + SERVO_OUTPUT_RAW 10 Hz, {seconds:.0} s per view"
    );
    println!(
        "{:<10} {:>14} {:>22} {:>8}",
        "view", "UI CPU % core", "rest of process % core", "fps"
    );
    for (name, k) in [("Flight", None), ("Charts", Some(KeyCode::Tab))] {
        let (ui, rest, fps, _) = run_ui(k, None);
        println!("{name:<10} {ui:>14.2} {rest:>22.2} {fps:>8.1}");
    }
    // The Map view (Shift-Tab from Flight) downloads the mission when shown, and follows the
    // vehicle with GLOBAL_POSITION_INT at 50 Hz.
    map_setup();
    println!("(GLOBAL_POSITION_INT 50 Hz, a 50-item mission, a 3000-point track)");
    let (ui, rest, fps, _) = run_ui(Some(KeyCode::BackTab), None);
    println!("{:<10} {ui:>14.2} {rest:>22.2} {fps:>8.1}", "Map");

    let flood_cancel = CancellationToken::new();
    rt.spawn(flood(serve_addr, 5000, flood_cancel.clone()));
    let frames_in = || {
        running
            .router
            .stats
            .frames_in
            .load(std::sync::atomic::Ordering::Relaxed)
    };
    for (name, view_key) in [("Flight", None), ("Map", Some(KeyCode::BackTab))] {
        let (in0, t_in) = (frames_in(), Instant::now());
        let (ui, rest, fps, mut lat) = run_ui(view_key, Some((keypresses, 0.0)));
        let arrived = (frames_in() - in0) as f64 / t_in.elapsed().as_secs_f64();
        lat.sort();
        let pct =
            |p: f64| lat[((lat.len() as f64 - 1.0) * p).round() as usize].as_secs_f64() * 1000.0;
        println!(
            "\n{name} view: keypress to redrawn screen while 5000 frames/s are sent ({arrived:.0} frames/s reached the router, {} presses)",
            lat.len()
        );
        println!(
            "p50 {:.2} ms  p99 {:.2} ms  max {:.2} ms   (UI CPU {ui:.1} % core, rest {rest:.1} %, {fps:.1} fps)",
            pct(0.5),
            pct(0.99),
            pct(1.0)
        );
    }
    flood_cancel.cancel();
    cancel.cancel();
    rt.block_on(async { while tasks.join_next().await.is_some() {} });
}

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let bench = args.iter().any(|a| a == "--bench");
    // `cargo bench --bench tui -- map` runs one part: render, fleet, map or live.
    let part = args.iter().find(|a| !a.starts_with('-')).cloned();
    let run = |name: &str| part.as_deref().is_none_or(|p| p == name);
    let (frames, seconds, presses) = if bench {
        (2000, 10.0, 300)
    } else {
        (20, 1.0, 10)
    };
    if run("render") {
        render_cost(frames);
    }
    if run("fleet") {
        fleet_render_cost(frames);
    }
    if run("map") {
        map_render_cost(frames);
    }
    if run("live") {
        live(seconds, presses);
    }
}
