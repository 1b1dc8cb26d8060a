//! Any autopilot's identity and flight modes, from what its HEARTBEAT says: `autopilot`
//! (MAV_AUTOPILOT), `type` (MAV_TYPE) and `custom_mode`.
//!
//! - PX4 (`MAV_AUTOPILOT_PX4`): `custom_mode` holds the main mode in bits 16–23 and the sub
//!   mode in bits 24–31 (PX4's `px4_custom_mode`); names as pymavlink's `px4_map`.
//! - Every other autopilot: ArduPilot's mode numbers, the table chosen by MAV_TYPE as
//!   pymavlink's `mode_mapping_bynumber` chooses it (Plane with its QuadPlane Q modes, Copter,
//!   Rover and boats, Sub, AntennaTracker, Blimp).
//! - No table for the vehicle (an unknown MAV_TYPE, a type the dialect does not know): the mode
//!   reads `MODE(n)`, and the vehicle stays listed.
//!
//! The numbers are raw `u8`/`u32` so a heartbeat whose enums the dialect lacks still names its
//! mode.

/// MAV_AUTOPILOT_ARDUPILOTMEGA.
pub const AUTOPILOT_ARDUPILOT: u8 = 3;
/// MAV_AUTOPILOT_PX4.
pub const AUTOPILOT_PX4: u8 = 12;
/// MAV_AUTOPILOT_INVALID: not a flight controller (ground stations, peripherals).
pub const AUTOPILOT_INVALID: u8 = 8;

/// ArduPlane, QuadPlane's Q modes included (pymavlink's `mode_mapping_apm`).
pub const PLANE: &[(&str, u32)] = &[
    ("MANUAL", 0),
    ("CIRCLE", 1),
    ("STABILIZE", 2),
    ("TRAINING", 3),
    ("ACRO", 4),
    ("FBWA", 5),
    ("FBWB", 6),
    ("CRUISE", 7),
    ("AUTOTUNE", 8),
    ("AUTO", 10),
    ("RTL", 11),
    ("LOITER", 12),
    ("TAKEOFF", 13),
    ("AVOID_ADSB", 14),
    ("GUIDED", 15),
    ("INITIALISING", 16),
    ("QSTABILIZE", 17),
    ("QHOVER", 18),
    ("QLOITER", 19),
    ("QLAND", 20),
    ("QRTL", 21),
    ("QAUTOTUNE", 22),
    ("QACRO", 23),
    ("THERMAL", 24),
    ("LOITERALTQLAND", 25),
    ("AUTOLAND", 26),
];

/// ArduCopter and TradHeli (pymavlink's `mode_mapping_acm`).
pub const COPTER: &[(&str, u32)] = &[
    ("STABILIZE", 0),
    ("ACRO", 1),
    ("ALT_HOLD", 2),
    ("AUTO", 3),
    ("GUIDED", 4),
    ("LOITER", 5),
    ("RTL", 6),
    ("CIRCLE", 7),
    ("POSITION", 8),
    ("LAND", 9),
    ("OF_LOITER", 10),
    ("DRIFT", 11),
    ("SPORT", 13),
    ("FLIP", 14),
    ("AUTOTUNE", 15),
    ("POSHOLD", 16),
    ("BRAKE", 17),
    ("THROW", 18),
    ("AVOID_ADSB", 19),
    ("GUIDED_NOGPS", 20),
    ("SMART_RTL", 21),
    ("FLOWHOLD", 22),
    ("FOLLOW", 23),
    ("ZIGZAG", 24),
    ("SYSTEMID", 25),
    ("AUTOROTATE", 26),
    ("AUTO_RTL", 27),
    ("TURTLE", 28),
    ("RATE_ACRO", 29),
];

/// ArduRover, for rovers and boats (pymavlink's `mode_mapping_rover`).
pub const ROVER: &[(&str, u32)] = &[
    ("MANUAL", 0),
    ("ACRO", 1),
    ("LEARNING", 2),
    ("STEERING", 3),
    ("HOLD", 4),
    ("LOITER", 5),
    ("FOLLOW", 6),
    ("SIMPLE", 7),
    ("DOCK", 8),
    ("CIRCLE", 9),
    ("AUTO", 10),
    ("RTL", 11),
    ("SMART_RTL", 12),
    ("GUIDED", 15),
    ("INITIALISING", 16),
];

/// ArduSub (pymavlink's `mode_mapping_sub`, and ArduSub's motor detection and surface
/// tracking).
pub const SUB: &[(&str, u32)] = &[
    ("STABILIZE", 0),
    ("ACRO", 1),
    ("ALT_HOLD", 2),
    ("AUTO", 3),
    ("GUIDED", 4),
    ("CIRCLE", 7),
    ("SURFACE", 9),
    ("POSHOLD", 16),
    ("MANUAL", 19),
    ("MOTOR_DETECT", 20),
    ("SURFTRAK", 21),
];

/// AntennaTracker (pymavlink's `mode_mapping_tracker`).
pub const TRACKER: &[(&str, u32)] = &[
    ("MANUAL", 0),
    ("STOP", 1),
    ("SCAN", 2),
    ("GUIDED", 4),
    ("AUTO", 10),
    ("INITIALISING", 16),
];

/// Blimp (pymavlink's `mode_mapping_blimp`).
pub const BLIMP: &[(&str, u32)] = &[
    ("LAND", 0),
    ("MANUAL", 1),
    ("VELOCITY", 2),
    ("LOITER", 3),
    ("RTL", 4),
    ("AUTO", 5),
    ("HOLD", 6),
];

/// A PX4 `custom_mode` from its main and sub mode.
#[must_use]
pub const fn px4_custom_mode(main: u8, sub: u8) -> u32 {
    ((main as u32) << 16) | ((sub as u32) << 24)
}

/// PX4's main mode (bits 16–23 of `custom_mode`).
#[must_use]
pub const fn px4_main_mode(custom_mode: u32) -> u8 {
    ((custom_mode >> 16) & 0xff) as u8
}

/// PX4's sub mode (bits 24–31 of `custom_mode`).
#[must_use]
pub const fn px4_sub_mode(custom_mode: u32) -> u8 {
    (custom_mode >> 24) as u8
}

const PX4_MANUAL: u8 = 1;
const PX4_ALTCTL: u8 = 2;
const PX4_POSCTL: u8 = 3;
const PX4_AUTO: u8 = 4;
const PX4_ACRO: u8 = 5;
const PX4_OFFBOARD: u8 = 6;
const PX4_STABILIZED: u8 = 7;
const PX4_RATTITUDE: u8 = 8;

/// PX4's modes as pymavlink's `px4_map` names them, with the `custom_mode` that selects each
/// (main mode, and the sub mode for the AUTO modes).
pub const PX4: &[(&str, u32)] = &[
    ("MANUAL", px4_custom_mode(PX4_MANUAL, 0)),
    ("STABILIZED", px4_custom_mode(PX4_STABILIZED, 0)),
    ("ACRO", px4_custom_mode(PX4_ACRO, 0)),
    ("RATTITUDE", px4_custom_mode(PX4_RATTITUDE, 0)),
    ("ALTCTL", px4_custom_mode(PX4_ALTCTL, 0)),
    ("POSCTL", px4_custom_mode(PX4_POSCTL, 0)),
    ("LOITER", px4_custom_mode(PX4_AUTO, 3)),
    ("MISSION", px4_custom_mode(PX4_AUTO, 4)),
    ("RTL", px4_custom_mode(PX4_AUTO, 5)),
    ("LAND", px4_custom_mode(PX4_AUTO, 6)),
    ("RTGS", px4_custom_mode(PX4_AUTO, 7)),
    ("FOLLOWME", px4_custom_mode(PX4_AUTO, 8)),
    ("OFFBOARD", px4_custom_mode(PX4_OFFBOARD, 0)),
    ("TAKEOFF", px4_custom_mode(PX4_AUTO, 2)),
];

/// The ArduPilot mode table for a MAV_TYPE, as pymavlink's `mode_mapping_bynumber` (with the
/// VTOL types QuadPlane reports in newer firmware read as Plane too).
fn ardupilot_table(mav_type: u8) -> &'static [(&'static str, u32)] {
    match mav_type {
        // HELICOPTER, TRICOPTER, QUADROTOR, HEXAROTOR, OCTOROTOR, DECAROTOR, DODECAROTOR, COAXIAL
        2 | 3 | 4 | 13 | 14 | 15 | 29 | 35 => COPTER,
        // FIXED_WING, VTOL_TAILSITTER_DUOROTOR, VTOL_TAILSITTER_QUADROTOR, VTOL_TILTROTOR,
        // VTOL_FIXEDROTOR, VTOL_TAILSITTER, VTOL_TILTWING
        1 | 19..=24 => PLANE,
        // GROUND_ROVER, SURFACE_BOAT
        10 | 11 => ROVER,
        5 => TRACKER,
        12 => SUB,
        7 => BLIMP,
        _ => &[],
    }
}

/// Every mode the vehicle has, by name, with the `custom_mode` number that selects it: the
/// table a mode picker offers. Empty when the vehicle's modes are not known.
#[must_use]
pub fn modes_for(autopilot: u8, mav_type: u8) -> &'static [(&'static str, u32)] {
    match autopilot {
        AUTOPILOT_PX4 => PX4,
        AUTOPILOT_INVALID => &[],
        _ => ardupilot_table(mav_type),
    }
}

/// The mode's name for this vehicle (`QHOVER`, `LOITER`, `POSCTL`), or `MODE(n)` when the
/// vehicle's table does not name it.
#[must_use]
pub fn mode_name(autopilot: u8, mav_type: u8, custom_mode: u32) -> String {
    let known = if autopilot == AUTOPILOT_PX4 {
        px4_mode_name(custom_mode)
    } else {
        modes_for(autopilot, mav_type)
            .iter()
            .find(|(_, n)| *n == custom_mode)
            .map(|(name, _)| *name)
    };
    known.map_or_else(|| format!("MODE({custom_mode})"), str::to_owned)
}

/// PX4's mode from the main mode, and the sub mode for AUTO (pymavlink's
/// `interpret_px4_mode`).
fn px4_mode_name(custom_mode: u32) -> Option<&'static str> {
    let main = px4_main_mode(custom_mode);
    let sub = px4_sub_mode(custom_mode);
    let wanted = if main == PX4_AUTO {
        px4_custom_mode(main, sub)
    } else {
        px4_custom_mode(main, 0)
    };
    PX4.iter()
        .find(|(_, n)| *n == wanted)
        .map(|(name, _)| *name)
}

/// The `custom_mode` that selects the named mode (any case) on this vehicle: ArduPilot's
/// mode number, or PX4's main and sub mode packed as in its heartbeat. `MODE(n)` names `n`.
#[must_use]
pub fn mode_number(autopilot: u8, mav_type: u8, name: &str) -> Option<u32> {
    let name = name.trim();
    if let Some(found) = modes_for(autopilot, mav_type)
        .iter()
        .find(|(n, _)| n.eq_ignore_ascii_case(name))
    {
        return Some(found.1);
    }
    let upper = name.to_ascii_uppercase();
    upper
        .strip_prefix("MODE(")
        .and_then(|rest| rest.strip_suffix(')'))
        .and_then(|n| n.parse().ok())
}

/// What the vehicle is, for a header or a list: `ArduPlane`, `ArduCopter`, `PX4 quadrotor`,
/// or the raw numbers when the dialect does not name them (`autopilot 3 type 60`).
#[must_use]
pub fn vehicle_name(autopilot: u8, mav_type: u8) -> String {
    let kind = match mav_type {
        1 => Some("fixed wing"),
        2 => Some("quadrotor"),
        3 => Some("coaxial"),
        4 => Some("helicopter"),
        5 => Some("antenna tracker"),
        6 => Some("ground station"),
        7 => Some("airship"),
        10 => Some("rover"),
        11 => Some("boat"),
        12 => Some("submarine"),
        13 => Some("hexarotor"),
        14 => Some("octorotor"),
        15 => Some("tricopter"),
        19..=24 => Some("VTOL"),
        29 => Some("dodecarotor"),
        35 => Some("decarotor"),
        _ => None,
    };
    match autopilot {
        AUTOPILOT_ARDUPILOT => {
            let table = ardupilot_table(mav_type);
            let firmware = if std::ptr::eq(table, PLANE) {
                "ArduPlane"
            } else if std::ptr::eq(table, COPTER) {
                "ArduCopter"
            } else if std::ptr::eq(table, ROVER) {
                "ArduRover"
            } else if std::ptr::eq(table, SUB) {
                "ArduSub"
            } else if std::ptr::eq(table, TRACKER) {
                "AntennaTracker"
            } else if std::ptr::eq(table, BLIMP) {
                "Blimp"
            } else {
                return format!("ArduPilot type {mav_type}");
            };
            firmware.to_owned()
        }
        AUTOPILOT_PX4 => {
            kind.map_or_else(|| format!("PX4 type {mav_type}"), |k| format!("PX4 {k}"))
        }
        _ => match kind {
            Some(k) => format!("{k} (autopilot {autopilot})"),
            None => format!("autopilot {autopilot} type {mav_type}"),
        },
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const QUADROTOR: u8 = 2;
    const FIXED_WING: u8 = 1;

    #[test]
    fn arducopter_heartbeats_read_copter_modes() {
        assert_eq!(mode_name(AUTOPILOT_ARDUPILOT, QUADROTOR, 5), "LOITER");
        assert_eq!(mode_name(AUTOPILOT_ARDUPILOT, QUADROTOR, 0), "STABILIZE");
        assert_eq!(mode_name(AUTOPILOT_ARDUPILOT, QUADROTOR, 4), "GUIDED");
        assert_eq!(mode_name(AUTOPILOT_ARDUPILOT, 4, 2), "ALT_HOLD");
        assert_eq!(vehicle_name(AUTOPILOT_ARDUPILOT, QUADROTOR), "ArduCopter");
    }

    #[test]
    fn arduplane_and_quadplane_modes() {
        assert_eq!(mode_name(AUTOPILOT_ARDUPILOT, FIXED_WING, 18), "QHOVER");
        assert_eq!(mode_name(AUTOPILOT_ARDUPILOT, FIXED_WING, 5), "FBWA");
        // QuadPlane's VTOL types, old and new.
        for ty in [19, 20, 21, 22] {
            assert_eq!(mode_name(AUTOPILOT_ARDUPILOT, ty, 20), "QLAND");
        }
        assert_eq!(vehicle_name(AUTOPILOT_ARDUPILOT, 21), "ArduPlane");
    }

    #[test]
    fn rover_sub_tracker_blimp() {
        assert_eq!(mode_name(AUTOPILOT_ARDUPILOT, 10, 4), "HOLD");
        assert_eq!(mode_name(AUTOPILOT_ARDUPILOT, 11, 10), "AUTO");
        assert_eq!(mode_name(AUTOPILOT_ARDUPILOT, 12, 19), "MANUAL");
        assert_eq!(mode_name(AUTOPILOT_ARDUPILOT, 5, 2), "SCAN");
        assert_eq!(mode_name(AUTOPILOT_ARDUPILOT, 7, 2), "VELOCITY");
    }

    #[test]
    fn px4_main_and_sub_modes() {
        // 196609 = 0x0003_0001: main mode 3 (POSCTL); the low 16 bits are reserved.
        assert_eq!(mode_name(AUTOPILOT_PX4, QUADROTOR, 196_609), "POSCTL");
        assert_eq!(mode_name(AUTOPILOT_PX4, QUADROTOR, 65_536), "MANUAL");
        // AUTO (4) with sub modes: 4 MISSION, 5 RTL, 3 LOITER.
        assert_eq!(mode_name(AUTOPILOT_PX4, QUADROTOR, 0x0404_0000), "MISSION");
        assert_eq!(mode_name(AUTOPILOT_PX4, QUADROTOR, 0x0504_0000), "RTL");
        assert_eq!(mode_name(AUTOPILOT_PX4, FIXED_WING, 0x0304_0000), "LOITER");
        assert_eq!(
            mode_name(AUTOPILOT_PX4, FIXED_WING, 0x0006_0000),
            "OFFBOARD"
        );
        // An AUTO sub mode PX4's table lacks, and a main mode it lacks.
        assert_eq!(
            mode_name(AUTOPILOT_PX4, QUADROTOR, 0x6304_0000),
            "MODE(1661206528)"
        );
        assert_eq!(
            mode_name(AUTOPILOT_PX4, QUADROTOR, 0x0063_0000),
            "MODE(6488064)"
        );
        assert_eq!(
            mode_number(AUTOPILOT_PX4, QUADROTOR, "mission"),
            Some(0x0404_0000)
        );
        assert_eq!(
            mode_number(AUTOPILOT_PX4, QUADROTOR, "POSCTL"),
            Some(196_608)
        );
        assert_eq!(vehicle_name(AUTOPILOT_PX4, QUADROTOR), "PX4 quadrotor");
    }

    #[test]
    fn every_px4_mode_reads_back_its_own_name() {
        for (name, number) in PX4 {
            assert_eq!(mode_name(AUTOPILOT_PX4, 2, *number), *name);
        }
    }

    #[test]
    fn names_are_unique_and_read_back_in_every_table() {
        for table in [PLANE, COPTER, ROVER, SUB, TRACKER, BLIMP, PX4] {
            for (i, (name, number)) in table.iter().enumerate() {
                assert!(table[i + 1..].iter().all(|(n, m)| n != name && m != number));
            }
        }
        for ty in [1, 2, 5, 7, 10, 12] {
            for (name, number) in modes_for(AUTOPILOT_ARDUPILOT, ty) {
                assert_eq!(mode_name(AUTOPILOT_ARDUPILOT, ty, *number), *name);
                let lower = name.to_ascii_lowercase();
                assert_eq!(mode_number(AUTOPILOT_ARDUPILOT, ty, &lower), Some(*number));
            }
        }
    }

    #[test]
    fn an_unknown_vehicle_falls_back_to_numbers() {
        assert_eq!(mode_name(AUTOPILOT_ARDUPILOT, 60, 5), "MODE(5)");
        assert_eq!(mode_name(99, 60, 7), "MODE(7)");
        assert!(modes_for(AUTOPILOT_ARDUPILOT, 60).is_empty());
        assert_eq!(mode_number(AUTOPILOT_ARDUPILOT, 60, "LOITER"), None);
        assert_eq!(mode_number(AUTOPILOT_ARDUPILOT, 60, "mode(5)"), Some(5));
        assert_eq!(vehicle_name(AUTOPILOT_ARDUPILOT, 60), "ArduPilot type 60");
        assert_eq!(vehicle_name(99, 60), "autopilot 99 type 60");
        // A ground station has no modes.
        assert!(modes_for(AUTOPILOT_INVALID, 6).is_empty());
    }

    #[test]
    fn copter_names_are_not_plane_numbers() {
        assert_eq!(
            mode_number(AUTOPILOT_ARDUPILOT, QUADROTOR, "LOITER"),
            Some(5)
        );
        assert_eq!(
            mode_number(AUTOPILOT_ARDUPILOT, FIXED_WING, "LOITER"),
            Some(12)
        );
        assert_eq!(mode_number(AUTOPILOT_ARDUPILOT, QUADROTOR, "QHOVER"), None);
    }
}
