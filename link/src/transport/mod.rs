//! Tokio transports: turn a [`LinkUrl`] into links that report [`LinkEvent`]s.
//!
//! A *link* is one peer connection: a TCP client or accepted socket, a serial port, one UDP
//! peer address, or an in-memory pipe. Each link announces itself with `Up` (carrying its
//! bounded egress queue), reports every received frame, and ends with `Down`. An *endpoint*
//! is what a URL opens: a listener yields many links, a client or serial port one link that
//! keeps its [`LinkId`] across reconnects. Parse errors are counted and skipped; I/O errors end
//! the link (and clients reconnect with capped back-off); nothing panics or spins.

mod backoff;
mod error;
mod events;
mod options;
mod sender;
mod serial;
mod stats;
mod stream;
mod tcp;
mod udp;
#[cfg(feature = "zenoh")]
pub mod zenoh;

use std::net::SocketAddr;

use tokio::task::JoinHandle;
use tokio_util::sync::CancellationToken;

use crate::url::LinkUrl;

pub(crate) use backoff::{Backoff, sleep_or_cancel};
pub use error::LinkError;
pub use events::{Events, LinkEvent, LinkEventHandler, LinkId};
pub(crate) use events::{emit, emit_down, emit_frames};
pub use options::{LinkOptions, ZenohMode, ZenohOptions, ZenohRole};
pub(crate) use sender::take_batch;
pub use sender::{EgressFilter, LinkSender, SendError, SendSummary};
pub use stats::{LinkStats, LinkStatsSnapshot};
pub use stream::{run_stream_link, spawn_stream_link};
use udp::DirectUdp;

/// A running endpoint.
#[derive(Debug)]
pub struct EndpointHandle {
    url: LinkUrl,
    local_addr: Option<SocketAddr>,
    link_id: Option<LinkId>,
    task: JoinHandle<()>,
}

impl EndpointHandle {
    /// The URL this endpoint was opened from.
    pub fn url(&self) -> &LinkUrl {
        &self.url
    }

    /// The bound local address (udpin, udpout, tcpin); `None` for tcp clients and serial.
    /// With port 0 this is where the OS put us.
    pub fn local_addr(&self) -> Option<SocketAddr> {
        self.local_addr
    }

    /// The fixed link id of single-link endpoints (udpout, tcp, serial).
    pub fn link_id(&self) -> Option<LinkId> {
        self.link_id
    }

    /// True once the endpoint and all its links have stopped.
    pub fn is_finished(&self) -> bool {
        self.task.is_finished()
    }

    /// Waits until the endpoint and all its links have stopped (after cancellation).
    pub async fn join(self) {
        if let Err(e) = self.task.await {
            tracing::error!(url = %self.url, "endpoint task failed: {e}");
        }
    }
}

/// Opens the endpoint a URL describes and runs it until `cancel` fires.
///
/// Listeners and udpout bind before this returns (so errors like "address in use" surface
/// here and [`EndpointHandle::local_addr`] is known). A serial device that does not exist is an
/// error unless [`LinkOptions::wait_for_device`] is set. Past that, TCP clients and serial ports
/// never fail here: they retry with back-off until they connect (a vehicle may appear later, a
/// USB radio may be replugged).
pub async fn spawn_endpoint(
    url: &LinkUrl,
    events: impl Into<Events>,
    opts: LinkOptions,
    cancel: CancellationToken,
) -> Result<EndpointHandle, LinkError> {
    let events = events.into();
    let (local_addr, link_id, task) = match url {
        LinkUrl::UdpIn { host, port } => {
            let at = SocketEndpoint::resolve(url, host, *port, events, opts, cancel).await?;
            let (addr, task) = udp::spawn_udpin(at)?;
            (Some(addr), None, task)
        }
        LinkUrl::UdpOut { host, port } => {
            let at = SocketEndpoint::resolve(url, host, *port, events, opts, cancel).await?;
            let (addr, id, task) = udp::spawn_udpout(at)?;
            (Some(addr), Some(id), task)
        }
        LinkUrl::TcpIn { host, port } => {
            let at = SocketEndpoint::resolve(url, host, *port, events, opts, cancel).await?;
            let (addr, task) = tcp::spawn_tcpin(at).await?;
            (Some(addr), None, task)
        }
        LinkUrl::Tcp { host, port } => {
            let (id, task) = tcp::spawn_tcp_client(host.clone(), *port, events, opts, cancel);
            (None, Some(id), task)
        }
        LinkUrl::Serial { device, baud } => {
            if !opts.wait_for_device && !std::path::Path::new(device).exists() {
                return Err(LinkError::NoDevice {
                    device: device.clone(),
                });
            }
            let (id, task) = serial::spawn_serial(device.clone(), *baud, events, opts, cancel);
            (None, Some(id), task)
        }
        #[cfg(feature = "zenoh")]
        LinkUrl::Zenoh { fleet, vehicle } => {
            let (id, task) =
                zenoh::spawn_zenoh(fleet, vehicle.as_deref(), events, opts, cancel).await?;
            (None, id, task)
        }
        #[cfg(not(feature = "zenoh"))]
        LinkUrl::Zenoh { .. } => {
            return Err(LinkError::Zenoh(format!(
                "{url}: this build has no Zenoh support (build with the `zenoh` feature)"
            )));
        }
    };
    Ok(EndpointHandle {
        url: url.clone(),
        local_addr,
        link_id,
        task,
    })
}

/// What a socket endpoint (udpin, udpout, tcpin) starts from: the URL it was opened from, its
/// host and the addresses `host:port` resolved to, where its events go, its options and its
/// cancellation.
pub(crate) struct SocketEndpoint<'a> {
    pub(crate) url: &'a LinkUrl,
    pub(crate) host: &'a str,
    pub(crate) addrs: Vec<SocketAddr>,
    pub(crate) events: Events,
    pub(crate) opts: LinkOptions,
    pub(crate) cancel: CancellationToken,
}

impl<'a> SocketEndpoint<'a> {
    /// Resolves `host:port` (see [`resolve`]) for the endpoint `url` names.
    async fn resolve(
        url: &'a LinkUrl,
        host: &'a str,
        port: u16,
        events: Events,
        opts: LinkOptions,
        cancel: CancellationToken,
    ) -> Result<Self, LinkError> {
        Ok(Self {
            url,
            host,
            addrs: resolve(host, port).await?,
            events,
            opts,
            cancel,
        })
    }
}

/// Resolves `host:port`, IPv4 addresses first (so `localhost` binds and connects like
/// pymavlink does).
pub(crate) async fn resolve(host: &str, port: u16) -> Result<Vec<SocketAddr>, LinkError> {
    let mut addrs: Vec<SocketAddr> = tokio::net::lookup_host((host, port))
        .await
        .map_err(|source| LinkError::Resolve {
            host: host.to_string(),
            source,
        })?
        .collect();
    addrs.sort_by_key(|a| !a.is_ipv4());
    if addrs.is_empty() {
        return Err(LinkError::NoAddress {
            host: host.to_string(),
        });
    }
    Ok(addrs)
}
