//! The daemon's own MAVLink traffic: the ground station client (system 255, component 190 by
//! default) attached to the router through an in-memory byte link like any other client, so
//! its frames are routed and logged the same way.
//!
//! The client owns the identity and the sequence counter; the rest of the daemon (the terminal
//! UI, the command line through a serve port) talks through its [`ClientHandle`]. It sends the
//! 1 Hz GCS heartbeat only while an operator is present ([`ClientHandle::operator_present`]):
//! a vehicle with `FS_GCS_ENABL` set must see the heartbeats stop when every operator is gone.

use tokio::io::DuplexStream;
use tokio_util::sync::CancellationToken;

use super::{ClientConfig, ClientHandle};

/// Starts the daemon's client on its end of the own-traffic link.
#[must_use]
pub fn attach(
    stream: DuplexStream,
    system_id: u8,
    component_id: u8,
    cancel: CancellationToken,
) -> ClientHandle {
    ClientHandle::over_stream(
        stream,
        ClientConfig {
            system_id: vtol_link::SystemId(system_id),
            component_id: vtol_link::ComponentId(component_id),
            target: None,
        },
        cancel,
    )
}
