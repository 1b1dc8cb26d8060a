//! `firmware-sim`: the simulated twin of the two-rotor convertible VTOL of Escareño, Salazar and
//! Lozano (CDC 2006) — the paper's nonlinear hover model, the prototype's embedded hardware, the
//! attitude estimator and the nested-saturation controller — and the MAVLink vehicle that flies
//! it.

pub mod airframe;
pub mod atomic_file;
pub mod clock;
pub mod control;
pub mod endpoint;
pub mod estimator;
pub mod fleet;
pub mod frames;
pub mod globe;
pub mod harness;
pub mod integrator;
pub mod mission;
pub mod mode;
pub mod navigation;
pub mod params;
pub mod plant;
pub mod sensors;
pub mod serve;
pub mod signing;
pub mod simulate;
pub mod tlog;
pub mod vehicle;

pub use airframe::{Airframe, ModelMode};
pub use control::{Controller, Gains};
pub use frames::Euler;
pub use mode::FlightMode;
pub use vehicle::{Vehicle, VehicleConfig};
