//! The Map view's mission keys: `u` uploads a file (checked first, then `y`), `w` downloads the
//! mission into a file, `g` starts it (`y`), `n` makes an item current (`y` while the vehicle
//! flies the mission); refused on a replay. The keys' logic without a terminal, then the
//! requests carried out by the real client against the embedded twin, the outcomes fed back.

use std::time::{Duration, Instant};

use ratatui::crossterm::event::{KeyCode, KeyEvent, KeyModifiers};
use vtol_gcs::tracker::VehicleState;
use vtol_gcs::tui::app::mission_keys::{DEFAULT_MISSION_FILE, MissionPrompt};
use vtol_gcs::tui::app::{App, Confirm, Outcome, Request, View};
use vtol_link::dialect::{self, MavMessage};

use crate::ui_support::recording::{Recording, app_with_params};
use crate::ui_support::{chars, run, start, wait_standby, wait_state};

fn press(app: &mut App, state: &VehicleState, c: KeyCode) -> Vec<Request> {
    app.on_key(KeyEvent::new(c, KeyModifiers::NONE), state, Instant::now())
}

/// Types over the prompt's offer: clears it first.
fn retype(app: &mut App, state: &VehicleState, text: &str) {
    for _ in 0..64 {
        press(app, state, KeyCode::Backspace);
    }
    chars(app, state, text);
}

fn last_note(app: &App) -> String {
    app.log.back().map(|(_, t)| t.clone()).unwrap_or_default()
}

/// Home and five items near the twin's home (a VTOL take-off, three waypoints on a 150 m box,
/// a VTOL landing at home), as `tests/pymavlink/test_tui_mission.py` flies them.
const MISSION: &str = "QGC WPL 110\n\
    0\t1\t0\t16\t0\t0\t0\t0\t-35.363261\t149.16523\t584\t1\n\
    1\t0\t3\t84\t0\t0\t0\t0\t0\t0\t20\t1\n\
    2\t0\t3\t16\t0\t0\t0\t0\t-35.361912\t149.16523\t20\t1\n\
    3\t0\t3\t16\t0\t0\t0\t0\t-35.361912\t149.166882\t20\t1\n\
    4\t0\t3\t16\t0\t0\t0\t0\t-35.363261\t149.166882\t20\t1\n\
    5\t0\t3\t85\t0\t0\t0\t0\t-35.363261\t149.16523\t0\t1\n";

#[test]
fn upload_asks_for_a_file_then_y() {
    let state = VehicleState::default();
    let mut app = App {
        view: View::Map,
        ..App::default()
    };
    assert!(chars(&mut app, &state, "u").is_empty());
    assert_eq!(
        app.mission_prompt,
        Some(MissionPrompt::Upload(DEFAULT_MISSION_FILE.into()))
    );
    // Keys go to the prompt: `g` and `y` are letters of the path here.
    retype(&mut app, &state, "box.waypoints");
    assert_eq!(
        press(&mut app, &state, KeyCode::Enter),
        [Request::MissionCheck("box.waypoints".into())]
    );
    assert!(app.mission_prompt.is_none() && !app.typing);
    // A bad file: its first problem, nothing to confirm.
    app.on_outcome(Outcome::MissionChecked(Err(
        "box.waypoints: line 3: latitude 95 is out of range (and 1 more); nothing sent".into(),
    )));
    assert!(app.confirm.is_none());
    assert!(last_note(&app).contains("line 3"), "{:?}", app.log);
    // A good one waits for `y`; anything else cancels.
    let items = vtol_gcs::mission::file::read(MISSION, vtol_gcs::mission::Kind::Mission)
        .expect("reads")
        .into_iter()
        .map(|l| l.item)
        .collect::<Vec<_>>();
    let checked = || Outcome::MissionChecked(Ok(("box.waypoints".into(), items.clone())));
    app.on_outcome(checked());
    assert!(matches!(app.confirm, Some(Confirm::MissionUpload { .. })));
    assert_eq!(
        app.confirm.as_ref().map(|c| c.text().0),
        Some("Upload 5 mission items from box.waypoints?".into())
    );
    assert!(chars(&mut app, &state, "n").is_empty());
    assert!(last_note(&app).contains("nothing sent"));
    app.on_outcome(checked());
    assert_eq!(
        chars(&mut app, &state, "y"),
        [Request::MissionUpload {
            path: "box.waypoints".into(),
            items: items.clone()
        }]
    );
    // The path typed is offered next time; Esc closes the prompt with nothing sent.
    chars(&mut app, &state, "w");
    assert_eq!(
        app.mission_prompt,
        Some(MissionPrompt::Save("box.waypoints".into()))
    );
    assert!(press(&mut app, &state, KeyCode::Esc).is_empty());
    assert!(app.mission_prompt.is_none() && !app.typing);
    chars(&mut app, &state, "w");
    assert_eq!(
        press(&mut app, &state, KeyCode::Enter),
        [Request::MissionSave("box.waypoints".into())]
    );
}

/// A vehicle flying the mission in AUTO at item 3 of 5.
fn flying_auto() -> Recording {
    let mut rec = Recording::new();
    rec.fly_wing(0, 3_000, |_| (10, true, 0.0, 0.0, 0.0, 30.0));
    rec.feed(
        2_900,
        &MavMessage::MISSION_CURRENT(dialect::MISSION_CURRENT_DATA {
            seq: 3,
            total: 5,
            ..Default::default()
        }),
    );
    rec
}

#[test]
fn start_and_set_current_are_guarded() {
    let rec = flying_auto();
    let state = &rec.state;
    let mut app = app_with_params();
    app.view = View::Map;
    // Start: always `y` first; the prompt says the vehicle is armed.
    assert!(chars(&mut app, state, "g").is_empty());
    let Some(c @ Confirm::MissionStart { .. }) = app.confirm.clone() else {
        panic!("{:?}", app.confirm)
    };
    assert_eq!(
        c,
        Confirm::MissionStart {
            from: Some(3),
            armed: true,
            airborne: true
        }
    );
    assert!(c.text().1.is_some_and(|t| t.contains("IN THE AIR")));
    assert_eq!(chars(&mut app, state, "y"), [Request::MissionStart]);
    // `n` offers the next item; flying the mission, it asks first.
    chars(&mut app, state, "n");
    assert_eq!(app.mission_prompt, Some(MissionPrompt::Current("4".into())));
    assert!(press(&mut app, state, KeyCode::Enter).is_empty());
    assert_eq!(app.confirm, Some(Confirm::MissionSetCurrent { seq: 4 }));
    assert_eq!(chars(&mut app, state, "y"), [Request::MissionSetCurrent(4)]);
    // Out of the mission, or not a number: said, nothing sent.
    for typed in ["9", "0", "x"] {
        chars(&mut app, state, "n");
        retype(&mut app, state, typed);
        assert!(press(&mut app, state, KeyCode::Enter).is_empty(), "{typed}");
        assert!(app.confirm.is_none(), "{typed}");
        assert!(last_note(&app).contains("nothing sent"), "{typed}");
    }
    assert!(last_note(&app).contains("not an item number"));
    chars(&mut app, state, "n");
    retype(&mut app, state, "9");
    press(&mut app, state, KeyCode::Enter);
    assert_eq!(
        last_note(&app),
        "set current: the mission has items 1 to 5; nothing sent"
    );
    // On the ground, disarmed, the item is sent at once.
    let idle = VehicleState::default();
    chars(&mut app, &idle, "n");
    retype(&mut app, &idle, "2");
    assert_eq!(
        press(&mut app, &idle, KeyCode::Enter),
        [Request::MissionSetCurrent(2)]
    );
}

#[test]
fn a_replay_offers_no_mission_commands() {
    let rec = flying_auto();
    let mut app = app_with_params();
    app.view = View::Map;
    app.replay = true;
    for k in ["u", "w", "g", "n"] {
        assert!(chars(&mut app, &rec.state, k).is_empty(), "{k}");
        assert!(app.confirm.is_none() && app.mission_prompt.is_none(), "{k}");
        assert_eq!(
            last_note(&app),
            "replay: the vehicle is a recorded log; commands are not offered"
        );
    }
}

#[test]
fn the_prompt_and_the_help_show() {
    let rec = flying_auto();
    let mut app = app_with_params();
    app.view = View::Map;
    chars(&mut app, &rec.state, "u");
    let frame = rec.render(&mut app, 3_000, (80, 24));
    assert!(
        frame.contains("Upload a mission file (Enter checks it, Esc cancels)")
            && frame.contains("mission.waypoints▏"),
        "{frame}"
    );
    press(&mut app, &rec.state, KeyCode::Esc);
    chars(&mut app, &rec.state, "?");
    let frame = rec.render(&mut app, 3_000, (80, 24));
    assert!(frame.contains("Map: u w g n r"), "{frame}");
}

/// The requests against the embedded twin: a file checked (a bad one shows its problem), the
/// mission uploaded and verified (the map shows it), an item made current, the mission
/// downloaded into a file that holds what was uploaded, the mission started (AUTO).
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn mission_keys_against_the_twin() {
    let (running, cancel, mut tasks, control) = start().await;
    let state = wait_standby(&running).await;
    let dir = tempfile::tempdir().expect("temp dir");
    let good = dir.path().join("box.waypoints");
    std::fs::write(&good, MISSION).expect("write");
    let bad = dir.path().join("bad.waypoints");
    std::fs::write(
        &bad,
        MISSION.replace("-35.361912\t149.16523", "95\t149.16523"),
    )
    .expect("write");
    let mut app = app_with_params();
    app.view = View::Map;

    let check = |p: &std::path::Path| Request::MissionCheck(p.display().to_string());
    run(&mut app, &control, vec![check(&bad)]).await;
    assert!(app.confirm.is_none());
    let note = last_note(&app);
    assert!(
        note.starts_with(&format!("{}: line 4", bad.display())) && note.ends_with("nothing sent"),
        "{note}"
    );

    run(&mut app, &control, vec![check(&good)]).await;
    let reqs = chars(&mut app, &state, "y");
    assert!(
        matches!(reqs[..], [Request::MissionUpload { .. }]),
        "{reqs:?}"
    );
    run(&mut app, &control, reqs).await;
    assert_eq!(
        last_note(&app),
        format!(
            "uploaded 5 mission items from {} (verified by download)",
            good.display()
        )
    );
    assert_eq!(app.map.items.len(), 5, "the map shows the new mission");

    let current = |seq: u16| {
        move |s: &VehicleState| {
            s.vehicles.values().any(|v| {
                s.messages
                    .get(&(v.system_id, v.component_id, 42))
                    .and_then(|m| m.last.decode().ok())
                    .is_some_and(|m| matches!(m, MavMessage::MISSION_CURRENT(c) if c.seq == seq))
            })
        }
    };
    run(&mut app, &control, vec![Request::MissionSetCurrent(3)]).await;
    assert_eq!(last_note(&app), "current item 3: done");
    wait_state(&running, "MISSION_CURRENT 3", current(3)).await;

    let saved = dir.path().join("saved.waypoints");
    run(
        &mut app,
        &control,
        vec![Request::MissionSave(saved.display().to_string())],
    )
    .await;
    assert_eq!(
        last_note(&app),
        format!("mission of 5 items written to {}", saved.display())
    );
    let sent = vtol_gcs::mission::verify::load(&good, vtol_gcs::mission::Kind::Mission)
        .expect("good file");
    let back = vtol_gcs::mission::verify::load(&saved, vtol_gcs::mission::Kind::Mission)
        .expect("saved file");
    assert_eq!(
        vtol_gcs::mission::verify::difference(&sent, &back, vtol_gcs::mission::Kind::Mission),
        None
    );

    run(&mut app, &control, vec![Request::MissionStart]).await;
    assert_eq!(last_note(&app), "mission start: done");
    wait_state(&running, "AUTO", |s| {
        s.vehicles.values().any(|v| v.mode_name() == "AUTO")
    })
    .await;

    cancel.cancel();
    let _ = tokio::time::timeout(Duration::from_secs(5), async {
        while tasks.join_next().await.is_some() {}
    })
    .await;
}
