//! MAVLink 2 message signing, written once for the daemon and the twin.
//!
//! Contract (MAVLink devguide "Message Signing", byte order as pymavlink and the C library):
//! - A signed frame has incompat flag 0x01 set and 13 more bytes after the CRC:
//!   `link_id (1) | timestamp (6, little-endian) | signature (6)`. The timestamp counts 10 µs
//!   units since 2015-01-01 00:00:00 UTC (Unix time 1 420 070 400 s) and has 48 bits.
//! - `signature = SHA-256(key ‖ frame bytes from the magic 0xFD through the timestamp)[..6]`,
//!   the frame bytes including the header with the signed flag set, the payload, the CRC
//!   (computed over that header) and the link id.
//! - [`SigningKey`]: 32 secret bytes, from a passphrase (SHA-256 of its UTF-8 bytes, as MAVProxy's
//!   `signing setup` does) or from a key file of 64 hex characters. `Debug` and `Display` never
//!   show key bytes, and no error of this module quotes them.
//! - [`TimestampSource`]: the timestamp we send with never goes back, grows by at least 1 per
//!   signed frame and follows the wall clock (`max(last + 1, now)`), so a link that was idle or
//!   cut for minutes resumes with timestamps a receiver takes, even one that forgot our stream.
//!   Accepting a signed frame raises it to the frame's timestamp, as the spec asks.
//! - [`Signing::verify`] accepts a frame when its signature is right and, for its stream
//!   `(link id, system id, component id)`, its timestamp is strictly greater than the last one
//!   accepted; the first frame of a stream is refused if it is more than 60 s
//!   ([`NEW_STREAM_WINDOW`]) behind our own timestamp. Unsigned frames (MAVLink 1 included) are
//!   refused unless their message id is on the allow-list (RADIO_STATUS by default). A refused
//!   frame changes no state.
//! - [`SigningState`] (key and last timestamp) persists as a small TOML file
//!   (`key = "<64 hex>"`, `timestamp = N`), written with owner-only permissions; every broken
//!   file gives one [`SigningFileError`] naming the file and, where it can, the line.
//!
//! Nothing here reads the clock by itself except the `*_now` conveniences: callers pass `now`,
//! so tests can move time freely.

mod key;
mod signature;
mod state;
#[cfg(test)]
mod tests;
mod timestamp;
mod verify;

pub use key::{KeyError, SigningKey};
pub use signature::{SignError, SignatureFields, sign_frame, signature_matches, signature_of};
use state::read_text;
pub use state::{SigningFileError, SigningState};
pub use timestamp::{TimestampSource, timestamp_at};
pub use verify::{Accepted, Refusal, Signing};

/// How a signing state file is written, as its errors say it (never with a value of the file).
pub const STATE_FILE_FORMAT: &str = "expected key = \"64 hex characters\" and timestamp = N";

/// Seconds from the Unix epoch to the signing epoch, 2015-01-01 00:00:00 UTC.
pub const SIGNING_EPOCH_UNIX_S: u64 = 1_420_070_400;
/// Timestamp units per second (one unit is 10 µs).
pub const TIMESTAMP_UNITS_PER_S: u64 = 100_000;
/// Largest timestamp a signature can carry (48 bits).
pub const MAX_TIMESTAMP: u64 = (1 << 48) - 1;
/// How far (in timestamp units: 60 s) the first frame of a new stream may be behind our own
/// timestamp (devguide; pymavlink and the C library use the same 6 000 000).
pub const NEW_STREAM_WINDOW: u64 = 60 * TIMESTAMP_UNITS_PER_S;
/// At most this many streams are remembered; a further new stream is refused (the C library
/// keeps 16). Only frames with a right signature create streams.
pub const MAX_STREAMS: usize = 1024;
/// Bytes of the signature proper (the last field of the trailer).
pub const SIGNATURE_BYTES: usize = 6;
/// Bytes of a signing key.
pub const KEY_LEN: usize = 32;
