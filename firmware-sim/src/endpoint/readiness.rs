//! What ground stations and SDKs wait on before they arm or fly, as ArduPilot reports it:
//!
//! - EKF_STATUS_REPORT (streamed in ArduPlane's EXTRA3 group) with flags read from the estimator:
//!   none but `EKF_UNINITIALIZED` while the gyros calibrate; attitude once they are; velocity
//!   and position (relative, absolute, predicted, vertical, above ground) once the position
//!   source has been fused (at once in the models that fly on the true state). The variances are
//!   ArduPilot's normalised test ratios: 0 when the solution is good, 1 when there is none.
//!   DroneKit's `is_armable` waits on `EKF_PRED_POS_HORIZ_ABS`.
//! - SYS_STATUS `MAV_SYS_STATUS_PREARM_CHECK`, present and enabled always, healthy while the
//!   vehicle passes its pre-arm checks (and while armed, keeping the last result as ArduPilot
//!   does). MAVSDK's `health.is_armable` is this bit.
//! - While disarmed and failing a check, a "PreArm: …" STATUSTEXT to every link when the
//!   failure starts or changes and then every [`PREARM_TEXT_PERIOD_US`] of sim time, ArduPilot's
//!   30 s.
//! - ArduPlane's pre-arm mission check: a VTOL landing too close after the waypoint before it
//!   stops arming ("PreArm: VTOL land too short, min 9m").

use mavlink::dialects::ardupilotmega as apm;

use super::Endpoint;
use crate::model::airframe::ModelMode;
use crate::model::vehicle::{ArmError, Vehicle};
use crate::nav::fixed_wing::vtol_land_too_short;

/// EKF_STATUS_REPORT's message id.
pub const EKF_STATUS_REPORT: u32 = 193;

/// How often a failing pre-arm check is repeated, µs of sim time (ArduPilot: 30 s).
pub const PREARM_TEXT_PERIOD_US: u64 = 30_000_000;

/// The pre-arm reporting state.
#[derive(Debug, Clone, Default)]
pub struct PreArmReport {
    /// The failure last reported and when, µs of sim time.
    last: Option<(String, u64)>,
}

/// Whether the navigation solution has a position: the estimator has fused a fix, or the model
/// flies on the true state (the paper model, `perfect_state`).
fn has_position(v: &Vehicle) -> bool {
    let c = v.config();
    c.model == ModelMode::Paper || c.perfect_state || v.estimator().position_m().is_some()
}

/// EKF_STATUS_REPORT flags for the vehicle as it stands.
#[must_use]
pub fn ekf_flags(v: &Vehicle) -> apm::EkfStatusFlags {
    use apm::EkfStatusFlags as F;
    if !v.estimator().is_calibrated() && !v.config().perfect_state {
        return F::EKF_UNINITIALIZED;
    }
    let mut flags = F::EKF_ATTITUDE;
    if has_position(v) {
        flags |= F::EKF_VELOCITY_HORIZ
            | F::EKF_VELOCITY_VERT
            | F::EKF_POS_HORIZ_REL
            | F::EKF_POS_HORIZ_ABS
            | F::EKF_POS_VERT_ABS
            | F::EKF_POS_VERT_AGL
            | F::EKF_PRED_POS_HORIZ_REL
            | F::EKF_PRED_POS_HORIZ_ABS;
    }
    flags
}

/// EKF_STATUS_REPORT for the vehicle as it stands.
#[must_use]
pub fn ekf_status_report(v: &Vehicle) -> apm::MavMessage {
    use apm::EkfStatusFlags as F;
    let flags = ekf_flags(v);
    let ratio = |bit: F| if flags.contains(bit) { 0.0 } else { 1.0 };
    apm::MavMessage::EKF_STATUS_REPORT(apm::EKF_STATUS_REPORT_DATA {
        velocity_variance: ratio(F::EKF_VELOCITY_HORIZ),
        pos_horiz_variance: ratio(F::EKF_POS_HORIZ_ABS),
        pos_vert_variance: ratio(F::EKF_POS_VERT_ABS),
        // The heading comes from the motion-capture rig, not a compass.
        compass_variance: ratio(F::EKF_ATTITUDE),
        terrain_alt_variance: ratio(F::EKF_POS_VERT_AGL),
        flags,
        airspeed_variance: 0.0,
    })
}

/// Whether SYS_STATUS reports the pre-arm checks as passed: while disarmed, the checks now;
/// while armed, they passed (arming needed them, or was forced past them as ArduPilot's
/// last result would show).
#[must_use]
pub fn prearm_ok(v: &Vehicle) -> bool {
    v.telemetry().armed || v.pre_arm_check().is_ok()
}

/// Adds `MAV_SYS_STATUS_PREARM_CHECK` to a SYS_STATUS (present and enabled; healthy when `ok`).
pub fn with_prearm_bit(msg: &mut apm::MavMessage, ok: bool) {
    use apm::MavSysStatusSensor as S;
    if let apm::MavMessage::SYS_STATUS(s) = msg {
        s.onboard_control_sensors_present |= S::MAV_SYS_STATUS_PREARM_CHECK;
        s.onboard_control_sensors_enabled |= S::MAV_SYS_STATUS_PREARM_CHECK;
        if ok {
            s.onboard_control_sensors_health |= S::MAV_SYS_STATUS_PREARM_CHECK;
        } else {
            s.onboard_control_sensors_health
                .remove(S::MAV_SYS_STATUS_PREARM_CHECK);
        }
    }
}

impl Endpoint {
    /// SYS_STATUS with the pre-arm bit.
    pub(super) fn sys_status(&self, errors_comm: u16) -> Option<apm::MavMessage> {
        let mut msg = super::streams::build(
            super::streams::id::SYS_STATUS,
            self.vehicle.telemetry(),
            errors_comm,
        )?;
        let ok = prearm_ok(&self.vehicle)
            && (self.vehicle.telemetry().armed || self.mission_prearm().is_none());
        with_prearm_bit(&mut msg, ok);
        Some(msg)
    }

    /// ArduPlane's pre-arm mission checks ([`vtol_land_too_short`]): the reason the stored
    /// mission stops arming, if it does. The landing airspeed is `TECS_LAND_ARSPD` when
    /// positive, else the cruise airspeed, as ArduPlane takes it.
    pub(super) fn mission_prearm(&self) -> Option<String> {
        let land = self.params.value("TECS_LAND_ARSPD");
        let speed = if land > 0.0 {
            land
        } else {
            self.params.value("TRIM_ARSPD_CM") / 100.0
        };
        vtol_land_too_short(
            &self.mission,
            &self.origin,
            speed,
            self.params.value("Q_TRANS_DECEL"),
        )
    }

    /// Announces a failing pre-arm check while disarmed: at once when it starts or changes,
    /// then every [`PREARM_TEXT_PERIOD_US`].
    pub(super) fn report_prearm(&mut self) {
        let failing = if self.vehicle.telemetry().armed {
            None
        } else {
            match self.vehicle.pre_arm_check() {
                Err(ArmError::PreArm(why)) => Some(why.to_owned()),
                _ => self.mission_prearm(),
            }
        };
        let Some(why) = failing else {
            self.prearm.last = None;
            return;
        };
        let due = match self.prearm.last {
            Some((ref last, at)) => {
                *last != why || self.now_us.saturating_sub(at) >= PREARM_TEXT_PERIOD_US
            }
            None => true,
        };
        if due {
            self.prearm.last = Some((why.clone(), self.now_us));
            self.announce(
                apm::MavSeverity::MAV_SEVERITY_CRITICAL,
                &format!("PreArm: {why}"),
            );
        }
    }
}
