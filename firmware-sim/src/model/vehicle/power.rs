//! The flight battery as the vehicle holds it: a pack outlives the firmware.

use super::Vehicle;
use crate::model::plant::battery::Battery;

impl Vehicle {
    /// The flight battery.
    #[must_use]
    pub fn battery(&self) -> &Battery {
        &self.battery
    }

    /// Puts `battery` in place of the pack the vehicle started with (a reboot keeps the pack
    /// it had, drawn as it was): reported from now, and driving the motors' supply.
    pub fn replace_battery(&mut self, battery: Battery) {
        self.telemetry.battery = *battery.state();
        self.actuators.set_supply(battery.supply_ratio());
        self.battery = battery;
    }
}
