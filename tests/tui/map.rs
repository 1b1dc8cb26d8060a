//! The Map view: a mission (take-off, a 200 m box, a loiter circle, a VTOL landing), the track
//! flown, the vehicle with its heading and its target, drawn at 80×24 and 200×50 and compared
//! with insta snapshots; and the same scene built from recorded MAVLink frames in the whole UI.

use crate::ui_support::recording::{Recording, app_with_params, heartbeat, key};
use firmware_sim::nav::globe::{GeoPoint, Origin};
use nalgebra::Vector3;
use ratatui::Terminal;
use ratatui::backend::TestBackend;
use ratatui::crossterm::event::KeyCode;
use vtol_gcs::tui::app::View;
use vtol_gcs::tui::map::{ItemKind, LatLon, MapCamera, MapItem, MapScene, MapVehicle};
use vtol_gcs::tui::view::map::draw_map;
use vtol_link::dialect::{self, MavMessage};

const HOME: LatLon = (-353_632_610, 1_491_652_300);

fn at(north_m: f64, east_m: f64) -> LatLon {
    let o = Origin(GeoPoint {
        lat_e7: HOME.0,
        lon_e7: HOME.1,
        alt_amsl_m: 0.0,
    });
    let p = o.to_global(&Vector3::new(north_m, east_m, 0.0));
    (p.lat_e7, p.lon_e7)
}

fn mission() -> Vec<MapItem> {
    let item = |seq, at, kind| MapItem { seq, at, kind };
    vec![
        item(1, (0, 0), ItemKind::Takeoff),
        item(2, at(200.0, 0.0), ItemKind::Waypoint),
        item(3, at(200.0, 200.0), ItemKind::Waypoint),
        item(4, at(0.0, 200.0), ItemKind::Waypoint),
        item(5, at(-100.0, 100.0), ItemKind::Loiter { radius_m: 50.0 }),
        item(6, at(0.0, 0.0), ItemKind::Land),
    ]
}

/// North from home to the box's first corner, then east along its top, every 5 m.
fn track() -> Vec<LatLon> {
    let north = (0..=40).map(|i| at(f64::from(i) * 5.0, 0.0));
    let east = (1..=24).map(|i| at(200.0, f64::from(i) * 5.0));
    north.chain(east).collect()
}

fn render(scene: &MapScene<'_>, camera: &MapCamera, size: (u16, u16)) -> String {
    let mut terminal = Terminal::new(TestBackend::new(size.0, size.1)).expect("test backend");
    terminal
        .draw(|f| draw_map(f, scene, camera, f.area()))
        .expect("draw");
    format!("{}", terminal.backend())
}

fn scene<'a>(items: &'a [MapItem], track: &'a [LatLon]) -> MapScene<'a> {
    MapScene {
        home: Some(HOME),
        vehicle: Some(MapVehicle {
            at: at(200.0, 120.0),
            heading_deg: Some(90.0),
        }),
        target: Some(at(200.0, 200.0)),
        items,
        current_seq: Some(3),
        track,
    }
}

#[test]
fn the_mission_at_80_by_24() {
    let (items, track) = (mission(), track());
    let camera = MapCamera {
        center: Some(at(50.0, 100.0)),
        follow: false,
        ..MapCamera::default()
    };
    let frame = render(&scene(&items, &track), &camera, (80, 24));
    for w in [
        "H",
        "→",
        "✛",
        "2",
        "3",
        "4",
        "5",
        "L6",
        "100 m",
        "N↑",
        "10 m/cell",
    ] {
        assert!(frame.contains(w), "no {w:?}\n{frame}");
    }
    insta::assert_snapshot!("map_80x24", frame);
}

#[test]
fn the_mission_at_200_by_50() {
    let (items, track) = (mission(), track());
    let camera = MapCamera {
        center: Some(at(50.0, 100.0)),
        follow: false,
        zoom: 3,
        ..MapCamera::default()
    };
    let frame = render(&scene(&items, &track), &camera, (200, 50));
    for w in [
        "H home",
        "100 m",
        "5 m/cell",
        "f: follow",
        "L6",
        "▶   3 waypoint              80 m",
        "5 loiter    r 50 m",
        "target  80 m",
        "home    233 m",
    ] {
        assert!(frame.contains(w), "no {w:?}\n{frame}");
    }
    insta::assert_snapshot!("map_200x50", frame);
}

#[test]
fn without_a_position_the_map_says_so() {
    let frame = render(&MapScene::default(), &MapCamera::default(), (80, 24));
    assert!(frame.contains("no position yet"), "{frame}");
}

/// The whole UI: the vehicle, home, target and current item from the tracker, the track from
/// its history; the map follows the vehicle, `-` zooms out, an arrow pans, `f` follows again.
#[test]
fn the_map_view_follows_the_recorded_vehicle() {
    let mut rec = Recording::new();
    rec.feed(0, &heartbeat(10, true));
    let mut home = dialect::HOME_POSITION_DATA::default();
    (home.latitude, home.longitude) = HOME;
    rec.feed(10, &MavMessage::HOME_POSITION(home));
    for (i, p) in track().into_iter().enumerate() {
        let mut g = dialect::GLOBAL_POSITION_INT_DATA::default();
        (g.lat, g.lon, g.hdg) = (p.0, p.1, if i <= 40 { 0 } else { 9000 });
        let ms = 100 + 100 * i as u64;
        if ms.is_multiple_of(1000) {
            rec.feed(ms, &heartbeat(10, true));
        }
        rec.feed(ms, &MavMessage::GLOBAL_POSITION_INT(g));
    }
    let mut t = dialect::POSITION_TARGET_GLOBAL_INT_DATA::default();
    (t.lat_int, t.lon_int) = at(200.0, 200.0);
    rec.feed(7_000, &MavMessage::POSITION_TARGET_GLOBAL_INT(t));
    let m = dialect::MISSION_CURRENT_DATA {
        seq: 3,
        ..Default::default()
    };
    rec.feed(7_000, &MavMessage::MISSION_CURRENT(m));
    rec.feed(7_000, &heartbeat(10, true));

    let mut app = app_with_params();
    app.map.items = mission();
    app.view = View::Map;
    let state = rec.state.clone();
    let frame = rec.render(&mut app, 7_000, (80, 24));
    assert!(frame.contains(" Map "), "{frame}");
    assert!(
        frame.contains("→") && frame.contains("following"),
        "{frame}"
    );
    let vehicle = at(200.0, 120.0);
    assert_eq!(app.map.camera.shown, Some(vehicle));
    insta::assert_snapshot!("map_view_following_80x24", frame);

    app.on_key(key(KeyCode::Char('-')), &state, rec.at(7_000));
    assert_eq!(app.map.camera.metres_per_cell(), 20.0);
    app.on_key(key(KeyCode::Left), &state, rec.at(7_000));
    let frame = rec.render(&mut app, 7_000, (80, 24));
    assert!(frame.contains("f: follow"), "{frame}");
    assert_ne!(app.map.camera.shown, Some(vehicle));
    app.on_key(key(KeyCode::Char('f')), &state, rec.at(7_000));
    rec.render(&mut app, 7_000, (80, 24));
    assert_eq!(app.map.camera.shown, Some(vehicle));
}

/// The track reads the history's GLOBAL_POSITION_INT frames once each and keeps them after the
/// history has let them go (it keeps 120 s).
#[test]
fn the_track_outlives_the_history() {
    use vtol_gcs::tui::view::map::TrackCache;
    use vtol_link::{ComponentId, SystemId};
    let mut rec = Recording::new();
    let mut track = TrackCache::default();
    let fix = |s: u64| {
        let mut g = dialect::GLOBAL_POSITION_INT_DATA::default();
        (g.lat, g.lon) = at(s as f64, 0.0);
        MavMessage::GLOBAL_POSITION_INT(g)
    };
    for s in 0..250 {
        rec.feed(s * 1000, &heartbeat(10, true));
        rec.feed(s * 1000, &fix(s));
        if s % 100 == 99 {
            track.update(&rec.history, SystemId(1), ComponentId(1));
        }
    }
    let points = track.update(&rec.history, SystemId(1), ComponentId(1));
    assert_eq!(points.len(), 250);
    assert_eq!(points[0], at(0.0, 0.0));
    assert_eq!(points[249], at(249.0, 0.0));
    let oldest = rec.history.frames[&(SystemId(1), ComponentId(1), 33)]
        .oldest_t_s()
        .expect("frames");
    assert!(
        oldest > 100.0,
        "the history let the first frames go: {oldest}"
    );
    // Another vehicle starts its own track.
    assert!(
        track
            .update(&rec.history, SystemId(2), ComponentId(1))
            .is_empty()
    );
}

/// Entering the Map view asks for the vehicle's mission once; what comes back is drawn, home
/// and items without a place left out, a take-off drawn at home; `r` asks again.
#[test]
fn the_map_view_downloads_the_mission_and_draws_its_items() {
    use vtol_gcs::mission::Item;
    use vtol_gcs::tui::app::{Outcome, Request};
    use vtol_link::dialect::{MavCmd, MavFrame};
    let mut app = vtol_gcs::tui::app::App::default();
    let state = vtol_gcs::tracker::VehicleState::default();
    let now = std::time::Instant::now();
    let tab = ratatui::crossterm::event::KeyEvent::from(ratatui::crossterm::event::KeyCode::Tab);
    let mut asked = Vec::new();
    while app.view != View::Map {
        asked.extend(app.on_key(tab, &state, now));
    }
    assert_eq!(asked, vec![Request::MissionDownload]);
    // Round the seven views once more: asked only once.
    let mut again = Vec::new();
    for _ in 0..7 {
        again.extend(app.on_key(tab, &state, now));
    }
    assert!(again.is_empty(), "{again:?}");
    let item = |command: MavCmd, x: f64, y: f64| Item {
        frame: MavFrame::MAV_FRAME_GLOBAL_RELATIVE_ALT as u8,
        command: command as u16,
        current: false,
        autocontinue: true,
        params: [0.0; 4],
        x,
        y,
        z: 30.0,
    };
    app.on_outcome(Outcome::Mission(Ok(vec![
        item(MavCmd::MAV_CMD_NAV_WAYPOINT, -35.36, 149.16),
        item(MavCmd::MAV_CMD_NAV_VTOL_TAKEOFF, 0.0, 0.0),
        item(MavCmd::MAV_CMD_NAV_WAYPOINT, -35.361, 149.161),
        item(MavCmd::MAV_CMD_DO_VTOL_TRANSITION, 0.0, 0.0),
        item(MavCmd::MAV_CMD_NAV_LOITER_UNLIM, -35.362, 149.162),
        item(MavCmd::MAV_CMD_NAV_VTOL_LAND, -35.363, 149.163),
    ])));
    let seqs: Vec<u16> = app.map.items.iter().map(|i| i.seq).collect();
    // The take-off at 0, 0 is drawn at home (item 0); the DO_ item is left out.
    assert_eq!(seqs, vec![1, 2, 4, 5]);
    assert_eq!(app.map.items[0].at, (-353_600_000, 1_491_600_000));
    assert_eq!(app.map.items[1].at, (-353_610_000, 1_491_610_000));
    let r =
        ratatui::crossterm::event::KeyEvent::from(ratatui::crossterm::event::KeyCode::Char('r'));
    assert_eq!(app.on_key(r, &state, now), vec![Request::MissionDownload]);
}
