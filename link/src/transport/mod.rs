//! Tokio transports: turn a [`LinkUrl`] into links that report [`LinkEvent`]s.
//!
//! A *link* is one peer connection: a TCP client or accepted socket, a serial port, one UDP
//! peer address, or an in-memory pipe. Each link announces itself with `Up` (carrying its
//! bounded egress queue), reports every received frame, and ends with `Down`. An *endpoint*
//! is what a URL opens: a listener yields many links, a client or serial port one link that
//! keeps its [`LinkId`] across reconnects. Parse errors are counted and skipped; I/O errors end
//! the link (and clients reconnect with capped back-off); nothing panics or spins.

mod serial;
mod stream;
mod tcp;
mod udp;
#[cfg(feature = "zenoh")]
pub mod zenoh;

use std::fmt;
use std::io;
use std::net::SocketAddr;
use std::sync::Arc;
use std::sync::atomic::{AtomicU32, AtomicU64, Ordering};
use std::time::Duration;

use tokio::sync::mpsc;
use tokio::task::JoinHandle;
use tokio_util::sync::CancellationToken;

use crate::decoder::DecodeStats;
use crate::frame::Frame;
use crate::url::{LinkUrl, UrlError};

pub use stream::{run_stream_link, spawn_stream_link};
use udp::DirectUdp;

/// Identifies one link for the life of the process (unique across all endpoints).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub struct LinkId(pub u32);

impl LinkId {
    /// A fresh id from the process-wide counter (starts at 1).
    pub fn next() -> LinkId {
        static NEXT: AtomicU32 = AtomicU32::new(1);
        LinkId(NEXT.fetch_add(1, Ordering::Relaxed))
    }
}

impl fmt::Display for LinkId {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "link#{}", self.0)
    }
}

/// What links report to their owner.
#[derive(Debug)]
pub enum LinkEvent {
    /// A link is connected. `tx` is its egress queue; it closes when the link goes down.
    Up {
        /// The link.
        id: LinkId,
        /// Human-readable peer (`tcp 127.0.0.1:5760`, `udp 10.0.0.2:14550`, device path).
        peer: String,
        /// Bounded egress queue of this link (and its counters).
        tx: LinkSender,
    },
    /// A frame arrived on a link.
    Frame {
        /// The link it arrived on.
        id: LinkId,
        /// The frame, raw bytes as received.
        frame: Frame,
    },
    /// A link went away (EOF, I/O error, UDP silence, shutdown).
    Down {
        /// The link.
        id: LinkId,
        /// Why, for logs and the TUI.
        reason: String,
    },
}

/// Per-link counters, shared between the link task and its owner.
#[derive(Debug, Default)]
pub struct LinkStats {
    rx_frames: AtomicU64,
    rx_bytes: AtomicU64,
    tx_frames: AtomicU64,
    tx_bytes: AtomicU64,
    tx_dropped_queue_full: AtomicU64,
    tx_errors: AtomicU64,
    bad_crc: AtomicU64,
    garbage_bytes: AtomicU64,
    unknown_id: AtomicU64,
    bad_incompat: AtomicU64,
}

/// A copy of [`LinkStats`] at one instant.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct LinkStatsSnapshot {
    /// Frames received (verified and unverified).
    pub rx_frames: u64,
    /// Bytes received, garbage included.
    pub rx_bytes: u64,
    /// Frames written to the transport.
    pub tx_frames: u64,
    /// Bytes written to the transport.
    pub tx_bytes: u64,
    /// Frames refused because the egress queue was full (slow peer).
    pub tx_dropped_queue_full: u64,
    /// Frames lost to send errors (UDP only; stream errors end the link).
    pub tx_errors: u64,
    /// Received candidates with a bad CRC.
    pub bad_crc: u64,
    /// Received bytes skipped while resyncing.
    pub garbage_bytes: u64,
    /// Received frames with message ids the dialect does not know.
    pub unknown_id: u64,
    /// Received frames dropped for unknown incompat flags.
    pub bad_incompat: u64,
}

impl LinkStats {
    /// Reads every counter.
    pub fn snapshot(&self) -> LinkStatsSnapshot {
        let g = |a: &AtomicU64| a.load(Ordering::Relaxed);
        LinkStatsSnapshot {
            rx_frames: g(&self.rx_frames),
            rx_bytes: g(&self.rx_bytes),
            tx_frames: g(&self.tx_frames),
            tx_bytes: g(&self.tx_bytes),
            tx_dropped_queue_full: g(&self.tx_dropped_queue_full),
            tx_errors: g(&self.tx_errors),
            bad_crc: g(&self.bad_crc),
            garbage_bytes: g(&self.garbage_bytes),
            unknown_id: g(&self.unknown_id),
            bad_incompat: g(&self.bad_incompat),
        }
    }

    pub(crate) fn add_decode(&self, d: &DecodeStats) {
        let add = |a: &AtomicU64, v: u64| {
            if v != 0 {
                a.fetch_add(v, Ordering::Relaxed);
            }
        };
        add(&self.rx_frames, d.frames);
        add(&self.bad_crc, d.bad_crc);
        add(&self.garbage_bytes, d.garbage_bytes);
        add(&self.unknown_id, d.unknown_id);
        add(&self.bad_incompat, d.bad_incompat);
    }

    pub(crate) fn add_rx_bytes(&self, n: usize) {
        self.rx_bytes.fetch_add(n as u64, Ordering::Relaxed);
    }

    pub(crate) fn add_tx(&self, frames: usize, bytes: usize) {
        self.tx_frames.fetch_add(frames as u64, Ordering::Relaxed);
        self.tx_bytes.fetch_add(bytes as u64, Ordering::Relaxed);
    }

    pub(crate) fn add_tx_error(&self) {
        self.tx_errors.fetch_add(1, Ordering::Relaxed);
    }
}

/// Why [`LinkSender::try_send`] refused a frame.
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
pub enum SendError {
    /// The queue is full: the frame was dropped and counted.
    #[error("egress queue full, frame dropped")]
    Full,
    /// The link is down.
    #[error("link is down")]
    Closed,
}

/// What became of the frames handed to [`LinkSender::try_send_many`].
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct SendSummary {
    /// Sent, or queued for the link's writer.
    pub taken: usize,
    /// Dropped because the queue was full (also counted in the link's `tx_dropped_queue_full`).
    pub full: usize,
    /// Lost because the link is down.
    pub closed: usize,
    /// Not wanted by the link ([`LinkOptions::accept`]).
    pub filtered: usize,
}

impl std::ops::AddAssign for SendSummary {
    fn add_assign(&mut self, o: Self) {
        self.taken += o.taken;
        self.full += o.full;
        self.closed += o.closed;
        self.filtered += o.filtered;
    }
}

/// Which frames a link takes, for an in-process consumer that reads only a few message types
/// (the daemon's own client): the others are never copied to it.
#[derive(Clone)]
pub struct EgressFilter(Arc<dyn Fn(&Frame) -> bool + Send + Sync>);

impl EgressFilter {
    /// A filter that takes the frames for which `accepts` is true.
    pub fn new(accepts: impl Fn(&Frame) -> bool + Send + Sync + 'static) -> Self {
        EgressFilter(Arc::new(accepts))
    }

    /// Whether the link takes `frame`.
    pub fn accepts(&self, frame: &Frame) -> bool {
        (self.0)(frame)
    }
}

impl fmt::Debug for EgressFilter {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str("EgressFilter")
    }
}

/// The egress side of one link: a bounded queue plus the link's counters.
///
/// `try_send` never waits, so one slow peer cannot stall the router; a full queue drops the
/// frame and counts it in `tx_dropped_queue_full`. A UDP peer whose writer has nothing queued
/// gets its datagrams from the caller's task at once, without a task hop.
#[derive(Debug, Clone)]
pub struct LinkSender {
    tx: mpsc::Sender<Frame>,
    stats: Arc<LinkStats>,
    direct: Option<Arc<DirectUdp>>,
    accept: Option<EgressFilter>,
}

impl LinkSender {
    pub(crate) fn new(
        tx: mpsc::Sender<Frame>,
        stats: Arc<LinkStats>,
        accept: Option<EgressFilter>,
    ) -> Self {
        LinkSender {
            tx,
            stats,
            direct: None,
            accept,
        }
    }

    pub(crate) fn with_direct_udp(
        tx: mpsc::Sender<Frame>,
        stats: Arc<LinkStats>,
        accept: Option<EgressFilter>,
        direct: Arc<DirectUdp>,
    ) -> Self {
        LinkSender {
            tx,
            stats,
            direct: Some(direct),
            accept,
        }
    }

    /// Whether the link wants `frame` ([`LinkOptions::accept`]); what it does not want is
    /// dropped by the sending calls and counted as filtered.
    pub fn accepts(&self, frame: &Frame) -> bool {
        self.accept.as_ref().is_none_or(|a| a.accepts(frame))
    }

    /// The UDP peer to send to directly, when its writer has nothing queued (so order holds).
    fn direct_now(&self) -> Option<&DirectUdp> {
        self.direct
            .as_deref()
            .filter(|d| d.queued.load(Ordering::Acquire) == 0 && !self.tx.is_closed())
    }

    /// Queues a frame without waiting; a full queue drops it (counted). A UDP peer whose
    /// writer is idle gets the datagram at once, from the caller's task. A frame the link does
    /// not take ([`LinkOptions::accept`]) is dropped and reported as sent.
    pub fn try_send(&self, frame: Frame) -> Result<(), SendError> {
        if !self.accepts(&frame) {
            return Ok(());
        }
        if let Some(d) = self.direct_now()
            && d.try_send_now(&frame, &self.stats).is_some()
        {
            return Ok(());
        }
        self.try_send_queued(frame)
    }

    /// Sends a run of frames, in order, without waiting, and empties `frames`: to a UDP peer
    /// whose writer is idle in as few system calls as the kernel allows (`sendmmsg`), the rest
    /// (the socket buffer full, or another kind of link) through the queue.
    pub fn try_send_many(&self, frames: &mut Vec<Frame>) -> SendSummary {
        let mut summary = SendSummary::default();
        if self.accept.is_some() {
            let before = frames.len();
            frames.retain(|f| self.accepts(f));
            summary.filtered = before - frames.len();
        }
        let mut start = 0;
        if let Some(d) = self.direct_now() {
            start = d.try_send_now_many(frames, &self.stats);
            summary.taken += start;
        }
        for frame in frames.drain(start..) {
            match self.try_send_queued(frame) {
                Ok(()) => summary.taken += 1,
                Err(SendError::Full) => summary.full += 1,
                Err(SendError::Closed) => summary.closed += 1,
            }
        }
        frames.clear();
        summary
    }

    /// Like [`LinkSender::try_send`] but always through the queue, so the link's own writer
    /// task does the I/O.
    pub fn try_send_queued(&self, frame: Frame) -> Result<(), SendError> {
        self.note_queued(1);
        match self.tx.try_send(frame) {
            Ok(()) => Ok(()),
            Err(mpsc::error::TrySendError::Full(_)) => {
                self.note_queued(-1);
                self.stats
                    .tx_dropped_queue_full
                    .fetch_add(1, Ordering::Relaxed);
                Err(SendError::Full)
            }
            Err(mpsc::error::TrySendError::Closed(_)) => {
                self.note_queued(-1);
                Err(SendError::Closed)
            }
        }
    }

    fn note_queued(&self, delta: isize) {
        if let Some(d) = &self.direct {
            if delta > 0 {
                d.queued.fetch_add(1, Ordering::AcqRel);
            } else {
                d.queued.fetch_sub(1, Ordering::AcqRel);
            }
        }
    }

    /// Queues a frame, waiting for room (for traffic that must not be dropped, e.g. a
    /// vehicle's replies on an in-memory link). Errors only if the link is down.
    pub async fn send(&self, frame: Frame) -> Result<(), SendError> {
        if !self.accepts(&frame) {
            return Ok(());
        }
        if let Some(d) = self.direct_now()
            && d.try_send_now(&frame, &self.stats).is_some()
        {
            return Ok(());
        }
        self.note_queued(1);
        let r = self.tx.send(frame).await.map_err(|_| SendError::Closed);
        if r.is_err() {
            self.note_queued(-1);
        }
        r
    }

    /// Free places in the egress queue now: a producer with traffic of two priorities sheds
    /// the lower one before the queue is full.
    pub fn room(&self) -> usize {
        self.tx.capacity()
    }

    /// True once the link is down.
    pub fn is_closed(&self) -> bool {
        self.tx.is_closed()
    }

    /// Completes when the link is down (its queue's receiver is gone).
    pub async fn closed(&self) {
        self.tx.closed().await
    }

    /// The link's counters.
    pub fn stats(&self) -> &Arc<LinkStats> {
        &self.stats
    }
}

/// Tuning for links. `Default` gives the values documented on each field.
#[derive(Debug, Clone)]
pub struct LinkOptions {
    /// Egress queue length per link, in frames (default 1024).
    pub queue_len: usize,
    /// A UDP peer that sends nothing for this long goes down (default 10 s).
    pub udp_peer_timeout: Duration,
    /// A `udpin` endpoint whose peers are vehicles (default false): a new peer address that
    /// sends as a system id another peer of the endpoint sent as is that vehicle come back
    /// (a restarted process, a radio bridge, a new NAT mapping): the old peer's link goes
    /// down and the new address is followed at once, as mavlink-router's UDP server follows
    /// its last sender. Off for clients, where scripts share system id 255.
    pub udp_follow_system: bool,
    /// First reconnect delay for TCP clients and serial ports (default 100 ms).
    pub reconnect_min: Duration,
    /// Cap of the doubling reconnect delay (default 2 s).
    pub reconnect_max: Duration,
    /// Open a serial endpoint whose device does not exist yet and wait for it to appear
    /// (default false: a missing device at start is an error, most likely a typo).
    pub wait_for_device: bool,
    /// Which frames the links take (default: all). For an in-process consumer that reads only
    /// a few message types: the others are never copied to it.
    pub accept: Option<EgressFilter>,
    /// The Zenoh session and this end's role, for `zenoh:` URLs.
    pub zenoh: ZenohOptions,
}

/// How a `zenoh:` endpoint joins the Zenoh network, and which end of the fleet it is.
#[derive(Debug, Clone, Default, PartialEq, Eq, Hash)]
pub struct ZenohOptions {
    /// Peer (default), client of a router, or a router itself.
    pub mode: ZenohMode,
    /// Endpoints to connect to, e.g. `tcp/127.0.0.1:7447`.
    pub connect: Vec<String>,
    /// Endpoints to listen on, e.g. `tcp/0.0.0.0:7447`.
    pub listen: Vec<String>,
    /// Which end of the fleet a `zenoh:` URL opens here.
    pub role: ZenohRole,
}

/// Zenoh's session modes.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Hash)]
pub enum ZenohMode {
    /// Talks to peers directly, and to routers.
    #[default]
    Peer,
    /// Talks through one router.
    Client,
    /// Routes for clients and peers (what `zenohd` does).
    Router,
}

impl std::str::FromStr for ZenohMode {
    type Err = String;

    fn from_str(s: &str) -> Result<Self, Self::Err> {
        match s {
            "peer" => Ok(ZenohMode::Peer),
            "client" => Ok(ZenohMode::Client),
            "router" => Ok(ZenohMode::Router),
            other => Err(format!(
                "unknown Zenoh mode '{other}'; expected peer, client or router"
            )),
        }
    }
}

impl fmt::Display for ZenohMode {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            ZenohMode::Peer => "peer",
            ZenohMode::Client => "client",
            ZenohMode::Router => "router",
        })
    }
}

/// Which end of a fleet a `zenoh:` URL opens.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Hash)]
pub enum ZenohRole {
    /// The ground end (a daemon's vehicle side): each vehicle of the fleet is a link, its
    /// frames read from `from_vehicle`, its egress published on `to_vehicle`.
    #[default]
    Ground,
    /// The vehicle's end (a daemon's serve side): one link whose egress, what the vehicle
    /// sends, is published on `from_vehicle`, and whose ingress is `to_vehicle`.
    Vehicle,
}

impl Default for LinkOptions {
    fn default() -> Self {
        LinkOptions {
            queue_len: 1024,
            udp_peer_timeout: Duration::from_secs(10),
            udp_follow_system: false,
            reconnect_min: Duration::from_millis(100),
            reconnect_max: Duration::from_secs(2),
            wait_for_device: false,
            accept: None,
            zenoh: ZenohOptions::default(),
        }
    }
}

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

    /// The task handle, for `select!` or abort.
    pub fn into_join_handle(self) -> JoinHandle<()> {
        self.task
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
            let (addr, task) = udp::spawn_udpin(url, host, *port, events, opts, cancel).await?;
            (Some(addr), None, task)
        }
        LinkUrl::UdpOut { host, port } => {
            let (addr, id, task) =
                udp::spawn_udpout(url, host, *port, events, opts, cancel).await?;
            (Some(addr), Some(id), task)
        }
        LinkUrl::TcpIn { host, port } => {
            let (addr, task) = tcp::spawn_tcpin(url, host, *port, events, opts, cancel).await?;
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

/// Takes a link's events in the task that received them: no queue and no task hop between a
/// link and its owner. The owner (the daemon's router) routes each frame before the link task
/// reads its socket again.
///
/// Implementations must not block: they run inside the links' tasks.
pub trait LinkEventHandler: Send + Sync {
    /// Handles one event. False when the owner is gone: the link stops.
    fn event(&self, event: LinkEvent) -> bool;

    /// Handles the frames one wake-up of a link task received, in order, and empties `frames`.
    /// False when the owner is gone. The default hands them to [`LinkEventHandler::event`] one
    /// by one; an owner that can do better with a run (one lock, one batched send per egress
    /// link) overrides it.
    fn frames(&self, frames: &mut Vec<(LinkId, Frame)>) -> bool {
        for (id, frame) in frames.drain(..) {
            if !self.event(LinkEvent::Frame { id, frame }) {
                return false;
            }
        }
        true
    }

    /// True once the owner is gone for good (a reconnecting link then stops trying).
    fn is_closed(&self) -> bool {
        false
    }
}

/// Where links report their events: a bounded queue read by an owner task, or a handler called
/// inline by the link tasks. `From<mpsc::Sender<LinkEvent>>` makes a queue.
#[derive(Clone)]
pub enum Events {
    /// A bounded queue; a full queue makes the link wait (it is the owner's job to keep up).
    Queue(mpsc::Sender<LinkEvent>),
    /// A handler called from the link tasks.
    Inline(Arc<dyn LinkEventHandler>),
}

impl fmt::Debug for Events {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Events::Queue(tx) => f.debug_tuple("Queue").field(tx).finish(),
            Events::Inline(_) => f.write_str("Inline"),
        }
    }
}

impl From<mpsc::Sender<LinkEvent>> for Events {
    fn from(tx: mpsc::Sender<LinkEvent>) -> Self {
        Events::Queue(tx)
    }
}

impl From<Arc<dyn LinkEventHandler>> for Events {
    fn from(handler: Arc<dyn LinkEventHandler>) -> Self {
        Events::Inline(handler)
    }
}

impl Events {
    /// True once the owner is gone.
    pub fn is_closed(&self) -> bool {
        match self {
            Events::Queue(tx) => tx.is_closed(),
            Events::Inline(h) => h.is_closed(),
        }
    }
}

/// Sends an event unless shutting down; false if the link should stop.
pub(crate) async fn emit(events: &Events, event: LinkEvent, cancel: &CancellationToken) -> bool {
    let tx = match events {
        Events::Inline(h) => return h.event(event),
        Events::Queue(tx) => tx,
    };
    // The common case, room in the queue, needs no future and no select.
    let event = match tx.try_send(event) {
        Ok(()) => return true,
        Err(mpsc::error::TrySendError::Closed(_)) => return false,
        Err(mpsc::error::TrySendError::Full(event)) => event,
    };
    tokio::select! {
        biased;
        _ = cancel.cancelled() => false,
        r = tx.send(event) => r.is_ok(),
    }
}

/// Sends the frames of one wake-up, in order, and empties `frames`; false if the link should
/// stop.
pub(crate) async fn emit_frames(
    events: &Events,
    frames: &mut Vec<(LinkId, Frame)>,
    cancel: &CancellationToken,
) -> bool {
    if frames.is_empty() {
        return true;
    }
    if let Events::Inline(h) = events {
        return h.frames(frames);
    }
    for (id, frame) in frames.drain(..) {
        if !emit(events, LinkEvent::Frame { id, frame }, cancel).await {
            return false;
        }
    }
    true
}

/// Reports a link as down. During shutdown the owner may be gone or not reading, so do not
/// wait then.
pub(crate) async fn emit_down(
    events: &Events,
    id: LinkId,
    reason: String,
    cancel: &CancellationToken,
) {
    tracing::debug!(%id, %reason, "link down");
    let ev = LinkEvent::Down { id, reason };
    match events {
        Events::Inline(h) => {
            h.event(ev);
        }
        Events::Queue(tx) if cancel.is_cancelled() => {
            let _ = tx.try_send(ev);
        }
        Events::Queue(tx) => {
            let _ = tx.send(ev).await;
        }
    }
}

/// Starts `batch` with `first` and appends the frames already queued behind it, up to
/// `max_bytes` (one write of a stream, one publication): returns how many frames it holds.
pub(crate) fn take_batch(
    first: &Frame,
    rx: &mut mpsc::Receiver<Frame>,
    batch: &mut Vec<u8>,
    max_bytes: usize,
) -> usize {
    batch.clear();
    batch.extend_from_slice(first.as_bytes());
    let mut frames = 1;
    while batch.len() < max_bytes {
        match rx.try_recv() {
            Ok(f) => {
                batch.extend_from_slice(f.as_bytes());
                frames += 1;
            }
            Err(_) => break,
        }
    }
    frames
}

/// Sleeps unless cancelled; false if cancelled.
pub(crate) async fn sleep_or_cancel(d: Duration, cancel: &CancellationToken) -> bool {
    tokio::select! {
        _ = cancel.cancelled() => false,
        _ = tokio::time::sleep(d) => true,
    }
}

/// Capped exponential back-off for reconnects.
#[derive(Debug)]
pub(crate) struct Backoff {
    next: Duration,
    min: Duration,
    max: Duration,
}

impl Backoff {
    pub(crate) fn new(opts: &LinkOptions) -> Self {
        let min = opts.reconnect_min.max(Duration::from_millis(1));
        Backoff {
            next: min,
            min,
            max: opts.reconnect_max.max(min),
        }
    }

    /// The delay to wait now; doubles the following one up to the cap.
    pub(crate) fn next_delay(&mut self) -> Duration {
        let d = self.next;
        self.next = (self.next * 2).min(self.max);
        d
    }

    /// After a connection that lasted, start again from the minimum.
    pub(crate) fn reset(&mut self) {
        self.next = self.min;
    }

    pub(crate) fn max(&self) -> Duration {
        self.max
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn backoff_doubles_to_cap_and_resets() {
        let mut b = Backoff::new(&LinkOptions::default());
        let seq: Vec<_> = (0..7).map(|_| b.next_delay().as_millis()).collect();
        assert_eq!(seq, vec![100, 200, 400, 800, 1600, 2000, 2000]);
        b.reset();
        assert_eq!(b.next_delay().as_millis(), 100);
    }

    #[test]
    fn link_ids_are_unique() {
        let a = LinkId::next();
        let b = LinkId::next();
        assert_ne!(a, b);
    }
}
