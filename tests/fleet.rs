//! Several vehicles in one daemon: a fleet of three real twins (`firmware_sim::shell::fleet`) behind
//! one TCP link into the daemon, the terminal UI switching between them and commanding only
//! the selected one; the tracker keeping them apart; a system id claimed by two vehicle links
//! reported as a conflict and never merged; and a snapshot of the UI with three vehicles.

mod common;
mod ui_support;

use std::sync::atomic::Ordering;
use std::time::{Duration, Instant};

use common::{logged_router, read_until, stream_link, wait_links};
use ratatui::Terminal;
use ratatui::backend::TestBackend;
use ratatui::crossterm::event::{Event, KeyCode, KeyEvent, KeyModifiers};
use tokio::io::{AsyncWriteExt, DuplexStream};
use tokio::sync::mpsc;
use tokio_util::sync::CancellationToken;
use ui_support::recording::{draw_snapshot, tailsitter_heartbeat};
use vtol_gcs::config::{Config, VehicleSource};
use vtol_gcs::daemon;
use vtol_gcs::daemon::Routing;
use vtol_gcs::links::{Side, SysidConflict};
use vtol_gcs::tlog::TlogReader;
use vtol_gcs::tracker::{History, VehicleState};
use vtol_gcs::tui::app::App;
use vtol_gcs::tui::client_control::ClientControl;
use vtol_gcs::tui::view::{self, RouterCounters, Snapshot};
use vtol_link::dialect::{self, MavAutopilot, MavMessage, MavState};
use vtol_link::{ComponentId, Frame, LinkId, LinkOptions, LinkUrl, SystemId, spawn_endpoint};

/// A tailsitter's heartbeat from a generic autopilot, standing by even when armed.
fn heartbeat(mode: u32, armed: bool) -> MavMessage {
    tailsitter_heartbeat(
        mode,
        armed,
        MavAutopilot::MAV_AUTOPILOT_GENERIC,
        MavState::MAV_STATE_STANDBY,
    )
}

/// A heartbeat of system `sys` (component 1), framed with sequence number `seq`.
fn beat(sys: u8, seq: u8, mode: u32, armed: bool) -> Frame {
    Frame::encode_v2(SystemId(sys), ComponentId(1), seq, &heartbeat(mode, armed))
}

fn key(c: char) -> Event {
    Event::Key(KeyEvent::new(KeyCode::Char(c), KeyModifiers::NONE))
}

fn ids(s: u8) -> (SystemId, ComponentId) {
    (SystemId(s), ComponentId(1))
}

#[test]
fn the_tracker_keeps_vehicles_on_one_link_apart() {
    let t0 = Instant::now();
    let mut s = VehicleState::new(t0);
    let link = LinkId(1);
    // Three vehicles interleaved on one link; vehicle 3 loses one frame in four.
    for n in 0u8..40 {
        for sys in 1..=3u8 {
            if sys == 3 && n % 4 == 3 {
                continue;
            }
            let f = beat(sys, n, 17 + u32::from(sys), sys == 2);
            s.apply(
                link,
                Side::Vehicle,
                &f,
                t0 + Duration::from_millis(u64::from(n) * 50),
            );
        }
    }
    let now = t0 + Duration::from_secs(2);
    assert_eq!(s.vehicles.len(), 3);
    let armed: Vec<_> = s
        .vehicles
        .values()
        .filter(|v| v.armed)
        .map(|v| v.system_id)
        .collect();
    assert_eq!(armed, [SystemId(2)]);
    assert_eq!(s.vehicles[&ids(1)].mode_name(), "QHOVER");
    assert_eq!(s.vehicles[&ids(3)].mode_name(), "QLAND");
    assert_eq!(s.vehicles[&ids(1)].lost, 0);
    assert_eq!(s.vehicles[&ids(2)].lost, 0);
    assert_eq!(s.vehicles[&ids(3)].lost, 9);
    assert!(s.vehicles[&ids(3)].window.loss_pct(now) > 20.0);
    assert!(s.vehicles[&ids(1)].window.loss_pct(now) < 1e-9);
    assert!(s.vehicles.values().all(|v| v.link == link));
}

/// Writes a heartbeat of system `sys` (custom mode `mode`, `armed` or not) into `end`.
async fn send_heartbeat(end: &mut DuplexStream, sys: u8, seq: u8, mode: u32, armed: bool) {
    end.write_all(beat(sys, seq, mode, armed).as_bytes())
        .await
        .unwrap();
}

#[tokio::test]
async fn a_system_id_claimed_by_two_vehicle_links_is_a_conflict_never_merged() {
    let cancel = CancellationToken::new();
    let (router, handle) = Routing::new(None, None);
    let (mut a, a_id, a_task) = stream_link(&router, Side::Vehicle, "vehicle a", &cancel);
    let (mut b, b_id, b_task) = stream_link(&router, Side::Vehicle, "vehicle b", &cancel);
    let (mut client, _, client_task) = stream_link(&router, Side::Client, "client", &cancel);
    let mut links = handle.links.clone();
    wait_links(&mut links, 3, "three links up").await;

    // A is system 1 (QHOVER); B claims system 1 too (QLAND), and is also system 2.
    send_heartbeat(&mut a, 1, 0, 18, false).await;
    let got = read_until(&mut client, Duration::from_secs(5), |f| !f.is_empty()).await;
    assert_eq!(got.len(), 1, "A's heartbeat reaches the client");
    let mut conflicts = handle.conflicts.clone();
    send_heartbeat(&mut b, 1, 0, 20, true).await;
    send_heartbeat(&mut b, 2, 0, 17, false).await;
    let seen = tokio::time::timeout(
        Duration::from_secs(5),
        conflicts.wait_for(|c| !c.is_empty()),
    )
    .await
    .expect("conflict reported")
    .expect("router running")
    .clone();
    assert_eq!(
        seen,
        [SysidConflict {
            system: SystemId(1),
            owner: a_id,
            claimant: b_id
        }]
    );
    // Only B's system 2 arrives: its system 1 frames go nowhere.
    let got = read_until(&mut client, Duration::from_secs(5), |f| !f.is_empty()).await;
    assert_eq!(got.len(), 1);
    assert_eq!(got[0].system_id(), 2);
    assert!(
        handle
            .stats
            .sysid_conflicts
            .load(std::sync::atomic::Ordering::Relaxed)
            >= 1
    );

    // Vehicles do not hear each other's broadcasts (a fleet's telemetry would flood every
    // vehicle's radio), but a frame one addresses to the other gets there.
    let got = read_until(&mut a, Duration::from_millis(300), |f| !f.is_empty()).await;
    assert!(got.is_empty(), "B's broadcasts reached A: {got:?}");
    let to_a = MavMessage::COMMAND_LONG(dialect::COMMAND_LONG_DATA {
        target_system: 1,
        target_component: 1,
        command: dialect::MavCmd::MAV_CMD_REQUEST_MESSAGE,
        param1: 0.0,
        ..Default::default()
    });
    b.write_all(
        Frame::encode_v2(vtol_link::SystemId(2), vtol_link::ComponentId(1), 1, &to_a).as_bytes(),
    )
    .await
    .unwrap();
    let got = read_until(&mut a, Duration::from_secs(5), |f| !f.is_empty()).await;
    assert_eq!(got.len(), 1, "B's command for system 1 reaches A");
    assert_eq!(got[0].system_id(), 2);

    // A goes away: the dispute ends and B may now speak as system 1.
    drop(a);
    tokio::time::timeout(Duration::from_secs(5), conflicts.wait_for(Vec::is_empty))
        .await
        .expect("conflict cleared")
        .expect("router running");
    send_heartbeat(&mut b, 1, 1, 20, true).await;
    let got = read_until(&mut client, Duration::from_secs(5), |f| !f.is_empty()).await;
    assert_eq!(got.len(), 1);
    assert_eq!(got[0].system_id(), 1);
    cancel.cancel();
    for task in [a_task, b_task, client_task] {
        let _ = task.await;
    }
    router.close();
}

/// A vehicle whose process restarts on a new source port of a `udpin` vehicle endpoint is the
/// same vehicle: the endpoint follows its new address at once, and nothing it sends after its
/// first frame is lost, to the clients or to the tlog. A vehicle on another endpoint claiming
/// the same system id is still a conflict: its frames are logged and go nowhere else.
#[tokio::test]
async fn a_vehicle_back_from_a_new_port_is_followed_and_a_second_claimant_is_logged_not_merged() {
    let (_dir, tlog_path, router, handle) = logged_router();
    let cancel = CancellationToken::new();
    // As the daemon opens its vehicle endpoints.
    let opts = LinkOptions {
        udp_follow_system: true,
        ..LinkOptions::default()
    };
    let url: LinkUrl = "udpin:127.0.0.1:0".parse().unwrap();
    let vehicles = spawn_endpoint(
        &url,
        router.events(Side::Vehicle),
        opts.clone(),
        cancel.clone(),
    )
    .await
    .unwrap();
    let to = vehicles.local_addr().unwrap();
    let elsewhere = spawn_endpoint(&url, router.events(Side::Vehicle), opts, cancel.clone())
        .await
        .unwrap();
    let (mut client, _, client_task) = stream_link(&router, Side::Client, "client", &cancel);
    let mut links = handle.links.clone();
    wait_links(&mut links, 1, "the client's link up").await;

    // The vehicle's process sends ten frames, stops, and its next process, up a moment later
    // (a restart is never instant: the model of it here is a pause of 0.6 s, past
    // FOLLOW_AFTER_SILENCE), sends ten more from another port.
    let first = std::net::UdpSocket::bind("127.0.0.1:0").unwrap();
    for seq in 0..10 {
        first
            .send_to(beat(1, seq, 17, false).as_bytes(), to)
            .unwrap();
    }
    drop(first);
    tokio::time::sleep(Duration::from_millis(600)).await;
    let second = std::net::UdpSocket::bind("127.0.0.1:0").unwrap();
    for seq in 10..20 {
        second
            .send_to(beat(1, seq, 17, false).as_bytes(), to)
            .unwrap();
    }
    let got = read_until(&mut client, Duration::from_secs(5), |f| f.len() >= 20).await;
    let seqs: Vec<u8> = got.iter().map(Frame::seq).collect();
    assert_eq!(
        seqs,
        (0..20).collect::<Vec<u8>>(),
        "frames lost across the restart"
    );
    assert_eq!(handle.stats.sysid_conflicts.load(Ordering::Relaxed), 0);
    // The old address's link went down: one vehicle link and the client's.
    wait_links(&mut links, 2, "the old peer's link down").await;

    // Another vehicle, on the other endpoint, sends as system 1: a conflict, not merged.
    let claimant = std::net::UdpSocket::bind("127.0.0.1:0").unwrap();
    claimant
        .send_to(
            beat(1, 100, 17, false).as_bytes(),
            elsewhere.local_addr().unwrap(),
        )
        .unwrap();
    let mut conflicts = handle.conflicts.clone();
    tokio::time::timeout(
        Duration::from_secs(5),
        conflicts.wait_for(|c| !c.is_empty()),
    )
    .await
    .expect("the conflict reported")
    .expect("router running");
    second
        .send_to(beat(1, 20, 17, false).as_bytes(), to)
        .unwrap();
    let got = read_until(&mut client, Duration::from_secs(5), |f| !f.is_empty()).await;
    let seqs: Vec<u8> = got.iter().map(Frame::seq).collect();
    assert_eq!(seqs, [20], "the claimant's frame reached the client");

    cancel.cancel();
    client_task.await.unwrap();
    vehicles.join().await;
    elsewhere.join().await;
    router.close();
    let logged: Vec<u8> = TlogReader::open(&tlog_path)
        .unwrap()
        .map(|(_, f)| f.seq())
        .collect();
    let mut want: Vec<u8> = (0..=20).collect();
    want.insert(20, 100);
    assert_eq!(
        logged, want,
        "every frame received is logged, the disputed one too"
    );
}

fn render(app: &mut App, state: &VehicleState, history: &History, now: Instant) -> String {
    render_with_links(app, state, history, now, Vec::new())
}

fn render_with_links(
    app: &mut App,
    state: &VehicleState,
    history: &History,
    now: Instant,
    links: Vec<view::LinkRow>,
) -> String {
    let snap = Snapshot {
        now,
        state,
        history,
        links,
        router: RouterCounters::default(),
        tlog: None,
        serving: vec!["tcpin:127.0.0.1:5770".into()],
    };
    draw_snapshot(app, &snap, (110, 30))
}

#[test]
fn ui_lists_three_vehicles_and_switches() {
    let t0 = Instant::now();
    let mut state = VehicleState::new(t0);
    let history = History::new(t0);
    // 1 hovers, 2 is armed in QLOITER, 3 fell silent 6 s ago.
    for n in 0u8..10 {
        let t = t0 + Duration::from_secs(u64::from(n));
        state.apply(LinkId(1), Side::Vehicle, &beat(1, n, 18, true), t);
        state.apply(LinkId(1), Side::Vehicle, &beat(2, n, 19, true), t);
        if n < 4 {
            state.apply(LinkId(1), Side::Vehicle, &beat(3, n, 17, false), t);
        }
    }
    let now = t0 + Duration::from_millis(9_500);
    let mut app = App::default();
    insta::assert_snapshot!(
        "fleet_three_vehicles",
        render(&mut app, &state, &history, now)
    );
    let press = |app: &mut App, c: char| {
        let Event::Key(k) = key(c) else {
            unreachable!()
        };
        app.on_key(k, &state, now)
    };
    let reqs = press(&mut app, 'v');
    assert_eq!(
        reqs,
        [vtol_gcs::tui::app::Request::ParamsPull],
        "the new vehicle's table"
    );
    assert_eq!(app.selected, Some(ids(2)));
    insta::assert_snapshot!(
        "fleet_second_selected",
        render(&mut app, &state, &history, now)
    );
    press(&mut app, 'v');
    assert_eq!(app.selected, Some(ids(3)));
    press(&mut app, 'v');
    assert_eq!(app.selected, Some(ids(1)), "wraps around");
    press(&mut app, 'V');
    assert_eq!(app.selected, Some(ids(3)));
}

#[test]
fn a_fleet_wider_than_the_screen_wraps_and_scrolls_to_the_selected_vehicle() {
    let t0 = Instant::now();
    let mut state = VehicleState::new(t0);
    let history = History::new(t0);
    for sys in 1u8..=20 {
        state.apply(
            LinkId(u32::from(sys)),
            Side::Vehicle,
            &beat(sys, 0, 17, false),
            t0,
        );
    }
    let mut app = App::default();
    let screen = render(&mut app, &state, &history, t0);
    let lines: Vec<&str> = screen.lines().collect();
    // The rows under the two header lines hold the list.
    let list: Vec<&str> = lines
        .iter()
        .copied()
        .filter(|l| l.contains("disarmed") && l.contains(" Hz "))
        .collect();
    assert_eq!(list.len(), 3, "three rows of vehicles:\n{screen}");
    assert!(list[0].contains("vehicles (v/V)  1 QSTABILIZE"), "{screen}");
    assert!(list[2].contains("more"), "the rest counted:\n{screen}");
    assert!(!screen.contains(" 20 QSTABILIZE"), "{screen}");
    // Select the last one: the list scrolls to show it, and counts what is before.
    let Event::Key(k) = key('V') else {
        unreachable!()
    };
    app.on_key(k, &state, t0);
    assert_eq!(app.selected, Some(ids(20)));
    let screen = render(&mut app, &state, &history, t0);
    assert!(screen.contains(" 20 QSTABILIZE disarmed"), "{screen}");
    let first = screen
        .lines()
        .find(|l| l.contains("vehicles (v/V)"))
        .unwrap();
    assert!(first.contains("vehicles (v/V) +"), "{screen}");

    // Twenty vehicle links: the header gives the shown vehicle's link health only.
    let links = (1u32..=20)
        .map(|id| view::LinkRow {
            id: LinkId(id),
            side: Side::Vehicle,
            peer: format!("zenoh test/v{id}"),
            own: false,
            stats: vtol_link::LinkStatsSnapshot::default(),
            policy: None,
        })
        .collect();
    let screen = render_with_links(&mut app, &state, &history, t0, links);
    let header = screen.lines().next().unwrap();
    assert_eq!(header.matches("% loss").count(), 1, "{screen}");
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn three_twins_one_daemon_the_ui_commands_the_selected_vehicle() {
    let cancel = CancellationToken::new();
    let mut fleet_config = firmware_sim::shell::serve::ServeConfig {
        listen: vec!["tcpin:127.0.0.1:0".parse().unwrap()],
        ..Default::default()
    };
    // Ready to arm at once, as `firmware-sim serve` starts.
    fleet_config.endpoint.vehicle.calibrated = true;
    let fleet = firmware_sim::shell::fleet::Fleet::start(fleet_config, 3, cancel.clone())
        .await
        .expect("fleet starts");
    let port = fleet.bound()[0].local_addr.expect("bound").port();
    let config = Config {
        serve: Vec::new(),
        log_dir: None,
        vehicle: VehicleSource::Url(format!("tcp:127.0.0.1:{port}").parse().unwrap()),
        ..Config::default()
    };
    let mut tasks = tokio::task::JoinSet::new();
    let running = daemon::start(&config, &cancel, &mut tasks)
        .await
        .expect("daemon starts");
    let mut rx = running.state.clone();
    tokio::time::timeout(
        Duration::from_secs(10),
        rx.wait_for(|s| s.vehicles.len() == 3),
    )
    .await
    .expect("three vehicles heard")
    .expect("tracker running");
    let keys: Vec<_> = running.state.borrow().vehicles.keys().copied().collect();
    assert_eq!(keys, [ids(1), ids(2), ids(3)]);

    // The UI's own loop on a test terminal: `v` selects vehicle 2, `a` `y` arms it.
    let control = ClientControl::new(running.client.clone());
    let mut terminal = Terminal::new(TestBackend::new(110, 30)).expect("test backend");
    let (events, events_rx) = mpsc::channel(16);
    let ui_cancel = cancel.child_token();
    let ui = vtol_gcs::tui::event_loop(&mut terminal, &running, control, events_rx, ui_cancel);
    let driver = async {
        for c in ['v', 'a', 'y'] {
            events.send(key(c)).await.unwrap();
        }
        let mut rx = running.state.clone();
        let armed = tokio::time::timeout(
            Duration::from_secs(10),
            rx.wait_for(|s| s.vehicles.get(&ids(2)).is_some_and(|v| v.armed)),
        )
        .await;
        let armed_at = armed
            .ok()
            .and_then(Result::ok)
            .map(|s| s.vehicles[&ids(2)].last_heartbeat);
        let result = match armed_at {
            Some(armed_at) => {
                // A heartbeat from each of the others after that: still disarmed.
                tokio::time::timeout(
                    Duration::from_secs(10),
                    rx.wait_for(|s| s.vehicles.values().all(|v| v.last_heartbeat > armed_at)),
                )
                .await
                .ok()
                .and_then(Result::ok)
                .map(|s| {
                    s.vehicles
                        .values()
                        .filter(|v| v.armed)
                        .map(|v| v.system_id)
                        .collect::<Vec<_>>()
                })
            }
            None => None,
        };
        events.send(key('q')).await.unwrap();
        result
    };
    let (r, armed) = tokio::join!(ui, driver);
    r.expect("ui ran");
    let screen = format!("{}", terminal.backend());
    assert_eq!(
        armed,
        Some(vec![SystemId(2)]),
        "only the selected vehicle armed; screen:\n{screen}"
    );
    assert_eq!(
        running.client.target(),
        Some((SystemId(2), ComponentId(1))),
        "the client commands vehicle 2"
    );
    assert!(screen.contains("vehicles (v/V)"), "{screen}");
    cancel.cancel();
    while tasks.join_next().await.is_some() {}
    fleet.join().await;
}
