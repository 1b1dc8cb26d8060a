//! The mission's progress in the Flight view, from MISSION_CURRENT, NAV_CONTROLLER_OUTPUT,
//! VFR_HUD and GLOBAL_POSITION_INT fed to the tracker: the current item out of the last, its
//! command, the distance and time to it and the items left, on one line at 80×24 and wider;
//! nothing without a mission outside AUTO, the reason in AUTO; no time when the vehicle stands.

use crate::ui_support::recording::{Recording, app_with_params};
use firmware_sim::nav::globe::{GeoPoint, Origin};
use nalgebra::Vector3;
use vtol_gcs::mission::Item;
use vtol_gcs::tui::app::App;
use vtol_link::dialect::{self, MavMessage};

const HOME: (i32, i32) = (-353_632_610, 1_491_652_300);
const AUTO: u32 = 10;
const QLOITER: u32 = 19;

fn at(north_m: f64, east_m: f64) -> (i32, i32) {
    let o = Origin(GeoPoint {
        lat_e7: HOME.0,
        lon_e7: HOME.1,
        alt_amsl_m: 0.0,
    });
    let p = o.to_global(&Vector3::new(north_m, east_m, 0.0));
    (p.lat_e7, p.lon_e7)
}

fn item(command: u16, place: (i32, i32)) -> Item {
    Item {
        frame: 3,
        command,
        current: false,
        autocontinue: true,
        params: [0.0; 4],
        x: f64::from(place.0) / 1e7,
        y: f64::from(place.1) / 1e7,
        z: 30.0,
    }
}

/// Home, a VTOL take-off, waypoints 2 to 4 on a 200 m box, a VTOL landing at home.
fn mission() -> Vec<Item> {
    vec![
        Item {
            frame: 0,
            ..item(16, HOME)
        },
        item(84, (0, 0)),
        item(16, at(200.0, 0.0)),
        item(16, at(200.0, 200.0)),
        item(16, at(0.0, 200.0)),
        item(85, HOME),
    ]
}

/// What the vehicle streams: how it flies.
struct Flying {
    mode: u32,
    /// MISSION_CURRENT's seq and total (0: a vehicle without the extension).
    current: Option<(u16, u16)>,
    wp_dist: Option<u16>,
    groundspeed: f32,
}

/// Five seconds of flight in `f.mode` at (200 m N, 20 m E), flying east.
fn flight(f: &Flying) -> Recording {
    let mut rec = Recording::new();
    rec.fly_wing(0, 5_000, |_| (f.mode, true, 0.0, 0.0, 1.57, 30.0));
    let (lat, lon) = at(200.0, 20.0);
    for ms in (0..5_000).step_by(200) {
        rec.feed(
            ms,
            &MavMessage::GLOBAL_POSITION_INT(dialect::GLOBAL_POSITION_INT_DATA {
                lat,
                lon,
                vy: (f.groundspeed * 100.0) as i16,
                hdg: 9000,
                ..Default::default()
            }),
        );
        rec.feed(
            ms,
            &MavMessage::VFR_HUD(dialect::VFR_HUD_DATA {
                groundspeed: f.groundspeed,
                airspeed: f.groundspeed,
                ..Default::default()
            }),
        );
        if let Some((seq, total)) = f.current {
            rec.feed(
                ms,
                &MavMessage::MISSION_CURRENT(dialect::MISSION_CURRENT_DATA {
                    seq,
                    total,
                    ..Default::default()
                }),
            );
        }
        if let Some(wp_dist) = f.wp_dist {
            rec.feed(
                ms,
                &MavMessage::NAV_CONTROLLER_OUTPUT(dialect::NAV_CONTROLLER_OUTPUT_DATA {
                    wp_dist,
                    ..Default::default()
                }),
            );
        }
    }
    rec
}

fn app(mission: Option<Vec<Item>>) -> App {
    let mut app = app_with_params();
    app.map.mission = mission;
    app
}

/// The frame's line that holds the mission, trimmed of the panel's borders.
fn mission_row(frame: &str) -> Option<String> {
    frame.lines().find_map(|l| {
        let i = l.find("Mission")?;
        Some(l[i..].trim_end_matches(['"', '│', ' ']).to_owned())
    })
}

#[test]
fn auto_shows_the_current_item_its_distance_time_and_the_items_left() {
    let rec = flight(&Flying {
        mode: AUTO,
        current: Some((3, 5)),
        wp_dist: Some(182),
        groundspeed: 12.1,
    });
    let mut app = app(Some(mission()));
    let frame = rec.render(&mut app, 4_900, (80, 24));
    assert_eq!(
        mission_row(&frame).as_deref(),
        Some("Mission 3/5 WAYPOINT 182 m 15 s, 2 left"),
        "{frame}"
    );
    insta::assert_snapshot!("flight_mission_progress_80x24", frame);
    for size in [(120, 40), (200, 50)] {
        let frame = rec.render(&mut app, 4_900, size);
        assert_eq!(
            mission_row(&frame).as_deref(),
            Some("Mission 3/5 WAYPOINT 182 m 15 s, 2 left"),
            "{size:?}\n{frame}"
        );
    }
}

/// Without NAV_CONTROLLER_OUTPUT, and without MISSION_CURRENT's `total` (MAVLink 1): the
/// distance from the item's place and the count from the downloaded mission.
#[test]
fn the_distance_and_count_come_from_the_downloaded_mission_when_the_vehicle_gives_none() {
    let rec = flight(&Flying {
        mode: AUTO,
        current: Some((3, 0)),
        wp_dist: None,
        groundspeed: 18.0,
    });
    let frame = rec.render(&mut app(Some(mission())), 4_900, (80, 24));
    // 180 m east to (200 N, 200 E) at 18 m/s: 10 s.
    assert_eq!(
        mission_row(&frame).as_deref(),
        Some("Mission 3/5 WAYPOINT 180 m 10 s, 2 left"),
        "{frame}"
    );
    let frame = rec.render(&mut app(None), 4_900, (80, 24));
    assert_eq!(
        mission_row(&frame).as_deref(),
        Some("Mission  - not downloaded (Map view: r)"),
        "{frame}"
    );
}

#[test]
fn standing_still_gives_no_time() {
    let rec = flight(&Flying {
        mode: AUTO,
        current: Some((3, 5)),
        wp_dist: Some(182),
        groundspeed: 0.2,
    });
    let frame = rec.render(&mut app(Some(mission())), 4_900, (80, 24));
    assert_eq!(
        mission_row(&frame).as_deref(),
        Some("Mission 3/5 WAYPOINT 182 m -, 2 left"),
        "{frame}"
    );
}

#[test]
fn without_a_mission_auto_says_so_and_other_modes_say_nothing() {
    let none = |mode| Flying {
        mode,
        current: Some((0, u16::MAX)),
        wp_dist: None,
        groundspeed: 0.0,
    };
    let frame = flight(&none(AUTO)).render(&mut app(None), 4_900, (80, 24));
    assert_eq!(
        mission_row(&frame).as_deref(),
        Some("Mission  - none on the vehicle"),
        "{frame}"
    );
    let frame = flight(&none(QLOITER)).render(&mut app(None), 4_900, (80, 24));
    assert_eq!(mission_row(&frame), None, "{frame}");
    let silent = Flying {
        current: None,
        ..none(AUTO)
    };
    let frame = flight(&silent).render(&mut app(None), 4_900, (80, 24));
    assert_eq!(
        mission_row(&frame).as_deref(),
        Some("Mission  - no MISSION_CURRENT"),
        "{frame}"
    );
}

/// Outside AUTO the vehicle's wp_dist is to another point: the distance is the item's.
#[test]
fn outside_auto_the_distance_is_to_the_item() {
    let rec = flight(&Flying {
        mode: QLOITER,
        current: Some((4, 5)),
        wp_dist: Some(7),
        groundspeed: 0.0,
    });
    let frame = rec.render(&mut app(Some(mission())), 4_900, (80, 24));
    // From (200 N, 20 E) to (0 N, 200 E).
    assert_eq!(
        mission_row(&frame).as_deref(),
        Some("Mission 4/5 WAYPOINT 269 m -, 1 left"),
        "{frame}"
    );
}

/// A long command name gives way on a narrow panel; the numbers stay.
#[test]
fn a_long_name_gives_way_first() {
    use vtol_gcs::tui::progress::{MissionLine, Progress};
    let line = MissionLine::Progress(Progress {
        seq: 12,
        total: Some(15),
        name: Some("RETURN_TO_LAUNCH".into()),
        distance_m: Some(12_345.0),
        speed_m_s: Some(20.0),
    });
    assert_eq!(
        line.text(80),
        "Mission 12/15 RETURN_TO_LAUNCH 12.3 km 10:17, 3 left"
    );
    assert_eq!(line.text(42), "Mission 12/15 12.3 km 10:17, 3 left");
}
