//! The operator's view of a whole flight, from recorded vehicle states: the mode picker (every
//! mode of the vehicle, guarded as the mode keys are), a replayed log offering no commands, a
//! tailsitter's attitude as ArduPlane reports it shown in the hover frame while it hovers,
//! outputs named by their `SERVOn_FUNCTION`, and the Links view keeping every address at 80×24.

use ratatui::crossterm::event::KeyCode;
use vtol_gcs::daemon::REPLAY_PEER;
use vtol_gcs::links::Side;
use vtol_gcs::tui::app::{App, Confirm, Request, View};
use vtol_gcs::tui::view::{LinkRow, RouterCounters, Snapshot};
use vtol_link::dialect::{self, MavAutopilot, MavMessage, MavState, MavType, MavVtolState};
use vtol_link::{LinkId, LinkStatsSnapshot};

use crate::ui_support::recording::{
    Recording, VEHICLE_LINK, app_with, app_with_params, draw_snapshot, hover, key, params_with,
};

fn keys(app: &mut App, rec: &Recording, at_ms: u64, ks: &[KeyCode]) -> Vec<Request> {
    let state = rec.state.clone();
    ks.iter()
        .flat_map(|k| app.on_key(key(*k), &state, rec.at(at_ms)))
        .collect()
}

fn ext_state(s: MavVtolState) -> MavMessage {
    MavMessage::EXTENDED_SYS_STATE(dialect::EXTENDED_SYS_STATE_DATA {
        vtol_state: s,
        landed_state: dialect::MavLandedState::MAV_LANDED_STATE_IN_AIR,
    })
}

/// `m` lists the vehicle's modes with the current one marked; typing filters; Enter on a mode
/// that needs a throttle nobody holds asks first in the air (as `s` does); AUTO goes at once;
/// Esc sends nothing.
#[test]
fn the_mode_picker_lists_every_mode_and_guards_as_the_mode_keys_do() {
    let rec = hover();
    let mut app = app_with_params();
    rec.render(&mut app, 20_000, (80, 24));
    assert!(keys(&mut app, &rec, 20_000, &[KeyCode::Char('m')]).is_empty());
    let frame = rec.render(&mut app, 20_000, (80, 24));
    for mode in ["QHOVER", "QLOITER", "FBWA", "AUTO", "RTL", "MANUAL"] {
        assert!(frame.contains(mode), "no {mode}:\n{frame}");
    }
    assert!(frame.contains("QHOVER       18  current"), "{frame}");
    insta::assert_snapshot!("mode_picker", frame);
    // The list scrolls to the last modes.
    keys(&mut app, &rec, 20_000, &[KeyCode::End]);
    let frame = rec.render(&mut app, 20_000, (80, 24));
    assert!(frame.contains("QACRO") && frame.contains("QRTL"), "{frame}");
    keys(&mut app, &rec, 20_000, &[KeyCode::Home]);

    // Filtered to FBWA: a fixed-wing mode with the throttle on the stick, in the air, no RC.
    let reqs = keys(
        &mut app,
        &rec,
        20_000,
        &[
            KeyCode::Char('f'),
            KeyCode::Char('b'),
            KeyCode::Char('w'),
            KeyCode::Char('a'),
        ],
    );
    assert!(reqs.is_empty());
    let frame = rec.render(&mut app, 20_000, (80, 24));
    assert!(
        frame.contains("FBWA") && !frame.contains("QHOVER       18"),
        "{frame}"
    );
    assert!(frame.contains("forward transition"), "{frame}");
    assert!(keys(&mut app, &rec, 20_000, &[KeyCode::Enter]).is_empty());
    match &app.confirm {
        Some(Confirm::Mode { name, consequence }) => {
            assert_eq!(*name, "FBWA");
            assert!(consequence.contains("falls"), "{consequence}");
        }
        other => panic!("expected the mode prompt, got {other:?}"),
    }
    assert_eq!(
        keys(&mut app, &rec, 20_000, &[KeyCode::Char('y')]),
        [Request::SetMode("FBWA")]
    );

    // AUTO through the list: no prompt, sent at once.
    keys(&mut app, &rec, 20_000, &[KeyCode::Char('m')]);
    let reqs = keys(
        &mut app,
        &rec,
        20_000,
        &[
            KeyCode::Char('a'),
            KeyCode::Char('u'),
            KeyCode::Char('t'),
            KeyCode::Char('o'),
            KeyCode::Enter,
        ],
    );
    assert_eq!(reqs, [Request::SetMode("AUTO")]);
    assert!(app.picker.is_none());

    // Esc closes with nothing sent.
    keys(&mut app, &rec, 20_000, &[KeyCode::Char('m'), KeyCode::Down]);
    assert!(keys(&mut app, &rec, 20_000, &[KeyCode::Esc]).is_empty());
    assert!(app.picker.is_none());
    assert!(
        app.log
            .back()
            .is_some_and(|(_, t)| t.contains("nothing sent"))
    );
}

/// A vehicle that is a replayed log: arm, modes, the picker and the twin's pushes send nothing
/// and say why; the footer says it; the views still change.
#[test]
fn a_replay_offers_no_commands() {
    let rec = hover();
    let mut app = app_with_params();
    let links = vec![LinkRow {
        id: VEHICLE_LINK,
        side: Side::Vehicle,
        peer: REPLAY_PEER.into(),
        own: false,
        policy: None,
        stats: LinkStatsSnapshot::default(),
    }];
    // The UI learns it from the frame it draws.
    let s = Snapshot {
        now: rec.at(20_000),
        state: &rec.state,
        history: &rec.history,
        links: links.clone(),
        router: RouterCounters::default(),
        tlog: None,
        serving: Vec::new(),
    };
    let frame = draw_snapshot(&mut app, &s, (80, 24));
    assert!(app.replay);
    assert!(frame.contains("ACTIVE │ REPLAY │"), "{frame}");
    for k in [
        'a', 'A', 'd', 'D', 'R', 't', 'l', 'p', 's', 'm', 'x', 'c', 'z',
    ] {
        assert!(
            keys(&mut app, &rec, 20_000, &[KeyCode::Char(k)]).is_empty(),
            "{k}"
        );
        assert!(app.confirm.is_none() && app.picker.is_none(), "{k}");
    }
    assert!(
        app.log
            .back()
            .is_some_and(|(_, t)| t.contains("commands are not offered")),
        "{:?}",
        app.log
    );
    // The parameter table is not written either; the views still change.
    app.view = View::Params;
    assert!(keys(&mut app, &rec, 20_000, &[KeyCode::Enter]).is_empty());
    assert!(app.params.edit.is_none());
    keys(&mut app, &rec, 20_000, &[KeyCode::Tab]);
    assert_eq!(app.view, View::Fleet);
    app.view = View::Flight;
    let frame = draw_snapshot(&mut app, &s, (80, 24));
    insta::assert_snapshot!("replay_without_commands", frame);
    // The same vehicle over a live link is commanded as ever.
    let mut live = app_with_params();
    let s = Snapshot {
        links: vec![LinkRow {
            peer: "tcp 127.0.0.1:5760".into(),
            ..links[0].clone()
        }],
        ..s
    };
    let _ = draw_snapshot(&mut live, &s, (80, 24));
    assert!(!live.replay);
    keys(&mut live, &rec, 20_000, &[KeyCode::Char('a')]);
    assert_eq!(live.confirm, Some(Confirm::Arm { force: false }));
}

/// ArduPlane's QuadPlane heartbeat: a fixed wing (Q_MAV_TYPE 0), ArduPilot autopilot.
fn plane_heartbeat(mode: u32) -> MavMessage {
    MavMessage::HEARTBEAT(dialect::HEARTBEAT_DATA {
        custom_mode: mode,
        mavtype: MavType::MAV_TYPE_FIXED_WING,
        autopilot: MavAutopilot::MAV_AUTOPILOT_ARDUPILOTMEGA,
        base_mode: dialect::MavModeFlag::MAV_MODE_FLAG_CUSTOM_MODE_ENABLED
            | dialect::MavModeFlag::MAV_MODE_FLAG_SAFETY_ARMED,
        system_status: MavState::MAV_STATE_ACTIVE,
        mavlink_version: 3,
    })
}

/// ArduPlane's tailsitter hovering upright, its attitude as it reports it: AHRS2 in the
/// fixed-wing body frame, `roll +129.9° pitch +89.9° yaw +128.5°` (which the UI once showed as
/// it came), and ATTITUDE the same in `vtol` FW, its VTOL view of it in MC; or, with
/// `first_boot`, the fixed-wing frame in MC too, as an ArduPlane SITL sends it before the reboot
/// that sets its VTOL view up.
fn arduplane_hover(vtol: MavVtolState, first_boot: bool) -> Recording {
    let mut rec = Recording::new();
    let d = |x: f32| x.to_radians();
    let wing = [d(129.9), d(89.9), d(128.5)];
    let view = {
        let q = nalgebra::UnitQuaternion::from_euler_angles(
            f64::from(wing[0]),
            f64::from(wing[1]),
            f64::from(wing[2]),
        );
        let (r, p, y) = vtol_gcs::tui::attitude::wing_to_hover(q).euler_angles();
        [r as f32, p as f32, y as f32]
    };
    let reported = if vtol == MavVtolState::MAV_VTOL_STATE_MC && !first_boot {
        view
    } else {
        wing
    };
    for ms in (0..5_000).step_by(100) {
        if ms % 1000 == 0 {
            rec.feed(ms, &plane_heartbeat(18));
            rec.feed(ms, &ext_state(vtol));
        }
        rec.feed(
            ms,
            &MavMessage::AHRS2(dialect::AHRS2_DATA {
                roll: wing[0],
                pitch: wing[1],
                yaw: wing[2],
                ..Default::default()
            }),
        );
        rec.feed(
            ms,
            &MavMessage::ATTITUDE(dialect::ATTITUDE_DATA {
                time_boot_ms: ms as u32,
                roll: reported[0],
                pitch: reported[1],
                yaw: reported[2],
                rollspeed: 0.0,
                pitchspeed: 0.0,
                yawspeed: 0.0,
            }),
        );
        rec.feed(
            ms,
            &MavMessage::SERVO_OUTPUT_RAW(dialect::SERVO_OUTPUT_RAW_DATA {
                servo1_raw: 1500,
                servo2_raw: 1500,
                servo3_raw: 1620,
                servo4_raw: 1610,
                ..Default::default()
            }),
        );
        rec.feed(
            ms,
            &MavMessage::LOCAL_POSITION_NED(dialect::LOCAL_POSITION_NED_DATA {
                time_boot_ms: ms as u32,
                z: -10.0,
                ..Default::default()
            }),
        );
    }
    rec
}

/// ArduPlane's tailsitter parameters as the daemon pulls them: Q_TAILSIT_ENABLE and its
/// outputs (elevons, then the left and right throttles).
fn arduplane_app() -> App {
    app_with(vec![
        ("ARSPD_FBW_MIN".into(), 9.0),
        ("Q_TAILSIT_ENABLE".into(), 1.0),
        ("SERVO1_FUNCTION".into(), 77.0),
        ("SERVO2_FUNCTION".into(), 78.0),
        ("SERVO3_FUNCTION".into(), 73.0),
        ("SERVO4_FUNCTION".into(), 74.0),
    ])
}

/// Hovering, the attitude reads upright (roll and pitch near 0) with the heading where the belly
/// faces, labelled "hover frame"; the horizon is level; the outputs are named by function. In
/// forward flight the wing frame is shown as reported, and says so.
#[test]
fn a_tailsitter_hovering_reads_upright_in_the_hover_frame() {
    // Before and after ArduPlane's VTOL view is set up: the same.
    let rec = arduplane_hover(MavVtolState::MAV_VTOL_STATE_MC, true);
    let mut app = arduplane_app();
    let first_boot = rec.render(&mut app, 5_000, (80, 24));
    let rec = arduplane_hover(MavVtolState::MAV_VTOL_STATE_MC, false);
    let mut app = arduplane_app();
    let frame = rec.render(&mut app, 5_000, (80, 24));
    assert_eq!(first_boot, frame);
    assert!(frame.contains("Horizon (hover frame)"), "{frame}");
    assert!(frame.contains("Attitude (hover frame)"), "{frame}");
    // 0.1° short of vertical in the report: 0.1° from upright.
    assert!(frame.contains("Roll      +0.1°"), "{frame}");
    assert!(frame.contains("Pitch     +0.1°"), "{frame}");
    // Yaw − roll of the report: the belly 1.4° west of north.
    assert!(frame.contains("Yaw       -1.4°"), "{frame}");
    for name in ["left elevon", "right elevon", "left motor", "right motor"] {
        assert!(frame.contains(name), "no {name}:\n{frame}");
    }
    assert!(!frame.contains("+129.9°"), "{frame}");
    insta::assert_snapshot!("tailsitter_hover", frame);

    // The same vehicle level in forward flight: the wing frame as reported.
    let rec = arduplane_hover(MavVtolState::MAV_VTOL_STATE_FW, false);
    let frame = rec.render(&mut app, 5_000, (80, 24));
    assert!(frame.contains("Attitude (wing frame)"), "{frame}");
    assert!(frame.contains("Pitch    +89.9°"), "{frame}");

    // The twin publishes Q_TAILSIT_* gains without the switch: a tailsitter too.
    let rec = arduplane_hover(MavVtolState::MAV_VTOL_STATE_MC, false);
    let mut twin = app_with(params_with(&[("Q_TAILSIT_ANGLE", 45.0)]));
    let frame = rec.render(&mut twin, 5_000, (80, 24));
    assert!(frame.contains("Attitude (hover frame)"), "{frame}");

    // Not a tailsitter (no Q_TAILSIT_ENABLE, a fixed-wing MAV_TYPE): as reported, unlabelled.
    let rec = arduplane_hover(MavVtolState::MAV_VTOL_STATE_MC, true);
    let mut plain = app_with(params_with(&[]));
    let frame = rec.render(&mut plain, 5_000, (80, 24));
    assert!(frame.contains(" Attitude and position "), "{frame}");
    assert!(frame.contains("Roll    +129.9°"), "{frame}");
}

/// At 80×24 the Links view keeps every link's address: whole on its row when it fits (a TCP
/// vehicle, a TCP client), else broken after the colon (a UDP client's long one).
#[test]
fn the_links_view_keeps_every_address_at_80_by_24() {
    let rec = hover();
    let mut app = app_with_params();
    app.view = View::Links;
    let row = |id: u32, side: Side, peer: &str, own: bool| LinkRow {
        id: LinkId(id),
        side,
        peer: peer.into(),
        own,
        policy: None,
        stats: LinkStatsSnapshot {
            rx_frames: 348,
            tx_frames: 5,
            ..Default::default()
        },
    };
    let snap = Snapshot {
        now: rec.at(20_000),
        state: &rec.state,
        history: &rec.history,
        links: vec![
            row(1, Side::Vehicle, "tcp 127.0.0.1:5810", false),
            row(2, Side::Client, "udp 192.168.100.200:14550", false),
            row(3, Side::Client, "tcp 127.0.0.1:43122", false),
        ],
        router: RouterCounters::default(),
        tlog: None,
        serving: vec!["tcpin:127.0.0.1:5770".into()],
    };
    let frame = draw_snapshot(&mut app, &snap, (80, 24));
    for peer in ["tcp 127.0.0.1:5810", "tcp 127.0.0.1:43122"] {
        assert!(
            frame.contains(peer),
            "{peer} not whole on its row:\n{frame}"
        );
    }
    // An address longer than the column breaks after its colon: the host whole, then the port.
    assert!(frame.contains("cli  udp 192.168.100.200: "), "{frame}");
    assert!(frame.contains("│         14550 "), "{frame}");
    insta::assert_snapshot!("links_addresses_80x24", frame);
}

/// A refusal longer than the screen is wide wraps at words in the footer, every word whole.
#[test]
fn a_long_refusal_wraps_at_words() {
    let rec = hover();
    let mut app = app_with_params();
    let reason = "PreArm: Q_TAILSIT_ENABLE set but the motors are not configured: \
                  check SERVO3_FUNCTION and SERVO4_FUNCTION for the left and right throttle";
    app.on_outcome(vtol_gcs::tui::app::Outcome::Command {
        what: "arm".into(),
        result: Err(reason.into()),
    });
    let frame = rec.render(&mut app, 20_000, (80, 24));
    let footer: Vec<&str> = frame.lines().rev().take(3).collect();
    for word in reason.split_whitespace() {
        assert!(
            footer.iter().any(|l| l.contains(word)),
            "{word} cut:\n{frame}"
        );
    }
}

/// QLOITER entered through a back transition holds where the vehicle stops, not where the mode
/// was entered 56 m before: the view shows no setpoint rather than a standing error; entered
/// from a hover it shows the entry point as before.
#[test]
fn qloiter_after_a_back_transition_shows_no_entry_point() {
    let mut rec = Recording::new();
    rec.fly_wing(0, 3_000, |_| (5, true, 0.0, 0.1, 0.0, 30.0));
    let mut app = app_with_params();
    rec.render(&mut app, 3_000, (80, 24));
    // QLOITER at 17 m/s, the back transition under way.
    rec.feed(
        3_000,
        &ext_state(MavVtolState::MAV_VTOL_STATE_TRANSITION_TO_MC),
    );
    rec.feed(
        3_000,
        &MavMessage::LOCAL_POSITION_NED(dialect::LOCAL_POSITION_NED_DATA {
            x: 56.0,
            z: -30.0,
            vx: 17.0,
            ..Default::default()
        }),
    );
    rec.feed(3_000, &crate::ui_support::recording::heartbeat(19, true));
    let frame = rec.render(&mut app, 3_000, (80, 24));
    assert!(frame.contains("QLOITER"), "{frame}");
    assert!(!frame.contains("where QLOITER was entered"), "{frame}");
    assert!(app.target_ned.is_none());

    // From a slow hover: the entry point.
    let rec = hover();
    let mut app = app_with_params();
    rec.render(&mut app, 20_000, (80, 24));
    let mut rec = rec;
    rec.fly(20_000, 21_000, |_| (19, true, 0.0, 0.0, 0.3, 1.0));
    let frame = rec.render(&mut app, 21_000, (80, 24));
    assert!(frame.contains("where QLOITER was entered"), "{frame}");
}

/// A vehicle without a battery monitor (ArduPilot's BATT_MONITOR 0 sends 0 mV and an unknown
/// charge) shows `BAT -`, not an empty pack at 0.0 V; a monitored pack shows its voltage.
#[test]
fn no_battery_monitor_reads_a_dash() {
    let sys_status = |mv: u16, pct: i8| {
        MavMessage::SYS_STATUS(dialect::SYS_STATUS_DATA {
            voltage_battery: mv,
            current_battery: -1,
            battery_remaining: pct,
            ..Default::default()
        })
    };
    let mut rec = hover();
    rec.feed(19_900, &sys_status(0, -1));
    let mut app = app_with_params();
    let frame = rec.render(&mut app, 20_000, (80, 24));
    assert!(frame.contains("BAT -"), "{frame}");
    assert!(!frame.contains("0.0V"), "{frame}");
    rec.feed(19_950, &sys_status(12_100, 80));
    let frame = rec.render(&mut app, 20_000, (80, 24));
    assert!(frame.contains("BAT 12.1V 80%"), "{frame}");
}

/// With an operator present, the daemon asks the vehicle for HOME_POSITION when it first hears
/// it (the twin, like
/// ArduPilot, sends it only when asked or when home moves): the home distance shows before
/// the vehicle arms.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn home_is_asked_for_on_connect() {
    let (running, cancel, mut tasks, _control) = crate::ui_support::start().await;
    // The terminal UI is the operator the requests are made for.
    let _operator = running.client.operator_present();
    let state = crate::ui_support::wait_state(&running, "HOME_POSITION", |s| {
        s.vehicles
            .keys()
            .any(|(sys, comp)| s.messages.contains_key(&(*sys, *comp, 242)))
    })
    .await;
    let v = state.vehicles.values().next().expect("vehicle");
    assert!(!v.armed);
    assert!(vtol_gcs::vitals::vitals(&state, v).home.is_some());
    cancel.cancel();
    while tasks.join_next().await.is_some() {}
}

/// ArduPilot's HOME_POSITION before its EKF has an origin has no local position (NaN): the home
/// distance is not shown rather than `home NaN m`.
#[test]
fn a_home_without_a_local_position_is_not_shown() {
    let mut rec = hover();
    rec.feed(
        19_900,
        &MavMessage::HOME_POSITION(dialect::HOME_POSITION_DATA {
            latitude: 473_977_420,
            longitude: 85_455_940,
            x: f32::NAN,
            y: f32::NAN,
            z: f32::NAN,
            ..Default::default()
        }),
    );
    let mut app = app_with_params();
    let frame = rec.render(&mut app, 20_000, (80, 24));
    assert!(!frame.contains("NaN"), "{frame}");
}

/// ArduPlane sends its last waypoint as POSITION_TARGET_GLOBAL_INT in hover and stick modes
/// too: there it is no setpoint (QHOVER's is HOVER_ALT), in AUTO it is.
#[test]
fn arduplanes_stale_target_in_a_hover_mode_is_no_setpoint() {
    let mut rec = hover();
    let home = MavMessage::HOME_POSITION(dialect::HOME_POSITION_DATA {
        latitude: 473_977_420,
        longitude: 85_455_940,
        altitude: 488_000,
        ..Default::default()
    });
    let target = MavMessage::POSITION_TARGET_GLOBAL_INT(dialect::POSITION_TARGET_GLOBAL_INT_DATA {
        lat_int: 473_977_420 + 5_000,
        lon_int: 85_455_940,
        alt: 488.0,
        coordinate_frame: dialect::MavFrame::MAV_FRAME_GLOBAL,
        ..Default::default()
    });
    rec.feed(19_900, &home);
    rec.feed(19_950, &target);
    let mut app = app_with_params();
    let frame = rec.render(&mut app, 20_000, (80, 24));
    assert!(!frame.contains("the vehicle's live target"), "{frame}");
    assert!(frame.contains("setpoint: HOVER_ALT"), "{frame}");
    // The same target in AUTO is the vehicle's.
    rec.fly(20_000, 21_000, |_| (10, true, 0.0, 0.0, 0.3, 1.0));
    rec.feed(20_990, &target);
    let frame = rec.render(&mut app, 21_000, (80, 24));
    assert!(frame.contains("the vehicle's live target"), "{frame}");
}

/// A vehicle whose HEARTBEAT carries a MAV_TYPE newer than the dialect (60) is shown, and the
/// message inspector shows its HEARTBEAT with the number the dialect has no name for.
#[test]
fn a_mav_type_newer_than_the_dialect_is_shown_with_its_number() {
    let mut rec = Recording::new();
    for i in 0..5u64 {
        let mut p = [0u8; 9];
        p[..4].copy_from_slice(&18u32.to_le_bytes());
        p[4] = 60;
        p[5] = MavAutopilot::MAV_AUTOPILOT_ARDUPILOTMEGA as u8;
        p[6] = 0x81;
        p[7] = MavState::MAV_STATE_ACTIVE as u8;
        p[8] = 3;
        let frame = vtol_link::Frame::encode_payload_v2(
            vtol_link::SystemId(1),
            vtol_link::ComponentId(1),
            i as u8,
            0,
            &p,
        )
        .unwrap();
        rec.feed_frame(i * 1000, &frame);
    }
    let mut app = app_with_params();
    let frame = rec.render(&mut app, 4_000, (120, 40));
    assert!(
        frame.contains("sys 1"),
        "the vehicle is not shown:\n{frame}"
    );
    app.view = View::Messages;
    let state = rec.state.clone();
    rec.render(&mut app, 4_000, (120, 40));
    for k in "/heart".chars() {
        app.on_key(key(KeyCode::Char(k)), &state, rec.at(4_000));
    }
    app.on_key(key(KeyCode::Enter), &state, rec.at(4_000));
    let frame = rec.render(&mut app, 4_000, (120, 40));
    assert!(
        frame.contains("type = 60 (not in the dialect's MavType)"),
        "no wire value:\n{frame}"
    );
}
