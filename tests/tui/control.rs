//! The UI's state and input logic without a terminal: key → action → request, and requests
//! carried out by the real client against the embedded twin (the daemon in this process), with
//! the outcomes fed back into the UI state as the event loop does.

use std::time::Instant;

use ratatui::crossterm::event::{KeyCode, KeyEvent, KeyModifiers};
use vtol_gcs::tracker::VehicleState;
use vtol_gcs::tui::app::{App, Confirm, Outcome, ParamStatus, Request, View};

use crate::ui_support::{chars, run, start, wait_standby, wait_state};

fn key(c: KeyCode) -> KeyEvent {
    KeyEvent::new(c, KeyModifiers::NONE)
}

#[test]
fn arm_needs_confirmation_and_any_other_key_cancels() {
    let state = VehicleState::default();
    let mut app = App::default();
    assert!(chars(&mut app, &state, "a").is_empty());
    assert_eq!(app.confirm, Some(Confirm::Arm { force: false }));
    assert!(chars(&mut app, &state, "n").is_empty(), "n cancels");
    assert_eq!(app.confirm, None);
    assert_eq!(
        chars(&mut app, &state, "ay"),
        [Request::Arm { force: false }]
    );
    assert_eq!(
        chars(&mut app, &state, "Ay"),
        [Request::Arm { force: true }]
    );
    assert_eq!(chars(&mut app, &state, "dy"), [Request::Disarm]);
    // q inside a confirmation cancels it instead of quitting.
    chars(&mut app, &state, "aq");
    assert!(!app.quit);
    chars(&mut app, &state, "q");
    assert!(app.quit);
}

#[test]
fn modes_pushes_and_window() {
    let state = VehicleState::default();
    let mut app = App::default();
    assert_eq!(chars(&mut app, &state, "t"), [Request::SetMode("QHOVER")]);
    assert_eq!(chars(&mut app, &state, "l"), [Request::SetMode("QLAND")]);
    assert_eq!(chars(&mut app, &state, "p"), [Request::SetMode("QLOITER")]);
    assert_eq!(
        chars(&mut app, &state, "X"),
        [Request::ParamSet {
            name: "SIM_PUSH_ROLL".into(),
            value: -vtol_gcs::tui::app::PUSH_NM
        }]
    );
    assert_eq!(
        chars(&mut app, &state, "z"),
        [Request::ParamSet {
            name: "SIM_PUSH_YAW".into(),
            value: vtol_gcs::tui::app::PUSH_NM
        }]
    );
    chars(&mut app, &state, "+");
    assert_eq!(app.window_s, 60.0);
    chars(&mut app, &state, "---");
    assert_eq!(app.window_s, 7.5);
    // Without a vehicle in QLOITER the arrows send nothing and say why.
    assert!(
        app.on_key(key(KeyCode::Up), &state, Instant::now())
            .is_empty()
    );
    assert!(app.log.back().unwrap().1.contains("no vehicle"));
}

#[test]
fn a_typed_value_that_is_not_a_number_is_refused_without_sending() {
    let state = VehicleState::default();
    let mut app = App::default();
    app.on_outcome(Outcome::Params(vec![("HOVER_ALT".into(), 1.0)]));
    app.view = View::Params;
    app.on_key(key(KeyCode::Enter), &state, Instant::now());
    assert!(app.typing);
    assert!(chars(&mut app, &state, "nan").is_empty());
    assert!(
        app.on_key(key(KeyCode::Enter), &state, Instant::now())
            .is_empty()
    );
    assert!(matches!(
        app.params.status.get("HOVER_ALT"),
        Some(ParamStatus::NotSent(r)) if r.contains("not a finite number")
    ));
    // A later value from the vehicle clears the local error.
    app.on_outcome(Outcome::Params(vec![("HOVER_ALT".into(), 1.5)]));
    assert_eq!(app.params.status.get("HOVER_ALT"), None);
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn parameter_edit_round_trip_and_arm_against_the_twin() {
    let (running, cancel, mut tasks, control) = start().await;
    let mut app = App::default();

    // Download: progress, then the table with the vehicle's values.
    let outcomes = run(&mut app, &control, vec![Request::ParamsPull]).await;
    assert!(
        outcomes
            .iter()
            .any(|o| matches!(o, Outcome::Progress { .. }))
    );
    let hover = app
        .params
        .value("HOVER_ALT")
        .expect("HOVER_ALT in the table");

    // Edit HOVER_ALT from the keyboard: filter, select, type, Enter.
    app.view = View::Params;
    let state = running.state.borrow().clone();
    let mut reqs = chars(&mut app, &state, "/hover_alt");
    reqs.extend(app.on_key(key(KeyCode::Enter), &state, Instant::now()));
    reqs.extend(app.on_key(key(KeyCode::Enter), &state, Instant::now()));
    let wanted = hover + 0.5;
    reqs.extend(chars(&mut app, &state, &wanted.to_string()));
    assert!(reqs.is_empty(), "nothing is sent before Enter: {reqs:?}");
    let reqs = app.on_key(key(KeyCode::Enter), &state, Instant::now());
    assert_eq!(
        reqs,
        [Request::ParamSet {
            name: "HOVER_ALT".into(),
            value: wanted
        }]
    );
    assert_eq!(
        app.params.status.get("HOVER_ALT"),
        Some(&ParamStatus::Pending(wanted))
    );
    run(&mut app, &control, reqs).await;
    assert_eq!(
        app.params.status.get("HOVER_ALT"),
        Some(&ParamStatus::Confirmed)
    );
    assert_eq!(app.params.value("HOVER_ALT"), Some(wanted));
    let read = running
        .client
        .param_get("HOVER_ALT")
        .await
        .expect("read back");
    assert_eq!(read.value, wanted, "the vehicle holds what the UI shows");

    // A value the vehicle refuses (b must stay below a - c - d): the reason is shown, the
    // value is unchanged on the vehicle and in the table.
    let b = app.params.value("LAT_SAT_B").expect("LAT_SAT_B");
    app.params.filter.clear();
    chars(&mut app, &state, "/lat_sat_b");
    app.on_key(key(KeyCode::Enter), &state, Instant::now());
    app.on_key(key(KeyCode::Enter), &state, Instant::now());
    let reqs = [
        chars(&mut app, &state, "5"),
        app.on_key(key(KeyCode::Enter), &state, Instant::now()),
    ]
    .concat();
    run(&mut app, &control, reqs).await;
    match app.params.status.get("LAT_SAT_B") {
        Some(ParamStatus::Refused(reason)) => assert!(!reason.is_empty()),
        other => panic!("expected a refusal, got {other:?}"),
    }
    assert_eq!(app.params.value("LAT_SAT_B"), Some(b));
    assert_eq!(
        running.client.param_get("LAT_SAT_B").await.unwrap().value,
        b
    );

    // Arm through the confirmation once the vehicle is ready; the tracker sees it armed.
    wait_standby(&running).await;
    app.view = View::Flight;
    let reqs = chars(&mut app, &state, "ay");
    let outcomes = run(&mut app, &control, reqs).await;
    assert_eq!(
        outcomes,
        [Outcome::Command {
            what: "arm".into(),
            result: Ok(())
        }]
    );
    wait_state(&running, "armed", |s| s.vehicles.values().any(|v| v.armed)).await;
    let reqs = chars(&mut app, &state, "dy");
    let outcomes = run(&mut app, &control, reqs).await;
    assert!(matches!(
        &outcomes[..],
        [Outcome::Command { result: Ok(()), .. }]
    ));
    wait_state(&running, "disarmed", |s| {
        s.vehicles.values().all(|v| !v.armed)
    })
    .await;

    cancel.cancel();
    while tasks.join_next().await.is_some() {}
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn gains_file_diff_then_transactional_upload() {
    let (running, cancel, mut tasks, control) = start().await;
    let dir = tempfile::tempdir().expect("tempdir");
    let path = dir.path().join("gains.param");
    // Applicable in one order only: every level shrinks, so d, c, b, a (each write keeps
    // a > b + c + d, b > c + d, c > d); the diff preview lists the four changes first.
    std::fs::write(
        &path,
        "LAT_SAT_A 0.4\nLAT_SAT_B 0.2\nLAT_SAT_C 0.1\nLAT_SAT_D 0.05\n",
    )
    .expect("write");
    let mut app = App {
        view: View::Params,
        ..App::default()
    };
    let state = running.state.borrow().clone();
    chars(&mut app, &state, "f");
    assert!(app.typing);
    // Replace the suggested path with ours.
    for _ in 0..64 {
        app.on_key(key(KeyCode::Backspace), &state, Instant::now());
    }
    chars(&mut app, &state, &path.display().to_string());
    let reqs = app.on_key(key(KeyCode::Enter), &state, Instant::now());
    assert_eq!(reqs, [Request::LoadGains(path.display().to_string())]);
    run(&mut app, &control, reqs).await;
    let diff = app.params.diff.clone().expect("diff preview");
    let names: Vec<_> = diff.iter().map(|(n, _, _)| n.as_str()).collect();
    assert_eq!(names, ["LAT_SAT_A", "LAT_SAT_B", "LAT_SAT_C", "LAT_SAT_D"]);
    assert_eq!(app.confirm, Some(Confirm::Upload));
    let reqs = chars(&mut app, &state, "y");
    assert_eq!(reqs, [Request::PushGains]);
    let outcomes = run(&mut app, &control, reqs).await;
    assert!(
        outcomes
            .iter()
            .any(|o| matches!(o, Outcome::Progress { what, .. } if what == "upload")),
        "{outcomes:?}"
    );
    assert!(
        matches!(outcomes.last(), Some(Outcome::GainsPushed(Ok(s))) if s.contains("4 changed")),
        "{outcomes:?}"
    );
    for (name, v) in [
        ("LAT_SAT_A", 0.4f32),
        ("LAT_SAT_B", 0.2),
        ("LAT_SAT_C", 0.1),
        ("LAT_SAT_D", 0.05),
    ] {
        assert_eq!(running.client.param_get(name).await.unwrap().value, v);
        assert_eq!(
            app.params.value(name),
            Some(v),
            "table refreshed after the upload"
        );
    }

    // A broken file: a line-numbered error, nothing sent.
    std::fs::write(&path, "LAT_SAT_A 0.5\nLAT_SAT_B nan\n").expect("write");
    let outcomes = run(
        &mut app,
        &control,
        vec![Request::LoadGains(path.display().to_string())],
    )
    .await;
    match &outcomes[..] {
        [Outcome::GainsLoaded(Err(e))] => assert!(e.contains('2'), "names the line: {e}"),
        other => panic!("expected an error, got {other:?}"),
    }
    assert_eq!(
        running.client.param_get("LAT_SAT_A").await.unwrap().value,
        0.4
    );

    cancel.cancel();
    while tasks.join_next().await.is_some() {}
}
