//! Every view of the terminal UI at the smallest size it supports (80×24) keeps whole column
//! titles and values, and at 200×50 uses the space; a LOST vehicle of a fleet shows no live
//! figures. Whole frames from recorded vehicle states, compared with insta snapshots.

use crate::ui_support::recording::{Recording, app_with_params, heartbeat, hover, key};
use ratatui::crossterm::event::KeyCode;
use vtol_gcs::tui::app::{App, Outcome, View};
use vtol_link::dialect::{self, MavMessage};

const REASON: &str = "LAT_SAT_B: saturation levels need a > b + c + d";

/// A hover, with a refused parameter selected in the table.
fn scene() -> (Recording, App) {
    let rec = hover();
    let mut app = app_with_params();
    app.on_outcome(Outcome::ParamSet {
        name: "LAT_SAT_B".into(),
        result: Err(REASON.into()),
    });
    // Select LAT_SAT_B (the fourth row).
    let state = rec.state.clone();
    app.view = View::Params;
    for _ in 0..3 {
        app.on_key(key(KeyCode::Down), &state, rec.at(20_000));
    }
    (rec, app)
}

/// Every word of `text` is in `frame` (a value wrapped over rows is still whole).
fn has_words(frame: &str, text: &str) -> bool {
    text.split_whitespace().all(|w| frame.contains(w))
}

fn check_view(app: &mut App, rec: &Recording, view: View, size: (u16, u16)) -> String {
    app.view = view;
    let frame = rec.render(app, 20_000, size);
    let want: &[&str] = match view {
        View::Flight => &[
            "right motor   1",
            "left motor    1",
            "left aileron  1",
            "right aileron 1",
            "elevator      1520 µs",
            "Alt     +1.00 m  setpoint   +1.00 m",
            "Vel   +0.00 +0.00 +0.00 m/s (N E D)",
            "Air       - m/s  AoA      -  SSA      -",
            "VTOL  -",
        ],
        View::Charts => &[
            "Roll (°, hover frame)",
            "Pitch (°, hover frame)",
            "Yaw (°, hover frame)",
            "Motors (µs)",
            "setpoint",
        ],
        // The peer whole, wrapped in its column when narrow.
        View::Links => &[
            "side",
            "peer",
            "loss",
            "heard",
            "rx",
            "tx",
            "tcp:127.0.0.1",
            "5760",
        ],
        View::Messages => &[
            "from",
            "message",
            "Hz",
            "LOCAL_POSITION_NED",
            "SERVO_OUTPUT_RAW",
            "vtol tailsitter duorotor",
            "safety armed, custom mode enabled",
        ],
        View::Params => &[
            "name",
            "value",
            "status",
            "REFUSED:",
            "LAT_SAT_B         0.6",
        ],
        View::Fleet => &[
            "sys", "state", "mode", "status", "Hz", "loss%", "heard", "battery", "QHOVER",
        ],
        View::Map => &[" Map ", "no position yet"],
    };
    for w in want {
        assert!(frame.contains(w), "{view:?} at {size:?}: no {w:?}\n{frame}");
    }
    assert!(
        !frame.contains("MavModeFlag") && !frame.contains("MAV_"),
        "{frame}"
    );
    if view == View::Params {
        assert!(has_words(&frame, REASON), "the whole reason\n{frame}");
    }
    frame
}

#[test]
fn every_view_whole_at_80_by_24() {
    let (rec, mut app) = scene();
    for (view, name) in [
        (View::Flight, "flight_80x24"),
        (View::Charts, "charts_80x24"),
        (View::Links, "links_80x24"),
        (View::Messages, "messages_80x24"),
        (View::Params, "params_80x24"),
        (View::Fleet, "fleet_80x24"),
        (View::Map, "map_80x24"),
    ] {
        let frame = check_view(&mut app, &rec, view, (80, 24));
        // Every chart keeps a legend: in its title when ratatui's would not fit.
        if view == View::Charts {
            assert!(
                frame.contains("Motors (µs): right motor left motor"),
                "{frame}"
            );
            assert!(frame.contains("L ail R ail elev"), "{frame}");
            assert!(frame.contains("alt N E ··· setpoint"), "{frame}");
        }
        insta::assert_snapshot!(name, frame);
    }
}

#[test]
fn every_view_uses_the_space_at_200_by_50() {
    let (rec, mut app) = scene();
    for (view, name) in [
        (View::Flight, "flight_200x50"),
        (View::Charts, "charts_200x50"),
        (View::Links, "links_200x50"),
        (View::Messages, "messages_200x50"),
        (View::Params, "params_200x50"),
        (View::Fleet, "fleet_200x50"),
        (View::Map, "map_200x50"),
    ] {
        let frame = check_view(&mut app, &rec, view, (200, 50));
        let wide: &[&str] = match view {
            // A column of charts beside the instruments.
            View::Flight => &[
                "Attitude (°, hover frame): roll pitch yaw",
                "Position (m): alt north east",
            ],
            View::Charts => &["left aileron right aileron elevator", "alt north east"],
            View::Links => &["rate Hz", "dropped", "bad crc"],
            View::Messages => &["Fields"],
            // The editor beside the table, with the selected row's whole status.
            View::Params => &["refused: LAT_SAT_B", "idle"],
            View::Fleet => &["Fleet: 1 vehicle, 0 lost"],
            View::Map => &["H home"],
        };
        for w in wide {
            assert!(frame.contains(w), "{view:?}: no {w:?}\n{frame}");
        }
        insta::assert_snapshot!(name, frame);
    }
}

/// In a fleet, a vehicle that fell silent shows LOST and no live figure: no rate, no running
/// flight timer, no battery or air data from before, its attitude and position marked stale.
#[test]
fn a_lost_fleet_vehicle_shows_no_live_numbers() {
    let mut rec = hover();
    // Vehicle 2 flies until 12 s with a battery report, then falls silent.
    for s in 0..12u64 {
        rec.feed_from(2, s * 1000, &heartbeat(19, true));
        rec.feed_from(
            2,
            s * 1000 + 10,
            &MavMessage::ATTITUDE(dialect::ATTITUDE_DATA {
                time_boot_ms: (s * 1000) as u32,
                roll: 0.1,
                ..Default::default()
            }),
        );
        rec.feed_from(
            2,
            s * 1000 + 20,
            &MavMessage::VFR_HUD(dialect::VFR_HUD_DATA {
                airspeed: 3.5,
                ..Default::default()
            }),
        );
    }
    rec.feed_from(
        2,
        11_500,
        &MavMessage::SYS_STATUS(dialect::SYS_STATUS_DATA {
            voltage_battery: 11_100,
            current_battery: 830,
            battery_remaining: 64,
            ..Default::default()
        }),
    );
    let mut app = app_with_params();
    app.on_key(key(KeyCode::Char('v')), &rec.state.clone(), rec.at(20_000));
    let frame = rec.render(&mut app, 20_000, (80, 24));
    let header = frame.lines().next().unwrap_or_default();
    assert!(header.contains("sys 2"), "{frame}");
    assert!(frame.contains("LINK LOST 9 s"), "{frame}");
    // The flight clock stopped at its last heartbeat (armed at 0 s, last heard at 11 s).
    assert!(header.contains("flight 00:11"), "{frame}");
    assert!(!header.contains("Hz"), "no link rate: {frame}");
    assert!(frame.contains("no live figures"), "{frame}");
    assert!(
        frame.contains("LINK LOST 9 s: last known values"),
        "{frame}"
    );
    for live in ["11.1V", "64%", "air 3.5", "3.5 m/s"] {
        assert!(!frame.contains(live), "{live} still shown:\n{frame}");
    }
    assert!(
        frame.contains("STALE") || frame.contains("stale"),
        "{frame}"
    );
    // In the list it is LOST, without mode or rate.
    assert!(frame.contains(" 2 LOST 9 s"), "{frame}");
    insta::assert_snapshot!(frame);
}

/// The last progress step of a download can arrive after the table (it has a task of its own):
/// a finished download leaves no "download 57/57" over the Params view.
#[test]
fn a_finished_download_leaves_no_progress_shown() {
    let rec = hover();
    let mut app = app_with_params();
    app.view = View::Params;
    let step = |done| Outcome::Progress {
        what: "download".into(),
        done,
        total: 57,
    };
    app.on_outcome(step(30));
    let frame = rec.render(&mut app, 20_000, (80, 24));
    assert!(frame.contains("download 30/57"), "{frame}");
    app.on_outcome(Outcome::Params(crate::ui_support::recording::params()));
    app.on_outcome(step(57));
    let frame = rec.render(&mut app, 20_000, (80, 24));
    assert!(!frame.contains("57/57"), "{frame}");
    assert!(app.params.progress.is_none());
}
