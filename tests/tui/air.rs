//! What the vehicle flies through and to, from standard messages fed to the tracker: airspeed
//! (VFR_HUD), angle of attack and sideslip (AOA_SSA), the VTOL state (EXTENDED_SYS_STATE) and a
//! transition's progress in the header and the Flight view; the live target
//! (POSITION_TARGET_GLOBAL_INT / _LOCAL_NED) as the setpoint in every mode that sends one.

use crate::ui_support::recording::{Recording, app_with_params};
use vtol_link::dialect::{self, MavFrame, MavMessage, MavVtolState, PositionTargetTypemask};

/// 1e-7 degree of latitude in metres (ArduPilot's scaling).
const M_PER_E7: f64 = 0.011_131_884_502_145_034;
const HOME_LAT: i32 = 473_977_420;
const HOME_LON: i32 = 85_455_940;
const HOME_ALT_MM: i32 = 488_000;

/// A flight in `mode` for 5 s at 1 m, home at the local origin.
fn flight(mode: u32) -> Recording {
    let mut rec = Recording::new();
    // Upright in a Q mode, level on the wing in the others.
    if mode >= 17 {
        rec.fly(0, 5_000, |_| (mode, true, 0.0, 0.0, 0.0, 1.0));
    } else {
        rec.fly_wing(0, 5_000, |_| (mode, true, 0.0, 0.0, 0.0, 1.0));
    }
    rec.feed(
        4_900,
        &MavMessage::HOME_POSITION(dialect::HOME_POSITION_DATA {
            latitude: HOME_LAT,
            longitude: HOME_LON,
            altitude: HOME_ALT_MM,
            ..Default::default()
        }),
    );
    rec
}

fn global_target(north_m: f64, east_m: f64, alt: f32, frame: MavFrame) -> MavMessage {
    use PositionTargetTypemask as M;
    let lat = HOME_LAT + (north_m / M_PER_E7).round() as i32;
    let scale = (f64::from(HOME_LAT) * 1e-7).to_radians().cos();
    let lon = HOME_LON + (east_m / (M_PER_E7 * scale)).round() as i32;
    MavMessage::POSITION_TARGET_GLOBAL_INT(dialect::POSITION_TARGET_GLOBAL_INT_DATA {
        lat_int: lat,
        lon_int: lon,
        alt,
        type_mask: M::all()
            - (M::POSITION_TARGET_TYPEMASK_X_IGNORE
                | M::POSITION_TARGET_TYPEMASK_Y_IGNORE
                | M::POSITION_TARGET_TYPEMASK_Z_IGNORE),
        coordinate_frame: frame,
        ..Default::default()
    })
}

/// AUTO, RTL and QRTL with ArduPlane's POSITION_TARGET_GLOBAL_INT (AMSL or relative to home),
/// GUIDED with a POSITION_TARGET_LOCAL_NED: the setpoint is the vehicle's target, in metres
/// north, east and up of the local origin.
#[test]
fn the_live_target_is_the_setpoint_in_every_mode_that_sends_one() {
    let amsl = |up: f32| (f64::from(HOME_ALT_MM) / 1000.0) as f32 + up;
    let cases: [(u32, &str, MavMessage, [&str; 3]); 4] = [
        (
            10,
            "AUTO",
            global_target(20.0, -10.0, amsl(15.0), MavFrame::MAV_FRAME_GLOBAL),
            ["+15.00", "+20.00", "-10.00"],
        ),
        (
            11,
            "RTL",
            global_target(0.0, 0.0, 25.0, MavFrame::MAV_FRAME_GLOBAL_RELATIVE_ALT),
            ["+25.00", "+0.00", "+0.00"],
        ),
        (
            21,
            "QRTL",
            global_target(-3.5, 4.0, amsl(2.0), MavFrame::MAV_FRAME_GLOBAL),
            ["+2.00", "-3.50", "+4.00"],
        ),
        (
            15,
            "GUIDED",
            MavMessage::POSITION_TARGET_LOCAL_NED(dialect::POSITION_TARGET_LOCAL_NED_DATA {
                x: 7.0,
                y: 2.5,
                z: -3.0,
                coordinate_frame: MavFrame::MAV_FRAME_LOCAL_NED,
                type_mask: PositionTargetTypemask::POSITION_TARGET_TYPEMASK_VX_IGNORE,
                ..Default::default()
            }),
            ["+3.00", "+7.00", "+2.50"],
        ),
    ];
    for (mode, name, msg, [alt, north, east]) in cases {
        let mut rec = flight(mode);
        rec.feed(4_950, &msg);
        let mut app = app_with_params();
        let frame = rec.render(&mut app, 5_000, (80, 24));
        assert!(frame.contains(name), "{frame}");
        for (axis, want) in [("Alt  ", alt), ("North", north), ("East ", east)] {
            let line = frame
                .lines()
                .find(|l| l.contains(axis) && l.contains("setpoint"))
                .unwrap_or_default();
            assert!(
                line.contains(&format!("setpoint {want:>7} m")),
                "{name} {axis}: {want}\n{frame}"
            );
        }
        assert!(frame.contains("the vehicle's live target"), "{frame}");
        if name == "AUTO" {
            insta::assert_snapshot!("live_target_auto", frame);
        }
        // Three seconds after the last one the target is no longer the vehicle's.
        rec.fly(5_000, 8_100, move |_| (mode, true, 0.0, 0.0, 0.0, 1.0));
        let frame = rec.render(&mut app, 8_100, (80, 24));
        assert!(!frame.contains("the vehicle's live target"), "{frame}");
    }
}

/// A target in body axes or as an offset is no point in the local frame: not shown.
#[test]
fn a_target_relative_to_the_vehicle_is_not_a_setpoint() {
    let mut rec = flight(15);
    rec.feed(
        4_950,
        &MavMessage::POSITION_TARGET_LOCAL_NED(dialect::POSITION_TARGET_LOCAL_NED_DATA {
            x: 7.0,
            coordinate_frame: MavFrame::MAV_FRAME_BODY_FRD,
            ..Default::default()
        }),
    );
    let mut app = app_with_params();
    let frame = rec.render(&mut app, 5_000, (80, 24));
    assert!(!frame.contains("the vehicle's live target"), "{frame}");
    assert!(!frame.contains("+7.00"), "{frame}");
}

fn ext_state(s: MavVtolState) -> MavMessage {
    MavMessage::EXTENDED_SYS_STATE(dialect::EXTENDED_SYS_STATE_DATA {
        vtol_state: s,
        landed_state: dialect::MavLandedState::MAV_LANDED_STATE_IN_AIR,
    })
}

fn hud(airspeed: f32) -> MavMessage {
    MavMessage::VFR_HUD(dialect::VFR_HUD_DATA {
        airspeed,
        groundspeed: airspeed,
        ..Default::default()
    })
}

/// ATTITUDE at roll, pitch, yaw in degrees, no rates.
fn attitude(roll: f32, pitch: f32, yaw: f32) -> MavMessage {
    MavMessage::ATTITUDE(dialect::ATTITUDE_DATA {
        roll: roll.to_radians(),
        pitch: pitch.to_radians(),
        yaw: yaw.to_radians(),
        ..Default::default()
    })
}

/// AHRS2 at roll, pitch, yaw in degrees: ArduPilot's secondary estimate, in the wing frame.
fn ahrs2(roll: f32, pitch: f32, yaw: f32) -> MavMessage {
    MavMessage::AHRS2(dialect::AHRS2_DATA {
        roll: roll.to_radians(),
        pitch: pitch.to_radians(),
        yaw: yaw.to_radians(),
        ..Default::default()
    })
}

/// The Flight view's roll, pitch and yaw readouts.
fn readouts(frame: &str) -> Vec<String> {
    ["Roll", "Pitch", "Yaw"]
        .iter()
        .map(|k| {
            let line = frame
                .lines()
                .find(|l| l.contains(&format!("│{k} ")))
                .unwrap_or_default();
            let at = line.find(&format!("│{k} ")).unwrap_or(0);
            line[at..]
                .split_whitespace()
                .nth(1)
                .unwrap_or_default()
                .to_owned()
        })
        .collect()
}

/// ArduPlane SITL's tailsitter standing on its tail, as it reported it: ATTITUDE roll 110.6°
/// pitch 90° yaw 97.6° in a fixed-wing mode (the wing frame), roll 0° pitch 0° yaw −13° in a
/// Q mode (its VTOL view), AHRS2 in the wing frame throughout. Shown in the hover frame either
/// way: upright, heading 347°; and so is a wing-frame ATTITUDE in a Q mode when AHRS2 says it
/// is one (as on SITL's first boot, before its VTOL view is set up).
#[test]
fn a_hover_reads_the_same_whichever_frame_the_attitude_comes_in() {
    let cases = [
        (
            "VTOL view, AHRS2",
            attitude(0.0, 0.0, -13.0),
            Some(ahrs2(110.6, 89.99, 97.6)),
        ),
        ("VTOL view alone", attitude(0.0, 0.0, -13.0), None),
        (
            "wing frame, AHRS2",
            attitude(110.6, 89.99, 97.6),
            Some(ahrs2(110.6, 89.99, 97.6)),
        ),
    ];
    for (what, att, ahrs) in cases {
        let mut rec = flight(17);
        rec.feed(4_960, &ext_state(MavVtolState::MAV_VTOL_STATE_MC));
        if let Some(a) = &ahrs {
            rec.feed(4_970, a);
        }
        rec.feed(4_980, &att);
        let mut app = app_with_params();
        let frame = rec.render(&mut app, 5_000, (80, 24));
        assert!(frame.contains("(hover frame)"), "{what}:\n{frame}");
        let r = readouts(&frame);
        let deg = |s: &str| s.trim_end_matches('°').parse::<f32>().unwrap_or(f32::NAN);
        assert!(
            deg(&r[0]).abs() < 0.5 && deg(&r[1]).abs() < 0.5,
            "{what}: {r:?}\n{frame}"
        );
        assert!((deg(&r[2]) + 13.0).abs() < 0.5, "{what}: {r:?}\n{frame}");
    }
}

fn aoa(aoa: f32, ssa: f32) -> MavMessage {
    MavMessage::AOA_SSA(dialect::AOA_SSA_DATA {
        time_usec: 0,
        AOA: aoa,
        SSA: ssa,
    })
}

/// A forward transition at 6 m/s of ARSPD_FBW_MIN's 10 is 60 % through; forward flight shows
/// its airspeed and angle of attack; a back transition with the nose 45° from vertical is half
/// way; with none of these messages every figure reads "-".
#[test]
fn airspeed_angle_of_attack_vtol_state_and_transition_progress() {
    let mut rec = flight(10);
    rec.feed(4_960, &hud(6.0));
    rec.feed(4_960, &aoa(8.5, -1.2));
    rec.feed(
        4_960,
        &ext_state(MavVtolState::MAV_VTOL_STATE_TRANSITION_TO_FW),
    );
    // Pitched 45° toward the belly, in ArduPlane's VTOL view (its ATTITUDE in a forward
    // transition).
    rec.feed(4_980, &attitude(0.0, -45.0, 0.0));
    let mut app = app_with_params();
    let frame = rec.render(&mut app, 5_000, (80, 24));
    assert!(
        frame.contains("→FW 60% air 6.0 m/s AoA +8.5°"),
        "header:\n{frame}"
    );
    assert!(
        frame.contains("Air     6.0 m/s  AoA  +8.5°  SSA  -1.2°"),
        "{frame}"
    );
    assert!(
        frame.contains("VTOL  →FW  transition  60% (of 10 m/s)"),
        "{frame}"
    );
    insta::assert_snapshot!("forward_transition", frame);

    rec.feed(4_970, &hud(14.2));
    rec.feed(4_970, &aoa(3.1, 0.4));
    rec.feed(4_970, &ext_state(MavVtolState::MAV_VTOL_STATE_FW));
    let frame = rec.render(&mut app, 5_000, (80, 24));
    assert!(frame.contains("FW air 14.2 m/s AoA +3.1°"), "{frame}");
    assert!(frame.contains("VTOL  FW"), "{frame}");
    assert!(!frame.contains("transition"), "{frame}");

    // Back transition: the nose 45° above the horizon, half way from level to upright (pitch
    // in the wing frame, as ArduPlane reports it).
    rec.fly_wing(5_000, 6_000, |_| {
        (18, true, 0.0, std::f32::consts::FRAC_PI_4, 0.0, 1.0)
    });
    rec.feed(
        5_990,
        &ext_state(MavVtolState::MAV_VTOL_STATE_TRANSITION_TO_MC),
    );
    let frame = rec.render(&mut app, 6_000, (80, 24));
    assert!(frame.contains("→MC 50%"), "{frame}");
    assert!(
        frame.contains("VTOL  →MC  transition  50% (nose up)"),
        "{frame}"
    );
    insta::assert_snapshot!("back_transition", frame);

    // A transition past ARSPD_FBW_MIN reads 100 %, not more; another ARSPD_FBW_MIN counts.
    let mut rec = flight(10);
    rec.feed(4_960, &hud(12.0));
    rec.feed(
        4_960,
        &ext_state(MavVtolState::MAV_VTOL_STATE_TRANSITION_TO_FW),
    );
    let frame = rec.render(&mut app, 5_000, (80, 24));
    assert!(frame.contains("→FW 100%"), "{frame}");
    app.on_outcome(vtol_gcs::tui::app::Outcome::ParamSet {
        name: "ARSPD_FBW_MIN".into(),
        result: Ok(16.0),
    });
    let frame = rec.render(&mut app, 5_000, (80, 24));
    assert!(frame.contains("→FW 75%"), "{frame}");

    // Hovering in still air: the angle of attack is the wind's noise, shown as "-".
    let mut rec = flight(18);
    rec.feed(4_960, &hud(0.4));
    rec.feed(4_960, &aoa(87.0, -40.0));
    rec.feed(4_960, &ext_state(MavVtolState::MAV_VTOL_STATE_MC));
    let frame = rec.render(&mut app, 5_000, (80, 24));
    assert!(frame.contains("MC air 0.4 m/s AoA -"), "{frame}");
    assert!(
        frame.contains("Air     0.4 m/s  AoA      -  SSA      -"),
        "{frame}"
    );

    // Nothing reported: "-" everywhere.
    let rec = flight(18);
    let frame = rec.render(&mut app, 5_000, (80, 24));
    assert!(frame.contains("VTOL - air - AoA -"), "{frame}");
    assert!(
        frame.contains("Air       - m/s  AoA      -  SSA      -"),
        "{frame}"
    );
    assert!(frame.contains("VTOL  -"), "{frame}");
}
