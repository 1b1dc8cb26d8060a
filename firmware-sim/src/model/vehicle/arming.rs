//! Arming, disarming and the pre-arm checks of the twin.

use super::{ARM_MAX_TILT_RAD, ArmError, SystemState, Vehicle, tilt_rad};
use crate::model::airframe::ModelMode;
use crate::model::estimator::Estimator;
use crate::model::frames::Euler;

impl Vehicle {
    /// Arms the motors. Without `force`, pre-arm checks apply (calibration done, level, landed).
    ///
    /// # Errors
    /// [`ArmError::PreArm`] saying which check failed.
    pub fn arm(&mut self, force: bool) -> Result<(), ArmError> {
        if self.telemetry.armed {
            return Ok(());
        }
        if !force {
            if self.telemetry.state == SystemState::Emergency {
                return Err(ArmError::PreArm("vehicle crashed"));
            }
            if !self.telemetry.mode.allows_arming() {
                return Err(ArmError::Mode(self.telemetry.mode));
            }
            self.pre_arm_check()?;
        }
        self.controller.reset();
        self.forward.clear_hover_heading();
        self.telemetry.armed = true;
        self.telemetry.state = SystemState::Active;
        Ok(())
    }

    /// The pre-arm checks that do not depend on the mode (calibration done, landed, level, not
    /// crashed): what SYS_STATUS reports as `MAV_SYS_STATUS_PREARM_CHECK`.
    ///
    /// # Errors
    /// [`ArmError::PreArm`] saying which check fails.
    pub fn pre_arm_check(&self) -> Result<(), ArmError> {
        if self.telemetry.state == SystemState::Emergency {
            return Err(ArmError::PreArm("vehicle crashed"));
        }
        if !self.estimator.is_calibrated() {
            return Err(ArmError::PreArm("gyro calibration in progress"));
        }
        if !self.on_ground {
            return Err(ArmError::PreArm("not landed"));
        }
        let e = self.estimator_or_truth_euler();
        if tilt_rad(&e) > ARM_MAX_TILT_RAD {
            return Err(ArmError::PreArm("not level"));
        }
        Ok(())
    }

    /// The attitude and position estimator (read only).
    #[must_use]
    pub fn estimator(&self) -> &Estimator {
        &self.estimator
    }

    fn estimator_or_truth_euler(&self) -> Euler {
        match self.config.model {
            ModelMode::Physical if !self.config.perfect_state => self.estimator.euler(),
            _ => self.plant.euler,
        }
    }

    /// Disarms. In flight only with `force`.
    ///
    /// # Errors
    /// [`ArmError::InFlight`].
    pub fn disarm(&mut self, force: bool) -> Result<(), ArmError> {
        if self.telemetry.armed && !self.on_ground && !force {
            return Err(ArmError::InFlight);
        }
        self.set_disarmed();
        Ok(())
    }
}
