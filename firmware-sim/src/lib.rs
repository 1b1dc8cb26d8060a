//! `firmware-sim`: the simulated twin of the two-rotor convertible VTOL of Escareño, Salazar and
//! Lozano (CDC 2006) — the paper's nonlinear hover model, the prototype's embedded hardware, the
//! attitude estimator and the nested-saturation controller — and the MAVLink vehicle that flies
//! it.
//!
//! The crate is built in layers; each reaches only the layers above it in this list:
//!
//! - [`model`]: the pure core (airframe, plant, sensors, estimator, controller, the signals
//!   between them, the vehicle that steps them). No I/O, no clock, no tokio, no MAVLink
//!   transport.
//! - [`nav`]: the onboard navigator and configuration (geodesy, missions, navigation, the
//!   parameter table); it imports only the model and vtol-link's text files.
//! - [`endpoint`]: the MAVLink vehicle: what the twin says and answers, as a pure state machine fed
//!   frames and the simulation time.
//! - [`shell`]: the processes around it: sockets, clocks, fleets, the test harness, signing
//!   state, tlogs, the radio, the offline `simulate` runner.
//!
//! `tests/layers.rs` holds these rules.

pub mod endpoint;
pub mod model;
pub mod nav;
pub mod shell;

pub use model::airframe::{Airframe, ModelMode};
pub use model::control::{Controller, Gains};
pub use model::frames::Euler;
pub use model::mode::FlightMode;
pub use model::vehicle::{Vehicle, VehicleConfig};
