//! MAVLink framing and transports shared by the `vtol-gcs` daemon and the `firmware-sim` twin.
//!
//! - [`frame`]: [`Frame`], one raw MAVLink v1/v2 frame (cheap to clone, forwarded unchanged),
//!   with header accessors, routing targets, typed decoding and hand-built COMMAND_ACKs.
//! - [`decoder`]: [`FrameDecoder`], a streaming parser with CRC checks, resync and counters.
//! - [`url`]: [`LinkUrl`], pymavlink-style link addresses.
//! - [`transport`]: tokio endpoints (udpin, udpout, tcpin, tcp, serial, in-memory streams)
//!   reporting [`LinkEvent`]s, each link with a bounded egress queue.
//!
//! The typed messages come from the `mavlink` crate's ardupilotmega dialect, re-exported as
//! [`dialect`].

pub mod decoder;
pub mod frame;
pub mod transport;
pub mod url;

pub use mavlink::MavlinkVersion;
/// The MAVLink dialect used for CRC_EXTRA and typed decoding (ardupilotmega, which includes
/// common and minimal).
pub use mavlink::dialects::ardupilotmega as dialect;

pub use decoder::{DecodeStats, FrameDecoder};
pub use frame::{
    Frame, FrameError, RawCommand, RawCommandAck, RawCommandKind, frame_len_from_prefix,
    gcs_heartbeat,
};
pub use transport::{
    EndpointHandle, LinkError, LinkEvent, LinkId, LinkOptions, LinkSender, LinkStats,
    LinkStatsSnapshot, SendError, run_stream_link, spawn_endpoint, spawn_stream_link,
};
pub use url::{LinkUrl, UrlError};
