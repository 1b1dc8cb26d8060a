//! HEARTBEAT out (`PROTOCOL.md` A.2) and the GCS heartbeat-loss failsafe (A.8).
//!
//! The heartbeat is built field by field: `HEARTBEAT_DATA::default()` in `mavlink` 0.21 reports
//! SAFETY_ARMED (E.2). It is emitted from the sim-time schedule, so it stops when the simulation
//! stalls, as the devguide asks of a faulted system.

use mavlink::dialects::ardupilotmega as apm;

use super::{Endpoint, Frame};
use crate::model::mode::FlightMode;
use crate::model::vehicle::SystemState;

/// GCS-failsafe state. The timer is armed only by a first heartbeat from `SYSID_MYGCS`
/// (ArduPlane's rule), so plain scripts that never send heartbeats cannot trigger it.
#[derive(Debug, Clone, Copy, Default)]
pub struct Failsafe {
    last_gcs_heartbeat_us: Option<u64>,
    active: bool,
}

impl Failsafe {
    /// Whether the failsafe is currently triggered.
    #[must_use]
    pub fn active(&self) -> bool {
        self.active
    }
}

/// `MAV_STATE` for a system state, with a failsafe forcing CRITICAL.
#[must_use]
pub fn mav_state(state: SystemState, failsafe: bool) -> apm::MavState {
    use apm::MavState as S;
    match state {
        SystemState::Emergency => S::MAV_STATE_EMERGENCY,
        _ if failsafe => S::MAV_STATE_CRITICAL,
        SystemState::Calibrating => S::MAV_STATE_CALIBRATING,
        SystemState::Standby => S::MAV_STATE_STANDBY,
        SystemState::Active => S::MAV_STATE_ACTIVE,
        SystemState::Critical => S::MAV_STATE_CRITICAL,
    }
}

impl Endpoint {
    /// The HEARTBEAT the twin sends now.
    #[must_use]
    pub fn heartbeat(&self) -> apm::MavMessage {
        let t = self.vehicle.telemetry();
        let mut base_mode = apm::MavModeFlag::MAV_MODE_FLAG_CUSTOM_MODE_ENABLED
            | apm::MavModeFlag::MAV_MODE_FLAG_STABILIZE_ENABLED;
        if t.armed {
            base_mode |= apm::MavModeFlag::MAV_MODE_FLAG_SAFETY_ARMED;
        }
        if t.mode == FlightMode::QStabilize {
            // Pilot throttle: ArduPlane flags manual input in its pilot-driven modes.
            base_mode |= apm::MavModeFlag::MAV_MODE_FLAG_MANUAL_INPUT_ENABLED;
        }
        if t.mode.is_autonomous() {
            // ArduPlane flags GUIDED in AUTO, GUIDED and QRTL (never AUTO_ENABLED).
            base_mode |= apm::MavModeFlag::MAV_MODE_FLAG_GUIDED_ENABLED;
        }
        apm::MavMessage::HEARTBEAT(apm::HEARTBEAT_DATA {
            custom_mode: t.mode.custom_mode(),
            mavtype: super::identity::MAV_TYPE,
            autopilot: super::identity::AUTOPILOT,
            base_mode,
            system_status: mav_state(t.state, self.failsafe.active),
            mavlink_version: 3,
        })
    }

    pub(super) fn on_heartbeat(&mut self, frame: &Frame, _hb: &apm::HEARTBEAT_DATA) {
        if u32::from(frame.system_id()) == self.params.value("SYSID_MYGCS") as u32 {
            self.failsafe.last_gcs_heartbeat_us = Some(self.now_us);
            if self.failsafe.active {
                self.failsafe.active = false;
                self.announce(apm::MavSeverity::MAV_SEVERITY_INFO, "GCS failsafe cleared");
            }
        }
    }

    pub(super) fn check_failsafe(&mut self) {
        if self.params.value("FS_GCS_ENABL") < 1.0 || self.failsafe.active {
            return;
        }
        let Some(last) = self.failsafe.last_gcs_heartbeat_us else {
            return;
        };
        let timeout_us = (self.params.value("FS_GCS_TIMEOUT") * 1e6) as u64;
        // Only an armed vehicle has anything to protect (ArduPlane checks the same).
        if self.vehicle.telemetry().armed && self.now_us.saturating_sub(last) > timeout_us {
            self.failsafe.active = true;
            self.vehicle.set_mode(FlightMode::QLand);
            self.announce(
                apm::MavSeverity::MAV_SEVERITY_CRITICAL,
                "Failsafe: GCS heartbeat lost, QLAND",
            );
        }
    }
}
