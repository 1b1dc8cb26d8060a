//! The battery failsafe end to end against the embedded twin: a capacity threshold set from the
//! UI (`BATT_LOW_MAH` just under the pack's capacity, `BATT_FS_LOW_ACT` = 2, Land) trips a few
//! seconds into a hover; the vehicle says so in ArduPilot's words, switches to QLAND and lands,
//! and the UI's header shows the failsafe banner and the battery in its warning colour.

use std::time::Instant;

use ratatui::Terminal;
use ratatui::backend::TestBackend;
use ratatui::style::Color;
use vtol_gcs::tui::app::{App, Outcome, Request};
use vtol_gcs::tui::draw_running;
use vtol_gcs::tui::view::RenderState;
use vtol_gcs::vitals::{Severity, vitals};

use crate::ui_support::{run, start, wait_standby, wait_state};

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_low_battery_shows_its_warning_and_the_vehicle_lands() {
    let (running, cancel, mut tasks, control) = start().await;
    let mut app = App::default();
    wait_standby(&running).await;
    // 1300 mAh pack: low once 4 mAh are drawn (about 3 s of hover); then land.
    let reqs = vec![
        Request::ParamSet {
            name: "BATT_LOW_MAH".into(),
            value: 1296.0,
        },
        Request::ParamSet {
            name: "BATT_FS_LOW_ACT".into(),
            value: 2.0,
        },
        Request::SetMode("QHOVER"),
        Request::Arm { force: false },
    ];
    for o in run(&mut app, &control, reqs).await {
        match o {
            Outcome::ParamSet { result, name } => assert!(result.is_ok(), "{name}: {result:?}"),
            Outcome::Command { result, what } => assert!(result.is_ok(), "{what}: {result:?}"),
            _ => {}
        }
    }
    wait_state(&running, "the battery failsafe's QLAND", |s| {
        s.vehicles.values().any(|v| {
            v.mode_name() == "QLAND"
                && v.status_texts
                    .iter()
                    .any(|(_, t)| t.starts_with("Battery 1 is low"))
        })
    })
    .await;
    let state = running.state.borrow().clone();
    let v = state.vehicles.values().next().expect("vehicle");
    let vit = vitals(&state, v);
    if v.armed {
        assert_eq!(vit.failsafe.as_deref(), Some("Battery failsafe: QLAND"));
    }
    let battery = vit.battery.expect("battery reported");
    assert_eq!(battery.severity, Severity::Warn, "{battery:?}");

    // The header at 80×24: the banner, and the battery in yellow.
    let mut terminal = Terminal::new(TestBackend::new(80, 24)).expect("backend");
    let mut render = RenderState::default();
    draw_running(
        &mut terminal,
        &mut app,
        &running,
        &mut render,
        Instant::now(),
    )
    .expect("draw");
    let buf = terminal.backend().buffer().clone();
    let row = |y: u16| -> String { (0..80).map(|x| buf[(x, y)].symbol()).collect() };
    let header = format!("{}\n{}", row(0), row(1));
    assert!(header.contains("QLAND"), "{header}");
    // Column of "BAT " (cells, not bytes: the row has box-drawing characters).
    let cells: Vec<String> = (0..80).map(|x| buf[(x, 1)].symbol().to_owned()).collect();
    let bat_x = (0..77)
        .find(|&i| cells[i..i + 4].concat() == "BAT ")
        .expect("battery on the vitals row") as u16;
    assert_eq!(buf[(bat_x, 1)].fg, Color::Yellow, "{header}");
    if v.armed {
        assert!(row(1).contains("Battery failsafe: QLAND"), "{header}");
    }

    // It lands and disarms by itself.
    wait_state(&running, "landed and disarmed", |s| {
        s.vehicles.values().all(|v| !v.armed)
    })
    .await;
    cancel.cancel();
    while tasks.join_next().await.is_some() {}
}
