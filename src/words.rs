//! The words shown for vehicle and link states, in one place for every surface that prints
//! them: the terminal UI, the daemon's status line and the command line. Plain functions of
//! plain values, below everything that shows them.

use vtol_link::dialect::MavState;

/// The armed state as shown: `ARMED` (loud) or `disarmed`.
#[must_use]
pub fn armed(armed: bool) -> &'static str {
    if armed { "ARMED" } else { "disarmed" }
}

/// A vehicle's state in a list of vehicles: `LOST` before anything else, then the armed state.
#[must_use]
pub fn vehicle_state(lost: bool, is_armed: bool) -> &'static str {
    if lost { "LOST" } else { armed(is_armed) }
}

/// A link's health: `LOST` or `ok`.
#[must_use]
pub fn link_health(lost: bool) -> &'static str {
    if lost { "LOST" } else { "ok" }
}

/// A MAV_STATE as shown (`ACTIVE`, `CRITICAL` …).
#[must_use]
pub fn mav_state(s: MavState) -> &'static str {
    match s {
        MavState::MAV_STATE_UNINIT => "UNINIT",
        MavState::MAV_STATE_BOOT => "BOOT",
        MavState::MAV_STATE_CALIBRATING => "CALIBRATING",
        MavState::MAV_STATE_STANDBY => "STANDBY",
        MavState::MAV_STATE_ACTIVE => "ACTIVE",
        MavState::MAV_STATE_CRITICAL => "CRITICAL",
        MavState::MAV_STATE_EMERGENCY => "EMERGENCY",
        MavState::MAV_STATE_POWEROFF => "POWEROFF",
        MavState::MAV_STATE_FLIGHT_TERMINATION => "TERMINATION",
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn lost_comes_before_the_armed_state() {
        assert_eq!(vehicle_state(true, true), "LOST");
        assert_eq!(vehicle_state(false, true), "ARMED");
        assert_eq!(vehicle_state(false, false), "disarmed");
        assert_eq!(link_health(false), "ok");
        assert_eq!(
            mav_state(MavState::MAV_STATE_FLIGHT_TERMINATION),
            "TERMINATION"
        );
    }
}
