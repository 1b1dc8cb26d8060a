//! MAVLink framing and transports shared by the `vtol-gcs` daemon and the `firmware-sim` twin.
//!
//! - [`frame`]: [`Frame`], one raw MAVLink v1/v2 frame (cheap to clone, forwarded unchanged),
//!   with header accessors, routing targets, typed decoding and hand-built COMMAND_ACKs.
//! - [`decoder`]: [`FrameDecoder`], a streaming parser with CRC checks, resync and counters.
//! - [`signing`]: MAVLink 2 signing: [`SigningKey`], signing and verifying frames with the
//!   spec's replay rules, the timestamp source and the persisted key and timestamp.
//! - [`url`]: [`LinkUrl`], pymavlink-style link addresses.
//! - [`text_file`]: the text files both programs keep (parameter files, missions), written
//!   atomically and refused with the file and line of the first problem.
//! - [`transport`]: tokio endpoints (udpin, udpout, tcpin, tcp, serial, in-memory streams)
//!   reporting [`LinkEvent`]s, each link with a bounded egress queue.
//!
//! The typed messages come from the `mavlink` crate's ardupilotmega dialect, re-exported as
//! [`dialect`].

pub mod decoder;
pub mod frame;
pub mod ids;
pub mod protocol;
pub mod signing;
pub mod statustext;
pub mod text_file;
pub mod tlog;
pub mod transport;
pub mod url;

pub use mavlink::MavlinkVersion;
/// The MAVLink dialect used for CRC_EXTRA and typed decoding (ardupilotmega, which includes
/// common and minimal).
pub use mavlink::dialects::ardupilotmega as dialect;

pub use decoder::{DecodeStats, FrameDecoder};
pub use frame::{
    Frame, FrameError, FrameSource, Lenient, RawCommand, RawCommandAck, RawCommandKind,
    command_long, frame_len_from_prefix, gcs_heartbeat,
};
pub use ids::{ComponentId, SystemId};
pub use signing::{
    Accepted, Refusal, SignError, Signing, SigningFileError, SigningKey, SigningState,
    TimestampSource,
};
pub use transport::{
    EgressFilter, EndpointHandle, Events, LinkError, LinkEvent, LinkEventHandler, LinkId,
    LinkOptions, LinkSender, LinkStats, LinkStatsSnapshot, SendError, SendSummary, ZenohMode,
    ZenohOptions, ZenohRole, run_stream_link, spawn_endpoint, spawn_stream_link,
};
pub use url::{LinkUrl, UrlError};

/// An error and its causes on one line, `outer: cause: root`, leaving out a cause whose text
/// the line already holds (many error messages quote their source). Both binaries report a
/// failure to start this way: one clear line.
#[must_use]
pub fn error_line(err: &(dyn std::error::Error + 'static)) -> String {
    let mut line = err.to_string();
    let mut cause = err.source();
    while let Some(c) = cause {
        let text = c.to_string();
        if !line.contains(&text) {
            line.push_str(": ");
            line.push_str(&text);
        }
        cause = c.source();
    }
    // Some dependencies (Zenoh) append where in their sources an error was made: the user
    // cannot act on a path of the build machine.
    let mut line = strip_source_locations(&line);
    // Errors quote what the user gave (a URL, a line of a file): a line break or another
    // control character in it is shown escaped, so the error stays one line.
    if line.contains(char::is_control) {
        line = line
            .chars()
            .map(|c| {
                if c.is_control() {
                    c.escape_default().to_string()
                } else {
                    c.to_string()
                }
            })
            .collect();
    }
    line
}

/// `text` without the ` at /path/to/file.rs:LINE` source locations some errors carry.
fn strip_source_locations(text: &str) -> String {
    let mut out = String::with_capacity(text.len());
    let mut rest = text;
    while let Some(i) = rest.find(" at ") {
        let after = &rest[i + 4..];
        let end = after
            .find(|c: char| c.is_whitespace() || c == ']')
            .unwrap_or(after.len());
        let token = after[..end].trim_end_matches('.');
        let is_location = token.contains('/')
            && token.rsplit_once(".rs:").is_some_and(|(_, pos)| {
                !pos.is_empty() && pos.chars().all(|c| c.is_ascii_digit() || c == ':')
            });
        if is_location {
            out.push_str(&rest[..i]);
            rest = after[token.len()..]
                .strip_prefix('.')
                .unwrap_or(&after[token.len()..]);
        } else {
            out.push_str(&rest[..i + 4]);
            rest = after;
        }
    }
    out.push_str(rest);
    out
}

#[cfg(test)]
mod error_line_tests {
    #[derive(Debug, thiserror::Error)]
    #[error("cannot open link: {0}")]
    struct Outer(#[source] std::io::Error);

    #[test]
    fn causes_already_quoted_are_not_repeated() {
        let e = Outer(std::io::Error::other("address in use"));
        assert_eq!(super::error_line(&e), "cannot open link: address in use");
    }

    /// Zenoh's errors name its source files on the build machine: left out.
    #[test]
    fn source_locations_of_dependencies_are_left_out() {
        let zenoh = "Can not create a new TCP listener bound to tcp/127.0.0.1:7447: \
            [127.0.0.1:7447: Address already in use (os error 98) at \
            /root/.cargo/registry/src/index.crates.io-1949cf8c6b5b557f/zenoh-link-commons-1.10.2/src/tcp.rs:61.] \
            at /root/.cargo/registry/src/x/zenoh-link-tcp-1.10.2/src/unicast.rs:338.";
        let e = Outer(std::io::Error::other(zenoh));
        assert_eq!(
            super::error_line(&e),
            "cannot open link: Can not create a new TCP listener bound to tcp/127.0.0.1:7447: \
             [127.0.0.1:7447: Address already in use (os error 98)]"
        );
        // A URL or a word "at" that is no source location stays.
        let e = Outer(std::io::Error::other(
            "no answer at tcp:127.0.0.1:5760 at all",
        ));
        assert!(super::error_line(&e).ends_with("no answer at tcp:127.0.0.1:5760 at all"));
    }
}
