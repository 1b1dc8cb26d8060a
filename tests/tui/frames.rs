//! Whole frames of the terminal UI rendered into ratatui's `TestBackend` from recorded vehicle
//! states (real MAVLink frames applied to the tracker at fixed times), compared with insta
//! snapshots: hover, armed climb, link lost, parameter edit, refused parameter, help overlay,
//! a terminal too small, and the charts, links and messages views.

use ratatui::crossterm::event::KeyCode;
use vtol_gcs::links::Side;
use vtol_gcs::tui::app::{App, Outcome, View};
use vtol_gcs::tui::view::{LinkRow, RouterCounters, Snapshot, TlogInfo};
use vtol_link::LinkStatsSnapshot;
use vtol_link::dialect::{self, MavMessage, MavState};

use crate::ui_support::recording::{
    OWN_LINK, Recording, VEHICLE_LINK, app_with, draw_snapshot, heartbeat, key, params_with,
};

fn links(rec: &Recording) -> Vec<LinkRow> {
    let vehicle = &rec.state.links[&VEHICLE_LINK];
    let own = &rec.state.links[&OWN_LINK];
    vec![
        LinkRow {
            id: VEHICLE_LINK,
            side: Side::Vehicle,
            peer: "embedded twin".into(),
            own: false,
            policy: None,
            stats: LinkStatsSnapshot {
                rx_frames: vehicle.frames,
                tx_frames: own.frames,
                ..Default::default()
            },
        },
        LinkRow {
            id: OWN_LINK,
            side: Side::Client,
            peer: vtol_gcs::daemon::OWN_TRAFFIC_PEER.into(),
            own: true,
            policy: None,
            stats: LinkStatsSnapshot {
                rx_frames: own.frames,
                tx_frames: vehicle.frames,
                ..Default::default()
            },
        },
    ]
}

fn render(app: &mut App, rec: &Recording, at_ms: u64, size: (u16, u16)) -> String {
    let snap = Snapshot {
        now: rec.at(at_ms),
        state: &rec.state,
        history: &rec.history,
        links: links(rec),
        router: RouterCounters {
            frames_in: 1234,
            frames_out: 1200,
            unroutable: 3,
            ..Default::default()
        },
        tlog: Some(TlogInfo {
            path: "logs/2026-11-23T11-00-00.tlog".into(),
            bytes: 123_456,
            records: 2345,
            dropped: 0,
            errors: 0,
            failing: None,
        }),
        serving: vec![
            "tcpin:127.0.0.1:5770".into(),
            "udpout:127.0.0.1:14550".into(),
        ],
    };
    draw_snapshot(app, &snap, size)
}

/// A UI with the twin's parameter table as the parameter frames show it: with all four
/// lateral saturation levels.
fn app_with_params() -> App {
    app_with(params_with(&[("LAT_SAT_C", 0.22), ("LAT_SAT_D", 0.18)]))
}

fn hover() -> Recording {
    let mut rec = Recording::with_own_traffic();
    rec.fly_hover();
    rec.status(
        5_000,
        dialect::MavSeverity::MAV_SEVERITY_INFO,
        "Mode QHOVER",
    );
    rec.status(
        6_000,
        dialect::MavSeverity::MAV_SEVERITY_WARNING,
        "push on roll 0.2 N.m",
    );
    rec
}

#[test]
fn hover_flight_view() {
    let rec = hover();
    let mut app = app_with_params();
    insta::assert_snapshot!(render(&mut app, &rec, 20_000, (100, 32)));
}

#[test]
fn armed_climb_flight_and_charts() {
    let mut rec = Recording::with_own_traffic();
    rec.fly(0, 4_000, |_| (18, false, 0.0, 0.0, 1.5, 0.0));
    rec.fly(4_000, 12_000, |t| {
        let alt = ((t - 4.0) / 6.0).min(1.0) as f32 * 0.8;
        (18, true, 0.02, -0.01, 1.5, alt)
    });
    let mut app = app_with_params();
    insta::assert_snapshot!(
        "armed_climb_flight",
        render(&mut app, &rec, 12_000, (100, 32))
    );
    app.view = View::Charts;
    insta::assert_snapshot!(
        "armed_climb_charts",
        render(&mut app, &rec, 12_000, (120, 40))
    );
}

#[test]
fn link_lost() {
    let rec = hover();
    let mut app = app_with_params();
    // Nothing since 20 s: at 27 s (last heartbeat at 19 s) the link is lost, rates read 0 and the attitude is stale.
    let frame = render(&mut app, &rec, 27_000, (100, 32));
    assert!(frame.contains("LINK LOST 8 s"), "{frame}");
    // No live figures: no link rate, and the flight clock stopped at the last heartbeat (19 s).
    let header = frame.lines().next().unwrap_or_default();
    assert!(!header.contains("Hz"), "{frame}");
    assert!(header.contains("flight 00:19"), "{frame}");
    assert!(frame.contains("STALE: attitude"), "{frame}");
    insta::assert_snapshot!(frame);
    app.view = View::Links;
    insta::assert_snapshot!(
        "link_lost_links_view",
        render(&mut app, &rec, 27_000, (100, 32))
    );
}

#[test]
fn parameter_edit_and_refusal() {
    let rec = hover();
    let mut app = app_with_params();
    app.view = View::Params;
    let state = rec.state.clone();
    let now = rec.at(20_000);
    // Filter to the lateral levels, pick LAT_SAT_B, type 0.7.
    for k in [
        KeyCode::Char('/'),
        KeyCode::Char('l'),
        KeyCode::Char('a'),
        KeyCode::Char('t'),
        KeyCode::Enter,
        KeyCode::Down,
        KeyCode::Enter,
    ] {
        assert!(app.on_key(key(k), &state, now).is_empty());
    }
    for c in "0.7".chars() {
        app.on_key(key(KeyCode::Char(c)), &state, now);
    }
    insta::assert_snapshot!(
        "parameter_edit_typing",
        render(&mut app, &rec, 20_000, (100, 30))
    );
    let reqs = app.on_key(key(KeyCode::Enter), &state, now);
    assert_eq!(
        reqs,
        [vtol_gcs::tui::app::Request::ParamSet {
            name: "LAT_SAT_B".into(),
            value: 0.7
        }]
    );
    insta::assert_snapshot!(
        "parameter_edit_sent",
        render(&mut app, &rec, 20_000, (100, 30))
    );
    app.on_outcome(Outcome::ParamSet {
        name: "LAT_SAT_B".into(),
        result: Err("LAT_SAT_B: saturation levels need a > b + c + d".into()),
    });
    insta::assert_snapshot!(
        "parameter_refused",
        render(&mut app, &rec, 20_000, (100, 30))
    );
    // A confirmed write shows the vehicle's value.
    app.on_outcome(Outcome::ParamSet {
        name: "LAT_SAT_A".into(),
        result: Ok(1.5),
    });
    insta::assert_snapshot!(
        "parameter_confirmed",
        render(&mut app, &rec, 20_000, (100, 30))
    );
}

#[test]
fn help_overlay() {
    let rec = hover();
    let mut app = app_with_params();
    app.on_key(key(KeyCode::Char('?')), &rec.state, rec.at(20_000));
    insta::assert_snapshot!(render(&mut app, &rec, 20_000, (100, 32)));
}

#[test]
fn tiny_terminal_says_so() {
    let rec = hover();
    let mut app = app_with_params();
    let frame = render(&mut app, &rec, 20_000, (40, 10));
    assert!(frame.contains("too small"), "{frame}");
    insta::assert_snapshot!(frame);
}

#[test]
fn messages_view_charts_array_elements() {
    let mut rec = hover();
    // SERVO_OUTPUT_RAW has no array, ATTITUDE_QUATERNION has `repr_offset_q[4]`.
    for i in 0..100u64 {
        let q = dialect::ATTITUDE_QUATERNION_DATA {
            repr_offset_q: [0.0, (i as f32) / 100.0, 0.0, 0.0],
            ..Default::default()
        };
        rec.feed(10_000 + i * 100, &MavMessage::ATTITUDE_QUATERNION(q));
    }
    let mut app = app_with_params();
    app.view = View::Messages;
    let state = rec.state.clone();
    let now = rec.at(20_000);
    // Draw once so the list is known, then filter to the quaternion and chart repr_offset_q[1].
    render(&mut app, &rec, 20_000, (120, 40));
    for k in [
        KeyCode::Char('/'),
        KeyCode::Char('q'),
        KeyCode::Char('u'),
        KeyCode::Char('a'),
        KeyCode::Enter,
    ] {
        app.on_key(key(k), &state, now);
    }
    render(&mut app, &rec, 20_000, (120, 40));
    app.on_key(key(KeyCode::Right), &state, now);
    let numeric = app.messages.listed_fields.clone();
    let idx = numeric
        .iter()
        .position(|p| p == "repr_offset_q[1]")
        .expect("array element listed");
    for _ in 0..idx {
        app.on_key(key(KeyCode::Down), &state, now);
    }
    app.on_key(key(KeyCode::Enter), &state, now);
    // A second series from another message on the same chart.
    app.on_key(key(KeyCode::Esc), &state, now);
    assert_eq!(app.messages.charts.len(), 1);
    assert_eq!(app.messages.charts[0][0].path, "repr_offset_q[1]");
    insta::assert_snapshot!(render(&mut app, &rec, 20_000, (120, 40)));
}

#[test]
fn qstabilize_in_the_air_asks_and_names_the_fall() {
    let mut rec = hover();
    rec.feed(
        19_990,
        &MavMessage::EXTENDED_SYS_STATE(dialect::EXTENDED_SYS_STATE_DATA {
            vtol_state: dialect::MavVtolState::MAV_VTOL_STATE_MC,
            landed_state: dialect::MavLandedState::MAV_LANDED_STATE_IN_AIR,
        }),
    );
    let mut app = app_with_params();
    let reqs = app.on_key(key(KeyCode::Char('s')), &rec.state, rec.at(20_000));
    assert!(reqs.is_empty(), "nothing sent before y: {reqs:?}");
    let frame = render(&mut app, &rec, 20_000, (80, 24));
    assert!(frame.contains("falls"), "{frame}");
    insta::assert_snapshot!(frame);
}

/// The vitals row from what a vehicle reports: battery (low, in yellow), GPS, home, a failed
/// sensor, and the reason for an EMERGENCY.
#[test]
fn vitals_row_battery_gps_home_and_the_reason_for_an_emergency() {
    let mut rec = hover();
    let mut voltages = [u16::MAX; 10];
    voltages[..3].copy_from_slice(&[3610, 3610, 3610]);
    rec.feed(
        19_900,
        &MavMessage::BATTERY_STATUS(dialect::BATTERY_STATUS_DATA {
            voltages,
            current_battery: 512,
            current_consumed: 1100,
            battery_remaining: 15,
            time_remaining: 95,
            charge_state: dialect::MavBatteryChargeState::MAV_BATTERY_CHARGE_STATE_LOW,
            ..Default::default()
        }),
    );
    rec.feed(
        19_900,
        &MavMessage::GPS_RAW_INT(dialect::GPS_RAW_INT_DATA {
            fix_type: dialect::GpsFixType::GPS_FIX_TYPE_3D_FIX,
            satellites_visible: 12,
            ..Default::default()
        }),
    );
    rec.feed(
        19_900,
        &MavMessage::HOME_POSITION(dialect::HOME_POSITION_DATA {
            x: -3.0,
            y: -3.0,
            ..Default::default()
        }),
    );
    use dialect::MavSysStatusSensor as S;
    let present = S::MAV_SYS_STATUS_SENSOR_3D_GYRO | S::MAV_SYS_STATUS_AHRS;
    rec.feed(
        19_900,
        &MavMessage::SYS_STATUS(dialect::SYS_STATUS_DATA {
            onboard_control_sensors_present: present,
            onboard_control_sensors_enabled: present,
            onboard_control_sensors_health: S::MAV_SYS_STATUS_SENSOR_3D_GYRO,
            voltage_battery: 10830,
            current_battery: 512,
            battery_remaining: 15,
            ..Default::default()
        }),
    );
    rec.status(
        19_950,
        dialect::MavSeverity::MAV_SEVERITY_CRITICAL,
        "Crash detected",
    );
    let MavMessage::HEARTBEAT(mut hb) = heartbeat(18, false) else {
        unreachable!()
    };
    hb.system_status = MavState::MAV_STATE_EMERGENCY;
    rec.feed(19_990, &MavMessage::HEARTBEAT(hb));
    let mut app = app_with_params();
    let frame = render(&mut app, &rec, 20_000, (80, 24));
    assert!(frame.contains("EMERGENCY"), "{frame}");
    assert!(frame.contains("why: Crash detected"), "{frame}");
    assert!(frame.contains("BAT 10.8V 15% 5.1A 1:35"), "{frame}");
    assert!(frame.contains("home 4.3 m 044°"), "{frame}");
    assert!(frame.contains("bad: EKF"), "{frame}");
    insta::assert_snapshot!(frame);
}

/// QLOITER holds where it was entered: the Flight view shows that point as the setpoint on
/// every axis (not "-").
#[test]
fn qloiter_shows_the_entry_point_as_its_target() {
    let mut rec = Recording::with_own_traffic();
    rec.fly(0, 5_000, |_| (18, true, 0.0, 0.0, 0.3, 1.0));
    let mut app = app_with_params();
    render(&mut app, &rec, 5_000, (80, 24));
    rec.fly(5_000, 8_000, |_| (19, true, 0.0, 0.0, 0.3, 1.2));
    let frame = render(&mut app, &rec, 8_000, (80, 24));
    assert!(
        frame.contains("North   +0.05 m  setpoint   +0.05 m"),
        "{frame}"
    );
    assert!(
        frame.contains("East    -0.02 m  setpoint   -0.02 m"),
        "{frame}"
    );
    assert!(
        frame.contains("Alt     +1.20 m  setpoint   +1.20 m"),
        "{frame}"
    );
    insta::assert_snapshot!(frame);
}

fn param_value(name: &str, value: f32) -> MavMessage {
    let mut p = dialect::PARAM_VALUE_DATA {
        param_value: value,
        param_type: dialect::MavParamType::MAV_PARAM_TYPE_REAL32,
        param_count: 11,
        param_index: 10,
        ..Default::default()
    };
    p.param_id = name.into();
    MavMessage::PARAM_VALUE(p)
}

/// The table follows the vehicle's last word: a push confirmed at 0.1 that the vehicle resets
/// to 0 shows 0 and no "confirmed"; a value typed wrong here is "not sent" (nothing went out)
/// until the vehicle's next value for it.
#[test]
fn a_parameter_follows_the_vehicles_last_word() {
    let mut rec = hover();
    let mut app = app_with_params();
    app.view = View::Params;
    app.on_outcome(Outcome::ParamSet {
        name: "SIM_PUSH_ROLL".into(),
        result: Ok(0.1),
    });
    let state = rec.state.clone();
    let now = rec.at(20_000);
    // HOVER_ALT is the first row: type a word into it.
    for k in [KeyCode::Enter, KeyCode::Char('x'), KeyCode::Enter] {
        assert!(app.on_key(key(k), &state, now).is_empty());
    }
    let frame = render(&mut app, &rec, 20_000, (80, 24));
    assert!(frame.contains("not sent"), "{frame}");
    rec.feed(20_100, &param_value("SIM_PUSH_ROLL", 0.0));
    render(&mut app, &rec, 20_200, (80, 24));
    rec.feed(20_300, &param_value("HOVER_ALT", 1.0));
    let frame = render(&mut app, &rec, 20_400, (80, 24));
    assert_eq!(app.params.value("SIM_PUSH_ROLL"), Some(0.0));
    assert!(app.params.status.is_empty(), "{:?}", app.params.status);
    assert!(
        !frame.contains("confirmed") && !frame.contains("not sent"),
        "{frame}"
    );
    insta::assert_snapshot!(frame);
}

/// Every view at the smallest size the UI supports (80×24) keeps whole column titles.
#[test]
fn every_view_at_80_by_24() {
    let rec = hover();
    let mut app = app_with_params();
    for (view, name, titles) in [
        (View::Charts, "charts_80x24", &["Roll", "Position"][..]),
        (
            View::Links,
            "links_80x24",
            &["side", "peer", "Hz", "loss%", "heard", "drop", "crc"][..],
        ),
        (View::Messages, "messages_80x24", &["message", "Hz"][..]),
    ] {
        app.view = view;
        let frame = render(&mut app, &rec, 20_000, (80, 24));
        for t in titles {
            assert!(frame.contains(t), "{name}: no {t:?}\n{frame}");
        }
        insta::assert_snapshot!(name, frame);
    }
}
