//! The live target against the embedded twin: the twin sends POSITION_TARGET_GLOBAL_INT as
//! ArduPlane does while its navigator flies to a point, and the Flight view shows that point as
//! the setpoint in GUIDED and QRTL, and none once the mode has no target.

use ratatui::Terminal;
use ratatui::backend::TestBackend;
use vtol_gcs::tracker::VehicleState;
use vtol_gcs::tui::air::live_target;
use vtol_gcs::tui::app::{App, Request};
use vtol_gcs::tui::view::RenderState;
use vtol_gcs::vitals::vitals;

use crate::ui_support::{chars, run, start, wait_standby, wait_state};

/// The first vehicle's live target now, if it sends one.
fn target(s: &VehicleState) -> Option<[f32; 3]> {
    let v = s.vehicles.values().next()?;
    live_target(s, v, vtol_gcs::tracker::now())
}

fn near(t: Option<[f32; 3]>, want: [f32; 3]) -> bool {
    t.is_some_and(|t| t.iter().zip(want).all(|(a, b)| (a - b).abs() < 0.05))
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn the_flight_view_shows_the_vehicles_live_target_in_guided_and_qrtl() {
    let (running, cancel, mut tasks, control) = start().await;
    let mut app = App::default();
    let state = wait_standby(&running).await;
    run(&mut app, &control, vec![Request::SetMode("QHOVER")]).await;
    let reqs = chars(&mut app, &state, "ay");
    run(&mut app, &control, reqs).await;
    wait_state(&running, "hovering", |s| {
        s.vehicles
            .values()
            .any(|v| vitals(s, v).airborne && v.position.is_some_and(|p| -p.pos_ned_m[2] > 0.8))
    })
    .await;
    // QHOVER flies to no point: the vehicle sends no target.
    assert!(target(&running.state.borrow()).is_none());

    // GUIDED, then a point 1 m north, 0.5 m east, 1.5 m up: the vehicle's own word on it. The
    // point is held in a hover (Q_GUIDED_MODE 1; ArduPlane's default flies it on the wing).
    run(
        &mut app,
        &control,
        vec![Request::ParamSet {
            name: "Q_GUIDED_MODE".into(),
            value: 1.0,
        }],
    )
    .await;
    run(&mut app, &control, vec![Request::SetMode("GUIDED")]).await;
    let want = [1.0, 0.5, -1.5];
    run(&mut app, &control, vec![Request::PositionTarget(want)]).await;
    wait_state(&running, "the GUIDED target sent back", |s| {
        near(target(s), want)
    })
    .await;
    let frame = draw(&mut app, &running);
    assert!(frame.contains("GUIDED"), "{frame}");
    assert!(frame.contains("setpoint   +1.00 m"), "north:\n{frame}");
    assert!(frame.contains("setpoint   +0.50 m"), "east:\n{frame}");
    assert!(frame.contains("setpoint   +1.50 m"), "altitude:\n{frame}");
    assert!(frame.contains("the vehicle's live target"), "{frame}");

    // QRTL flies home: the target moves to home's north and east.
    run(&mut app, &control, vec![Request::SetMode("QRTL")]).await;
    let home = wait_state(&running, "the QRTL target", |s| {
        target(s).is_some_and(|t| t[0].abs() < 0.05 && t[1].abs() < 0.05)
    })
    .await;
    let t = target(&home).expect("target");
    let frame = draw(&mut app, &running);
    assert!(frame.contains("QRTL"), "{frame}");
    assert!(
        frame.contains(&format!("setpoint {:+7.2} m", -t[2])),
        "altitude of the QRTL target {t:?}:\n{frame}"
    );
    assert!(frame.contains("the vehicle's live target"), "{frame}");

    // Back in QHOVER the target goes once the vehicle stops sending it.
    run(&mut app, &control, vec![Request::SetMode("QHOVER")]).await;
    wait_state(&running, "no target in QHOVER", |s| {
        s.vehicles
            .values()
            .next()
            .is_some_and(|v| v.mode_name() == "QHOVER")
            && target(s).is_none()
    })
    .await;
    let frame = draw(&mut app, &running);
    assert!(!frame.contains("the vehicle's live target"), "{frame}");
    run(&mut app, &control, vec![Request::SetMode("QLAND")]).await;

    cancel.cancel();
    while tasks.join_next().await.is_some() {}
}

/// The whole screen at 80×24 as the running UI draws it.
fn draw(app: &mut App, running: &vtol_gcs::daemon::Running) -> String {
    let mut terminal = Terminal::new(TestBackend::new(80, 24)).expect("test backend");
    let mut render = RenderState::default();
    vtol_gcs::tui::draw_running(
        &mut terminal,
        app,
        running,
        &mut render,
        vtol_gcs::tracker::now(),
    )
    .expect("draw");
    format!("{}", terminal.backend())
}
