//! Errors opening an endpoint.

use std::io;
use std::net::SocketAddr;

use crate::url::UrlError;

/// Errors opening an endpoint.
#[derive(Debug, thiserror::Error)]
pub enum LinkError {
    /// The URL did not parse.
    #[error(transparent)]
    Url(#[from] UrlError),
    /// Name resolution failed.
    #[error("cannot resolve '{host}': {source}")]
    Resolve {
        /// The host name.
        host: String,
        /// The resolver's error.
        source: io::Error,
    },
    /// The name resolved to nothing.
    #[error("'{host}' resolved to no address")]
    NoAddress {
        /// The host name.
        host: String,
    },
    /// Binding a socket failed (address in use, permission…).
    #[error("cannot bind {url} ({addr}): {source}")]
    Bind {
        /// The endpoint's URL.
        url: String,
        /// The address tried.
        addr: SocketAddr,
        /// The OS error.
        source: io::Error,
    },
    /// A serial device that does not exist when the endpoint is opened.
    #[error("serial device {device} does not exist")]
    NoDevice {
        /// The device path.
        device: String,
    },
    /// A Zenoh session or declaration that failed, or a `zenoh:` URL this end cannot take.
    #[error("{0}")]
    Zenoh(String),
    /// Another I/O error while opening.
    #[error("{url}: {source}")]
    Io {
        /// The endpoint's URL.
        url: String,
        /// The OS error.
        source: io::Error,
    },
}
