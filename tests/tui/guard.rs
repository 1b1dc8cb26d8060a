//! Guarded actions and recovery against the embedded twin: a key that would drop a hovering
//! vehicle asks first and `n` leaves it hovering; a disarm in the air names its consequence and
//! the vehicle refuses it; force disarm has its own prompt; a crash's refusal says how to
//! recover and the reboot key clears it.

use vtol_gcs::tracker::VehicleState;
use vtol_gcs::tui::app::{App, Confirm, Level, Outcome, Request};
use vtol_gcs::vitals::vitals;
use vtol_link::dialect::MavState;

use crate::ui_support::{chars, run, start, wait_standby, wait_state};

fn airborne_above(s: &VehicleState, alt_m: f32) -> bool {
    s.vehicles
        .values()
        .any(|v| vitals(s, v).airborne && v.position.is_some_and(|p| -p.pos_ned_m[2] > alt_m))
}

fn mode(s: &VehicleState) -> String {
    s.vehicles
        .values()
        .next()
        .map(|v| v.mode_name())
        .unwrap_or_default()
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn qstabilize_in_the_air_asks_first_and_a_crash_is_cleared_by_the_reboot_key() {
    let (running, cancel, mut tasks, control) = start().await;
    let mut app = App::default();
    let state = wait_standby(&running).await;
    // On the ground, QSTABILIZE is sent at once (no altitude to lose).
    assert_eq!(
        chars(&mut app, &state, "s"),
        [Request::SetMode("QSTABILIZE")]
    );
    run(&mut app, &control, vec![Request::SetMode("QHOVER")]).await;
    let reqs = chars(&mut app, &state, "ay");
    run(&mut app, &control, reqs).await;
    let state = wait_state(&running, "hovering", |s| airborne_above(s, 0.8)).await;

    // `s` in the air with no RC: a prompt naming the consequence, nothing sent; `n` cancels.
    assert!(chars(&mut app, &state, "s").is_empty());
    match &app.confirm {
        Some(Confirm::Mode { name, consequence }) => {
            assert_eq!(*name, "QSTABILIZE");
            assert!(consequence.contains("falls"), "{consequence}");
        }
        other => panic!("expected the mode prompt, got {other:?}"),
    }
    assert!(chars(&mut app, &state, "n").is_empty());
    assert!(app.confirm.is_none());
    // Still hovering in QHOVER a while later (200 more tracker updates).
    let mut rx = running.state.clone();
    for _ in 0..200 {
        rx.changed().await.expect("tracker running");
    }
    let later = rx.borrow().clone();
    assert_eq!(mode(&later), "QHOVER");
    assert!(airborne_above(&later, 0.8), "still hovering after n");

    // A disarm in the air says the vehicle will refuse it; it does, with its reason.
    assert!(chars(&mut app, &later, "d").is_empty());
    assert_eq!(app.confirm, Some(Confirm::DisarmInAir));
    let reqs = chars(&mut app, &later, "y");
    assert_eq!(reqs, [Request::Disarm]);
    match &run(&mut app, &control, reqs).await[..] {
        [Outcome::Command { result: Err(e), .. }] => assert!(e.contains("Disarm"), "{e}"),
        other => panic!("expected a refusal, got {other:?}"),
    }
    // Force disarm has its own prompt, naming the fall; `n` leaves it flying.
    chars(&mut app, &later, "D");
    assert_eq!(app.confirm, Some(Confirm::ForceDisarm { airborne: true }));
    assert!(chars(&mut app, &later, "n").is_empty());

    // Confirmed, QSTABILIZE with no throttle crashes the vehicle.
    chars(&mut app, &later, "s");
    let reqs = chars(&mut app, &later, "y");
    assert_eq!(reqs, [Request::SetMode("QSTABILIZE")]);
    run(&mut app, &control, reqs).await;
    let crashed = wait_state(&running, "the crash", |s| {
        s.vehicles
            .values()
            .any(|v| v.system_status == MavState::MAV_STATE_EMERGENCY && !v.armed)
    })
    .await;
    let v = crashed.vehicles.values().next().expect("vehicle");
    let reason = vitals(&crashed, v).reason.unwrap_or_default();
    assert!(
        reason.contains("rash"),
        "the header's reason for EMERGENCY: {reason:?}"
    );
    // Arming is refused, and the refusal says how to recover.
    run(&mut app, &control, vec![Request::SetMode("QHOVER")]).await;
    let reqs = chars(&mut app, &crashed, "ay");
    run(&mut app, &control, reqs).await;
    let (level, line) = app.log.back().expect("a log line").clone();
    assert_eq!(level, Level::Error);
    assert!(
        line.contains("crashed") && line.contains("vtol-gcs reboot"),
        "{line}"
    );

    // The reboot key asks, then reboots; the vehicle comes back and arms.
    assert!(chars(&mut app, &crashed, "R").is_empty());
    assert_eq!(app.confirm, Some(Confirm::Reboot));
    let reqs = chars(&mut app, &crashed, "y");
    assert_eq!(reqs, [Request::Reboot]);
    match &run(&mut app, &control, reqs).await[..] {
        [Outcome::Command { result: Ok(()), .. }] => {}
        other => panic!("reboot: {other:?}"),
    }
    wait_state(&running, "STANDBY after the reboot", |s| {
        s.vehicles
            .values()
            .any(|v| v.reboots > 0 && v.system_status == MavState::MAV_STATE_STANDBY)
    })
    .await;
    run(&mut app, &control, vec![Request::SetMode("QHOVER")]).await;
    let outcomes = run(&mut app, &control, vec![Request::Arm { force: false }]).await;
    assert!(
        matches!(&outcomes[..], [Outcome::Command { result: Ok(()), .. }]),
        "{outcomes:?}"
    );
    // Armed, the reboot key refuses and says why.
    let armed = wait_state(&running, "armed", |s| s.vehicles.values().any(|v| v.armed)).await;
    assert!(chars(&mut app, &armed, "R").is_empty());
    assert!(app.confirm.is_none());
    assert!(app.log.back().unwrap().1.contains("disarm first"));
    run(&mut app, &control, vec![Request::Disarm]).await;

    cancel.cancel();
    while tasks.join_next().await.is_some() {}
}
