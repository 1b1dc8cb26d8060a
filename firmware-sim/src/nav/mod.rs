//! The onboard navigator and configuration: geodesy, missions and their files, the guidance that
//! turns a mode and a mission into setpoints, and the vehicle's parameter table.

pub mod failsafe;
pub mod fixed_wing;
pub mod globe;
pub mod l1;
pub mod mission;
pub mod navigation;
pub mod params;
