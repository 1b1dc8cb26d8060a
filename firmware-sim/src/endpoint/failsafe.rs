//! The battery failsafe on the wire: [`crate::nav::failsafe`] decides, this says it
//! (STATUSTEXT, WARNING for low, CRITICAL for critical) and, while armed, flies the action: RTL
//! (home on the wing; QRTL with `Q_RTL_MODE` 3) or QLAND as ArduPlane does, or a forced disarm for
//! "terminate".

use mavlink::dialects::ardupilotmega as apm;

use super::Endpoint;
use crate::model::mode::FlightMode;
use crate::nav::failsafe::{Action, Level, Limits};

impl Endpoint {
    /// Checks the pack once per tick; a new level is announced and acted on.
    pub(super) fn check_battery_failsafe(&mut self) {
        let lim = Limits::from_params(&self.params);
        let battery = self.vehicle.telemetry().battery;
        let Some(event) = self.battery_failsafe.check(&lim, &battery, self.now_us) else {
            return;
        };
        let severity = match event.level {
            Level::Low => apm::MavSeverity::MAV_SEVERITY_WARNING,
            Level::Critical => apm::MavSeverity::MAV_SEVERITY_CRITICAL,
        };
        self.announce(severity, &event.text);
        if !self.vehicle.telemetry().armed {
            return;
        }
        let mode = match event.action {
            Action::None => return,
            // ArduPlane's handle_battery_failsafe: RTL (flown as QRTL with Q_RTL_MODE 3),
            // unless already landing.
            Action::Rtl => {
                let m = self.vehicle.telemetry().mode;
                if matches!(m, FlightMode::QLand | FlightMode::QRtl) {
                    return;
                }
                self.rtl_or_qrtl()
            }
            Action::QLand => FlightMode::QLand,
            Action::Terminate => {
                let _ = self.vehicle.disarm(true);
                self.announce(
                    apm::MavSeverity::MAV_SEVERITY_CRITICAL,
                    "Battery failsafe: terminate, motors stopped",
                );
                return;
            }
        };
        if self.vehicle.telemetry().mode != mode {
            self.vehicle.set_mode(mode);
            self.navigate();
            let text = format!("Battery failsafe: {}", mode.name());
            self.announce(apm::MavSeverity::MAV_SEVERITY_CRITICAL, &text);
        }
    }
}
