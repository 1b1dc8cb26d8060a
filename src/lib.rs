//! `vtol-gcs`: a MAVLink ground station and bridge for the two-rotor convertible VTOL. One async
//! daemon holds the vehicle link (the embedded twin, or a real vehicle over UDP, TCP or serial),
//! routes raw frames to any number of clients (pymavlink scripts, MAVProxy, QGroundControl),
//! logs every frame to a `.tlog`, and tracks the vehicle's state for the status line.

pub mod client;
pub mod config;
pub mod daemon;
pub mod fit;
pub mod gcs;
pub mod links;
pub mod log;
pub mod mission;
pub mod modes;
pub mod outputs;
pub mod params;
pub mod reboot;
pub(crate) mod router;
pub mod status;
pub mod tap;
pub mod tlog;
pub mod tracker;
pub mod trust;
pub mod tui;
pub mod words;
