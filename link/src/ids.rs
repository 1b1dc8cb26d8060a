//! MAVLink system and component ids as types of their own, so routing and tracking code never
//! confuses one with the other (or with a sequence number) in a bare `(u8, u8)` pair.

use std::fmt;

/// A MAVLink system id: one vehicle, one ground station (0 = broadcast in a target field).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord, Default)]
pub struct SystemId(pub u8);

/// A MAVLink component id within a system (0 = all components in a target field).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord, Default)]
pub struct ComponentId(pub u8);

impl SystemId {
    /// Whether this is the broadcast id 0.
    #[must_use]
    pub fn is_broadcast(self) -> bool {
        self.0 == 0
    }
}

impl ComponentId {
    /// Target component 0: every component of the system.
    pub const ALL: ComponentId = ComponentId(0);
    /// MAV_COMP_ID_AUTOPILOT1, the vehicle's flight controller.
    pub const AUTOPILOT1: ComponentId = ComponentId(1);
}

impl fmt::Display for SystemId {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        self.0.fmt(f)
    }
}

impl fmt::Display for ComponentId {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        self.0.fmt(f)
    }
}
