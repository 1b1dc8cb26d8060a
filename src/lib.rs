//! `vtol-gcs`: a MAVLink ground station and bridge for the two-rotor convertible VTOL. One async
//! daemon holds the vehicle link (the embedded twin, or a real vehicle over UDP, TCP or serial),
//! routes raw frames to any number of clients (pymavlink scripts, MAVProxy, QGroundControl),
//! logs every frame to a `.tlog`, and tracks the vehicle's state for the status line.
//!
//! The library's rooms, from the frame path up to what the operator sees. The command line
//! itself (`vtol-gcs run`, `params`, `mission`, `log` …) is the binary in `src/bin/vtol-gcs/`.

// The daemon and its frame path.

/// Daemon configuration: the TOML file and the command-line flags over it.
pub mod config;
/// `vtol-gcs run`: wires the links, router, tlog, tracker and own client, and runs them.
pub mod daemon;
/// The links' shared facts: each link's side and address, the router's counters, disputed
/// system ids; what the daemon, the UI and the binary read of the routing.
pub mod links;
/// What the daemon does when the vehicle reboots (parameters and mission fetched again).
pub mod reboot;
/// Forwards every frame between links by where each sender sits, and feeds the taps (only the
/// daemon names it).
pub(crate) mod router;
/// Fits the vehicle's stream rates to what a slow or congested link carries.
pub mod stream_fit;
/// What every consumer of frames shares: the frames the router hands over, with their time.
pub mod tap;
/// The `.tlog` telemetry log: writer, reader, file names.
pub mod tlog;
/// The vehicle's state, built from every routed frame, and its recent history for the charts.
pub mod tracker;
/// Per-endpoint trust policies and MAVLink 2 signing.
pub mod trust;

// Talking to a vehicle.

/// The ground station's MAVLink client: commands, parameters, missions, message intervals.
pub mod client;
/// Missions, fences and rally points: items, files, checks and verification.
pub mod mission;
/// An autopilot's identity and flight-mode names from its HEARTBEAT.
pub mod modes;
/// What each servo output drives, from its `SERVOn_FUNCTION` parameter.
pub mod outputs;
/// Parameter sets, their files, diffs and the transactional upload planner.
pub mod params;

// What the operator sees.

/// A decoded message as named fields: what `log export` writes, the inspector lists, a chart reads.
pub mod fields;
/// Flight logs: `log stats`, `log export`, `log plot`, and replay of a tlog.
pub mod log;
/// The one-line live status printed when the daemon runs without the terminal UI.
pub mod status;
/// The terminal UI: app state, views, and the event loop.
pub mod tui;
/// The vehicle's state at a glance (battery, GPS, home, air/ground, health) for every surface.
pub mod vitals;
/// The words shown for armed, lost and MAV_STATE states.
pub mod words;
