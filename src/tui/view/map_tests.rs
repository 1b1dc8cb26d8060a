//! Projection, camera and track tests of the Map view.

use super::*;
use crate::tui::map::{MapItem, MapState, MapVehicle, PAN_CELLS, ZOOMS_M, origin};
use nalgebra::Vector3;

const HOME: LatLon = (-353_632_610, 1_491_652_300);

fn at(north_m: f64, east_m: f64) -> LatLon {
    let p = origin(HOME).to_global(&Vector3::new(north_m, east_m, 0.0));
    (p.lat_e7, p.lon_e7)
}

#[test]
fn projection_is_metres_east_and_north_of_the_reference() {
    let (e, n) = east_north_m(HOME, at(100.0, -50.0));
    assert!(
        (e + 50.0).abs() < 0.05 && (n - 100.0).abs() < 0.05,
        "{e} {n}"
    );
    assert_eq!(east_north_m(HOME, HOME), (0.0, 0.0));
}

#[test]
fn zoom_stays_within_its_levels() {
    let mut c = MapCamera::default();
    assert_eq!(c.metres_per_cell(), 10.0);
    for _ in 0..20 {
        c.zoom_in();
    }
    assert_eq!(c.metres_per_cell(), ZOOMS_M[0]);
    for _ in 0..20 {
        c.zoom_out();
    }
    assert_eq!(c.metres_per_cell(), ZOOMS_M[ZOOMS_M.len() - 1]);
}

#[test]
fn the_camera_follows_until_panned_and_again_on_f() {
    let items = [MapItem {
        seq: 1,
        at: at(200.0, 0.0),
        kind: ItemKind::Waypoint,
    }];
    let mut scene = MapScene {
        home: Some(HOME),
        vehicle: Some(MapVehicle {
            at: at(10.0, 20.0),
            heading_deg: Some(90.0),
        }),
        items: &items,
        ..MapScene::default()
    };
    let mut state = MapState::default();
    assert_eq!(state.camera.center_for(&scene), Some(at(10.0, 20.0)));
    // A pan before any frame was drawn has nowhere to start from.
    state.camera.pan(PAN_CELLS, 0.0);
    assert!(state.camera.follow);
    state.camera.shown = state.camera.center_for(&scene);
    state.camera.pan(PAN_CELLS, 0.0);
    assert!(!state.camera.follow);
    let c = state.camera.center_for(&scene).expect("a centre");
    let (e, n) = east_north_m(at(10.0, 20.0), c);
    assert!(e.abs() < 0.05 && (n - 80.0).abs() < 0.05, "{e} {n}");
    // The vehicle moves on; the panned map stays.
    scene.vehicle = Some(MapVehicle {
        at: at(50.0, 50.0),
        heading_deg: None,
    });
    assert_eq!(state.camera.center_for(&scene), Some(c));
    state.camera.follow();
    assert_eq!(state.camera.center_for(&scene), Some(at(50.0, 50.0)));
    // No vehicle: home, then the first placed item.
    scene.vehicle = None;
    assert_eq!(state.camera.center_for(&scene), Some(HOME));
    scene.home = None;
    assert_eq!(state.camera.center_for(&scene), Some(at(200.0, 0.0)));
}

#[test]
fn scale_bar_lengths_are_round() {
    assert_eq!(scale_length_m(195.0), 100.0);
    assert_eq!(scale_length_m(200.0), 200.0);
    assert_eq!(scale_length_m(7.0), 5.0);
    assert_eq!(scale_length_m(0.7), 0.5);
    assert_eq!(metres_text(2000.0), "2 km");
    assert_eq!(heading_arrow(0.0), "↑");
    assert_eq!(heading_arrow(90.0), "→");
    assert_eq!(heading_arrow(-45.0), "↖");
    assert_eq!(heading_arrow(350.0), "↑");
}

#[test]
fn the_track_is_thinned_and_bounded() {
    let mut t = TrackCache::default();
    t.push((0, 0));
    assert!(t.points().is_empty());
    t.push(HOME);
    t.push((HOME.0 + 1, HOME.1));
    assert_eq!(t.points().len(), 1, "a point next to the last is not kept");
    for i in 0..10_000 {
        t.push((HOME.0 + 100 * i, HOME.1));
    }
    assert!(t.points().len() <= MAX_TRACK, "{}", t.points().len());
    assert!(t.points().len() > MAX_TRACK / 2);
    assert_eq!(t.points()[0], HOME);
    assert_eq!(*t.points().last().unwrap(), (HOME.0 + 100 * 9999, HOME.1));
}

#[test]
fn mission_items_take_their_kind_and_loiter_radius_from_the_command() {
    let p = at(10.0, 10.0);
    let kind = |cmd, params| MapItem::from_mission(1, cmd, params, p, 80.0).kind;
    assert_eq!(kind(16, [0.0; 4]), ItemKind::Waypoint);
    assert_eq!(kind(84, [0.0; 4]), ItemKind::Takeoff);
    assert_eq!(kind(85, [0.0; 4]), ItemKind::Land);
    assert_eq!(
        kind(18, [2.0, 0.0, -60.0, 0.0]),
        ItemKind::Loiter { radius_m: 60.0 }
    );
    assert_eq!(kind(17, [0.0; 4]), ItemKind::Loiter { radius_m: 80.0 });
    assert_eq!(
        kind(31, [0.0, 45.0, 0.0, 0.0]),
        ItemKind::Loiter { radius_m: 45.0 }
    );
    // DO_CHANGE_SPEED: not a leg.
    assert_eq!(kind(178, [0.0; 4]), ItemKind::Other);
}
