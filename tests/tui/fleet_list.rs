//! The vehicle list at 250 vehicles: the Fleet view puts the lost ones first, searches with
//! `/`, scrolls with the arrows and PgUp/PgDn, and Enter shows and commands the vehicle under
//! the cursor. Frames fed to the tracker, whole screens rendered at 80×24 and 200×50.

use std::time::Instant;

use crate::ui_support::recording::{Recording, heartbeat, key};
use ratatui::crossterm::event::KeyCode;
use vtol_gcs::tui::app::{App, Request, View};
use vtol_link::dialect::{self, MavMessage};

/// 250 vehicles heard once a second for 20 s; every 25th fell silent at 12 s, every 7th is
/// armed, 13 has a battery report.
fn fleet() -> Recording {
    let mut rec = Recording::new();
    for s in 0..20u64 {
        for sys in 1..=250u8 {
            if sys % 25 == 0 && s >= 12 {
                continue;
            }
            let mode = if sys % 7 == 0 { 19 } else { 17 };
            rec.feed_from(sys, s * 1000, &heartbeat(mode, sys % 7 == 0));
        }
    }
    rec.feed_from(
        13,
        19_500,
        &MavMessage::SYS_STATUS(dialect::SYS_STATUS_DATA {
            voltage_battery: 11_100,
            battery_remaining: 64,
            ..Default::default()
        }),
    );
    rec
}

fn press(app: &mut App, rec: &Recording, code: KeyCode) -> Vec<Request> {
    app.on_key(key(code), &rec.state, rec.at(20_000))
}

fn typed(app: &mut App, rec: &Recording, s: &str) {
    for c in s.chars() {
        press(app, rec, KeyCode::Char(c));
    }
}

/// The system ids of the table's rows, top to bottom.
fn rows(frame: &str) -> Vec<u8> {
    frame
        .lines()
        .filter_map(|l| {
            let cell = l.trim_matches('"').strip_prefix('│')?;
            let id = cell.trim_start_matches(['▶', ' ']).split(' ').next()?;
            id.parse().ok()
        })
        .collect()
}

#[test]
fn two_hundred_fifty_vehicles_lost_first_searched_and_scrolled() {
    let rec = fleet();
    let mut app = App::default();
    let t = Instant::now();
    app.view = View::Fleet;
    let frame = rec.render(&mut app, 20_000, (80, 24));
    assert!(
        frame.contains("Fleet: 250 vehicles, 10 lost, 34 armed"),
        "{frame}"
    );
    // The ten lost ones first, in system id order; then the armed ones.
    let top = rows(&frame);
    assert_eq!(
        &top[..10],
        &[25, 50, 75, 100, 125, 150, 175, 200, 225, 250],
        "{frame}"
    );
    assert!(frame.contains("LOST"), "{frame}");
    assert_eq!(top[10], 7, "then the armed ones:\n{frame}");
    assert!(frame.contains("rows 1–"), "{frame}");
    insta::assert_snapshot!("fleet_250_80x24", frame);

    // PgDn twice and End scroll: the cursor's row stays on screen.
    press(&mut app, &rec, KeyCode::PageDown);
    press(&mut app, &rec, KeyCode::PageDown);
    let frame = rec.render(&mut app, 20_000, (80, 24));
    assert_eq!(
        app.fleet.cursor.map(|k| k.0.0),
        Some(app.fleet.listed[40].0.0)
    );
    assert!(rows(&frame).contains(&app.fleet.listed[40].0.0), "{frame}");
    press(&mut app, &rec, KeyCode::End);
    let frame = rec.render(&mut app, 20_000, (80, 24));
    assert_eq!(rows(&frame).last(), Some(&249), "{frame}");
    assert!(frame.contains("of 250"), "{frame}");

    // Search: a number finds system ids that start with it (the armed 133 first); words find
    // state and mode.
    press(&mut app, &rec, KeyCode::Char('/'));
    typed(&mut app, &rec, "13");
    press(&mut app, &rec, KeyCode::Enter);
    let frame = rec.render(&mut app, 20_000, (80, 24));
    assert_eq!(
        rows(&frame),
        [133, 13, 130, 131, 132, 134, 135, 136, 137, 138, 139],
        "{frame}"
    );
    assert!(frame.contains("11.1V 64%"), "the battery of 13:\n{frame}");
    press(&mut app, &rec, KeyCode::Esc);
    press(&mut app, &rec, KeyCode::Char('/'));
    typed(&mut app, &rec, "lost");
    press(&mut app, &rec, KeyCode::Enter);
    let frame = rec.render(&mut app, 20_000, (80, 24));
    assert_eq!(rows(&frame).len(), 10, "{frame}");
    insta::assert_snapshot!("fleet_search_lost", frame);

    // Enter shows and commands the vehicle under the cursor: the header follows, its table
    // is asked for.
    press(&mut app, &rec, KeyCode::Down);
    let reqs = press(&mut app, &rec, KeyCode::Enter);
    assert_eq!(reqs, [Request::ParamsPull]);
    assert_eq!(app.selected.map(|k| k.0.0), Some(50));
    let frame = rec.render(&mut app, 20_000, (80, 24));
    assert!(
        frame.lines().next().unwrap_or_default().contains("sys 50"),
        "{frame}"
    );
    assert!(frame.contains("▶50"), "{frame}");

    // The whole list on a large terminal: 45 rows at once.
    press(&mut app, &rec, KeyCode::Esc);
    let frame = rec.render(&mut app, 20_000, (200, 50));
    assert!(rows(&frame).len() >= 40, "{frame}");
    insta::assert_snapshot!("fleet_250_200x50", frame);
    // Rendering 250 vehicles is not timed here (see docs/benchmarks/tui.md); it just finishes.
    let _ = t;
}
