//! UDP endpoints: `udpin` (server, one link per peer heard) and `udpout` (fixed destination).
//!
//! Unlike the `mavlink` crate's udpin, which replies only to the last sender (PROTOCOL.md
//! E.3), every peer address is its own link with its own queue, decoder and counters, as
//! pymavlink's `mavudp` keeps a client set. Each frame goes out as its own datagram, which is
//! what pymavlink and MAVProxy expect.
//!
//! Each received datagram is parsed to its end ([`FrameDecoder::finish`]): MAVLink over UDP
//! carries whole frames, and treating the datagram boundary as final means a false candidate
//! (e.g. a stray 0xFE with a large length) can never hold back the real frames behind it until
//! the next datagram. The cost: a frame split across two datagrams (a raw serial-to-UDP
//! bridge) is dropped, where pymavlink would reassemble it.
//!
//! One way to run a socket, whoever takes the events: a forwarder's cost is its system calls
//! and wake-ups per datagram, so the socket is read by a thread of its own in blocking mode,
//! like a bare `recvfrom` loop: one `recvfrom` sleeps and takes a datagram, or, while they come
//! in bursts, one `recvmmsg` takes every datagram waiting; the owner handles their frames
//! before the next one. An inline owner ([`Events::Inline`], the daemon's router) routes them
//! on that thread; a queue owner ([`Events::Queue`], the twin, the command-line client, tools)
//! gets them in its queue, and a full queue makes the reader wait ([`QueueHandler`]). The
//! socket is never registered with the async reactor, so sending on it (which the kernel
//! follows with a "writable" event for every datagram) wakes nobody. Nor does the thread sleep
//! with a timeout (a kernel timer armed and cancelled per datagram): a task wakes it with an
//! empty datagram of its own when it is to stop, or when it has timers due and no traffic woke
//! it ([`Wakeup`]).
//!
//! A producer sends straight to a peer whose writer has nothing queued (one `sendto`, or one
//! `sendmmsg` for a run of frames, never waiting), so the writer task only wakes when the
//! socket buffer was full.
//!
//! An inline owner's **udpout socket is connected to its destination** ([`Connection`]): the
//! kernel then keeps the route instead of looking it up for every datagram, ~0.7 µs of a
//! `sendto`'s ~5 µs on the benchmark machine, once per frame and client. A connected socket
//! hears only its destination, while a udpout link hears whatever arrives on its port
//! (pymavlink does the same): a second, unconnected socket shares the port
//! (`SO_REUSEPORT`) and takes the datagrams from any other address, on a task, since they are
//! rare. With nobody listening at the destination, the kernel reports each datagram's ICMP
//! "port unreachable" (or "host unreachable") to a connected socket as an error (Linux does
//! not rate-limit them on loopback): the first one dissolves the connection, the datagram that
//! met it is sent again with the address, so such a link costs and counts what an unconnected
//! one does, and a datagram from the destination (a listener that answers) connects it again.
//! Where any of this cannot be set up (a broadcast address, another OS) the link runs
//! unconnected, on one socket.

use std::collections::hash_map::Entry;
use std::io::{self, IoSlice, IoSliceMut};
use std::net::{Ipv4Addr, Ipv6Addr, SocketAddr, UdpSocket};
use std::os::fd::AsRawFd;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, AtomicU64, AtomicUsize, Ordering};
use std::time::{Duration, Instant};

use nix::sys::socket::{MsgFlags, MultiHeaders, SockaddrStorage, recvmmsg};
use tokio::sync::mpsc;
use tokio::task::JoinHandle;
use tokio_util::sync::CancellationToken;
use tokio_util::task::TaskTracker;

use super::{
    Events, LinkError, LinkEvent, LinkEventHandler, LinkId, LinkOptions, LinkSender, LinkStats,
    resolve, sleep_or_cancel,
};
use crate::decoder::FrameDecoder;
use crate::frame::Frame;
use crate::ids::SystemId;
use crate::url::LinkUrl;

/// Largest UDP payload: one receive slot, so no datagram is ever truncated.
const MAX_DATAGRAM_BYTES: usize = 65_536;
/// Pause after a receive error so a persistent error cannot become a busy loop.
const RECV_ERROR_PAUSE: Duration = Duration::from_millis(50);
/// Most datagrams a socket's reader takes per wake-up before it looks at its timers again.
const RECV_BATCH: usize = 32;
/// The same for a udpout socket, which only hears its peer's replies.
const REPLY_BATCH: usize = 8;
/// Most datagrams per `sendmmsg`.
const SEND_BATCH: usize = 64;
/// Most frames a UDP writer takes from its queue per wake-up.
const WRITE_BATCH: usize = 64;
/// How often a stopping blocking reader is woken again until it is gone, and its receive
/// timeout when it cannot be woken by a datagram ([`Wakeup`]).
pub(crate) const BLOCKING_TICK: Duration = Duration::from_millis(100);
/// How long a writer whose blocking socket's buffer is full waits before it tries again (a
/// blocking socket has no readiness events to wait on; a full UDP send buffer is rare).
const FULL_RETRY: Duration = Duration::from_millis(1);

/// A queue owner's events, from a reader's thread: a full queue makes the reader wait, as it
/// makes any link of a queue owner wait, unless the endpoint is stopping.
struct QueueHandler {
    tx: mpsc::Sender<LinkEvent>,
    cancel: CancellationToken,
    runtime: tokio::runtime::Handle,
}

impl LinkEventHandler for QueueHandler {
    fn event(&self, event: LinkEvent) -> bool {
        // The common case, room in the queue, needs no future.
        let event = match self.tx.try_send(event) {
            Ok(()) => return true,
            Err(mpsc::error::TrySendError::Closed(_)) => return false,
            Err(mpsc::error::TrySendError::Full(event)) => event,
        };
        // Called on a reader's own thread, never on the runtime's.
        self.runtime.block_on(async {
            tokio::select! {
                biased;
                () = self.cancel.cancelled() => false,
                r = self.tx.send(event) => r.is_ok(),
            }
        })
    }

    fn is_closed(&self) -> bool {
        self.tx.is_closed()
    }
}

/// The handler a reader's thread calls: the owner's, or one filling the owner's queue.
fn handler(events: Events, cancel: &CancellationToken) -> Arc<dyn LinkEventHandler> {
    match events {
        Events::Inline(h) => h,
        Events::Queue(tx) => Arc::new(QueueHandler {
            tx,
            cancel: cancel.clone(),
            runtime: tokio::runtime::Handle::current(),
        }),
    }
}

/// A UDP peer that producers may send to themselves while nothing is queued for the peer's
/// writer: a datagram then leaves without waking the writer task, which costs a task hop per
/// frame. Frames queued while the writer is busy keep their order, because a producer only
/// goes direct once the writer has sent everything it was given.
#[derive(Debug)]
pub(crate) struct DirectUdp {
    sock: Arc<UdpSocket>,
    dest: SocketAddr,
    /// Frames handed to the writer's queue and not yet sent by it.
    pub(crate) queued: AtomicUsize,
    /// A udpout socket connected to `dest`: send without an address while it is.
    connection: Option<Arc<Connection>>,
}

/// Whether a udpout socket is connected to its destination; see the module's documentation.
#[derive(Debug)]
struct Connection {
    dest: SocketAddr,
    /// True while the socket is connected: sends go without an address.
    on: AtomicBool,
    /// Serialises connecting and dissolving, so that `on` is true only while the socket is
    /// connected (a send may still meet a connection dissolved since it looked: it then sends
    /// with the address).
    change: std::sync::Mutex<()>,
}

impl Connection {
    fn is_on(&self) -> bool {
        self.on.load(Ordering::Relaxed)
    }

    /// Nobody listens at the destination (the kernel reported an ICMP error): send with the
    /// address from now on, which the kernel does not answer with errors.
    fn dissolve(&self, sock: &UdpSocket) {
        let Ok(_guard) = self.change.lock() else {
            return;
        };
        if self.on.swap(false, Ordering::Relaxed) {
            if let Err(e) = rustix::net::connect_unspec(sock) {
                tracing::debug!(dest = %self.dest, "udp disconnect: {e}");
            }
            tracing::debug!(dest = %self.dest, "nobody listens: udpout socket unconnected");
        }
    }

    /// A datagram came from the destination: connect again.
    fn reconnect(&self, sock: &UdpSocket) {
        let Ok(_guard) = self.change.lock() else {
            return;
        };
        if !self.is_on() {
            match rustix::net::connect(sock, &self.dest) {
                Ok(()) => {
                    self.on.store(true, Ordering::Relaxed);
                    tracing::debug!(dest = %self.dest, "udpout socket connected again");
                }
                Err(e) => tracing::debug!(dest = %self.dest, "udp connect: {e}"),
            }
        }
    }
}

/// The errors the kernel reports to a connected socket from an ICMP message about an earlier
/// datagram: nobody listens (or can be reached) at the destination.
fn is_icmp_error(e: &io::Error) -> bool {
    use rustix::io::Errno;
    matches!(
        Errno::from_io_error(e),
        Some(Errno::CONNREFUSED | Errno::HOSTUNREACH | Errno::NETUNREACH | Errno::HOSTDOWN)
    )
}

/// The errors of a send on a socket that is no longer connected.
fn is_unconnected(e: &io::Error) -> bool {
    matches!(
        rustix::io::Errno::from_io_error(e),
        Some(rustix::io::Errno::DESTADDRREQ | rustix::io::Errno::NOTCONN)
    )
}

impl DirectUdp {
    fn connected(&self) -> Option<&Connection> {
        self.connection.as_deref().filter(|c| c.is_on())
    }

    /// One datagram: without the address on a connected socket.
    fn send_one(&self, bytes: &[u8]) -> io::Result<usize> {
        let flags = rustix::net::SendFlags::DONTWAIT;
        if let Some(c) = self.connected() {
            let sent = rustix::net::send(&*self.sock, bytes, flags).map_err(io::Error::from);
            match sent {
                Err(e) if is_icmp_error(&e) => {
                    // The error belongs to an earlier datagram; this one is still to send.
                    c.dissolve(&self.sock);
                }
                Err(e) if is_unconnected(&e) => {}
                r => return r,
            }
        }
        rustix::net::sendto(&*self.sock, bytes, flags, &self.dest).map_err(io::Error::from)
    }

    /// Sends one datagram now if the socket has room: `None` when it would block.
    pub(crate) fn try_send_now(&self, frame: &Frame, stats: &LinkStats) -> Option<()> {
        match self.send_one(frame.as_bytes()) {
            Ok(n) => stats.add_tx(1, n),
            Err(e) if e.kind() == io::ErrorKind::WouldBlock => return None,
            Err(e) => {
                // Lost like any UDP datagram (e.g. ENOBUFS): counted, the link goes on.
                tracing::debug!(dest = %self.dest, "udp send error: {e}");
                stats.add_tx_error();
            }
        }
        Some(())
    }

    /// Sends the frames in order, one datagram each, batched into `sendmmsg` calls, until the
    /// socket buffer is full. Returns how many were dealt with (sent, or lost to an error and
    /// counted); the rest must wait for room.
    pub(crate) fn try_send_now_many(&self, frames: &[Frame], stats: &LinkStats) -> usize {
        if let [frame] = frames {
            return usize::from(self.try_send_now(frame, stats).is_some());
        }
        let addr = rustix::net::addr::SocketAddrArg::as_any(&self.dest);
        let mut done = 0;
        // Without addresses while connected, until a send finds the connection gone.
        let mut connected = self.connected();
        while done < frames.len() {
            let chunk = &frames[done..frames.len().min(done + SEND_BATCH)];
            let iovs: Vec<[IoSlice<'_>; 1]> =
                chunk.iter().map(|f| [IoSlice::new(f.as_bytes())]).collect();
            let mut no_control: Vec<rustix::net::SendAncillaryBuffer<'_, '_, '_>> =
                chunk.iter().map(|_| Default::default()).collect();
            let mut msgs: Vec<rustix::net::MMsgHdr<'_>> = iovs
                .iter()
                .zip(no_control.iter_mut())
                .map(|(iov, control)| {
                    if connected.is_some() {
                        rustix::net::MMsgHdr::new(iov, control)
                    } else {
                        rustix::net::MMsgHdr::new_with_addr(&addr, iov, control)
                    }
                })
                .collect();
            let sent =
                rustix::net::sendmmsg(&*self.sock, &mut msgs, rustix::net::SendFlags::DONTWAIT)
                    .map_err(io::Error::from);
            match sent {
                Ok(0) => break,
                Ok(n) => {
                    let bytes = msgs[..n].iter().map(rustix::net::MMsgHdr::bytes_sent).sum();
                    stats.add_tx(n, bytes);
                    done += n;
                }
                Err(e) if e.kind() == io::ErrorKind::WouldBlock => break,
                Err(e) if connected.is_some() && is_icmp_error(&e) => {
                    // An earlier datagram's error: nobody listens; these are still to send.
                    if let Some(c) = connected.take() {
                        c.dissolve(&self.sock);
                    }
                }
                Err(e) if connected.is_some() && is_unconnected(&e) => connected = None,
                Err(e) => {
                    // The first datagram of the call failed (ENOBUFS …): lost like any UDP
                    // datagram, counted, and the rest go on.
                    tracing::debug!(dest = %self.dest, "udp send error: {e}");
                    stats.add_tx_error();
                    done += 1;
                }
            }
        }
        done
    }
}

/// Datagrams closer together than this put a reader in batch mode (about 50 000 a second).
const BATCH_GAP: Duration = Duration::from_micros(20);

/// Receive buffers for one blocking reader and what the last receive put in them.
///
/// A reader sleeps in one `recvfrom` while datagrams come one per wake-up, as a bare loop
/// does, and in one `recvmmsg(MSG_WAITFORONE)` while they come in bursts (the last wake-up
/// found several, or they arrive less than [`BATCH_GAP`] apart). `recvmmsg` always tries once
/// more after the first datagram, so a lone datagram costs it a second, empty receive in the
/// kernel: at 10 000 frames a second that was most of a daemon's extra kernel time over a
/// bare forwarder.
struct Datagrams {
    buf: Vec<u8>,
    slots: usize,
    headers: MultiHeaders<SockaddrStorage>,
    got: Vec<(usize, Option<SocketAddr>)>,
    /// Take the next wake-up with `recvmmsg`.
    batch: bool,
    /// When the last wake-up returned.
    last: Option<Instant>,
}

impl Datagrams {
    fn new(slots: usize) -> Self {
        let slots = slots.clamp(1, RECV_BATCH);
        Datagrams {
            // Pages are only touched where datagrams land: a few per slot at most.
            buf: vec![0u8; slots * MAX_DATAGRAM_BYTES],
            slots,
            headers: MultiHeaders::preallocate(slots, None),
            got: Vec::with_capacity(slots),
            batch: false,
            last: None,
        }
    }

    /// Sleeps until a datagram arrives (or the socket's read timeout passes, `WouldBlock`),
    /// then takes it and, in batch mode, every other one waiting, up to the number of slots.
    /// `now` is read after the wake-up and returned for the caller's timers.
    fn recv(&mut self, sock: &UdpSocket) -> io::Result<(usize, Instant)> {
        let n = if self.batch || self.slots == 1 {
            self.recv_many(sock)?
        } else {
            self.recv_one(sock)?
        };
        let now = Instant::now();
        let close = self
            .last
            .is_some_and(|t| now.saturating_duration_since(t) < BATCH_GAP);
        self.batch = self.slots > 1 && (n > 1 || close);
        self.last = Some(now);
        Ok((n, now))
    }

    /// One `recvfrom` into the first slot.
    fn recv_one(&mut self, sock: &UdpSocket) -> io::Result<usize> {
        self.got.clear();
        // Not `UdpSocket::recv_from`: a socket whose receiving side was shut down (how a
        // connected reader is told to stop) returns without a sender address, which the
        // standard library asserts never happens.
        let (n, _, addr) = rustix::net::recvfrom(
            sock,
            &mut self.buf[..MAX_DATAGRAM_BYTES],
            rustix::net::RecvFlags::empty(),
        )?;
        self.got
            .push((n, addr.and_then(|a| SocketAddr::try_from(a).ok())));
        Ok(1)
    }

    /// One `recvmmsg(MSG_WAITFORONE)`: the first datagram, then every other one waiting.
    fn recv_many(&mut self, sock: &UdpSocket) -> io::Result<usize> {
        self.got.clear();
        let mut chunks = self.buf.chunks_mut(MAX_DATAGRAM_BYTES);
        let mut iovs: [[IoSliceMut<'_>; 1]; RECV_BATCH] =
            std::array::from_fn(|_| [IoSliceMut::new(chunks.next().unwrap_or_default())]);
        let msgs = recvmmsg(
            sock.as_raw_fd(),
            &mut self.headers,
            iovs[..self.slots].iter_mut(),
            MsgFlags::MSG_WAITFORONE,
            None,
        )
        .map_err(io::Error::from)?;
        for m in msgs {
            self.got.push((m.bytes, m.address.and_then(to_std)));
        }
        Ok(self.got.len())
    }

    /// The datagrams of the last receive: (bytes, sender).
    fn iter(&self) -> impl Iterator<Item = (&[u8], Option<SocketAddr>)> {
        self.got.iter().enumerate().map(|(i, (n, addr))| {
            let start = i * MAX_DATAGRAM_BYTES;
            (&self.buf[start..start + n], *addr)
        })
    }
}

fn to_std(a: SockaddrStorage) -> Option<SocketAddr> {
    a.as_sockaddr_in()
        .map(|v4| SocketAddr::from(*v4))
        .or_else(|| a.as_sockaddr_in6().map(|v6| SocketAddr::from(*v6)))
}

/// Binds `addrs` in turn: a socket for a blocking reader.
fn bind(url: &LinkUrl, addrs: &[SocketAddr]) -> Result<Arc<UdpSocket>, LinkError> {
    let io_err = |source| LinkError::Io {
        url: url.to_string(),
        source,
    };
    let mut last = None;
    for &addr in addrs {
        match UdpSocket::bind(addr) {
            Ok(s) => {
                grow_recv_buffer(&s);
                s.set_read_timeout(Some(BLOCKING_TICK)).map_err(io_err)?;
                return Ok(Arc::new(s));
            }
            Err(source) => last = Some((addr, source)),
        }
    }
    let (addr, source) = last.expect("resolve returns at least one address");
    Err(LinkError::Bind {
        url: url.to_string(),
        addr,
        source,
    })
}

/// Receive buffer asked for every UDP socket. Linux doubles what is asked and counts each small
/// datagram as ~770 bytes, so this holds ~2 700 of them: about a quarter of a second at 10 000 a
/// second, where Linux's default (`net.core.rmem_default`, 212 992 bytes) holds ~25 ms. A
/// reader kept off its CPU for longer than that (a busy machine, a stalled VM) would lose
/// datagrams in the kernel, where no counter of ours sees them. Not more: under a sustained
/// overload a full buffer is latency (at saturation the frames wait their turn in it). The kernel
/// grants at most `net.core.rmem_max` (beyond it only with `CAP_NET_ADMIN`); the memory is only
/// used while datagrams wait.
pub(crate) const RECV_BUFFER_BYTES: usize = 1 << 20;

/// Asks for [`RECV_BUFFER_BYTES`] of receive buffer; whatever is granted, the socket works.
fn grow_recv_buffer(s: &UdpSocket) {
    use rustix::net::sockopt;
    let granted = |s| sockopt::socket_recv_buffer_size(s).unwrap_or(0);
    let before = granted(s);
    // Linux reports twice what was asked (its bookkeeping overhead).
    if before >= 2 * RECV_BUFFER_BYTES {
        return;
    }
    if let Err(e) = sockopt::set_socket_recv_buffer_size(s, RECV_BUFFER_BYTES) {
        tracing::debug!("udp receive buffer: {e}");
    }
    if granted(s) < 2 * RECV_BUFFER_BYTES {
        // Beyond rmem_max: only with CAP_NET_ADMIN.
        let _ = sockopt::set_socket_recv_buffer_size_force(s, RECV_BUFFER_BYTES);
    }
    if granted(s) < before {
        // An rmem_max below the default: keep the default.
        let _ = sockopt::set_socket_recv_buffer_size(s, before / 2);
    }
    tracing::debug!(bytes = granted(s), "udp receive buffer");
}

fn local_addr(url: &LinkUrl, sock: &UdpSocket) -> Result<SocketAddr, LinkError> {
    sock.local_addr().map_err(|source| LinkError::Io {
        url: url.to_string(),
        source,
    })
}

/// Writes what producers could not send directly (the socket buffer was full), in order, one
/// datagram per frame, until cancelled.
async fn udp_writer(
    direct: Arc<DirectUdp>,
    mut rx: mpsc::Receiver<Frame>,
    stats: Arc<LinkStats>,
    cancel: CancellationToken,
) {
    let mut batch: Vec<Frame> = Vec::with_capacity(WRITE_BATCH);
    loop {
        let n = tokio::select! {
            _ = cancel.cancelled() => return,
            n = rx.recv_many(&mut batch, WRITE_BATCH) => n,
        };
        if n == 0 {
            // Owner dropped the sender: nothing more to send, wait for the end.
            cancel.cancelled().await;
            return;
        }
        let mut sent = 0;
        while sent < batch.len() {
            sent += direct.try_send_now_many(&batch[sent..], &stats);
            if sent < batch.len() {
                // A blocking socket has no readiness to wait on: try again shortly.
                if !sleep_or_cancel(FULL_RETRY, &cancel).await {
                    return;
                }
            }
        }
        // Only now may producers send directly again: these frames are out, in order.
        direct.queued.fetch_sub(batch.len(), Ordering::AcqRel);
        batch.clear();
    }
}

/// The writer of one UDP peer and the sender the owner uses for it.
fn udp_link(
    sock: &Arc<UdpSocket>,
    dest: SocketAddr,
    connection: Option<Arc<Connection>>,
    stats: &Arc<LinkStats>,
    opts: &LinkOptions,
    cancel: CancellationToken,
) -> (
    LinkSender,
    impl std::future::Future<Output = ()> + Send + 'static,
) {
    let (tx, rx) = mpsc::channel(opts.queue_len.max(1));
    let direct = Arc::new(DirectUdp {
        sock: sock.clone(),
        dest,
        queued: AtomicUsize::new(0),
        connection,
    });
    let sender =
        LinkSender::with_direct_udp(tx, stats.clone(), opts.accept.clone(), direct.clone());
    (sender, udp_writer(direct, rx, stats.clone(), cancel))
}

/// State of one UDP peer (one link) of a udpin socket.
struct Peer {
    id: LinkId,
    last_heard: Instant,
    decoder: FrameDecoder,
    stats: Arc<LinkStats>,
    writer_cancel: CancellationToken,
    /// The system ids it sent as, when the endpoint follows its vehicles
    /// ([`LinkOptions::udp_follow_system`]).
    systems: Vec<SystemId>,
}

/// What a datagram changed in the peers of a udpin socket ([`Peers::on_datagram`]).
#[derive(Default)]
struct Arrival {
    /// A peer that came back from the datagram's address: its old link is down, for the
    /// caller to report after the frames before `start` and before the new link's `Up`.
    replaced: Option<(LinkId, String)>,
    /// A new link, for the caller to report before the datagram's frames.
    up: Option<LinkEvent>,
    /// Where the datagram's frames start in the caller's list.
    start: usize,
}

/// The peers of a udpin socket.
struct Peers {
    sock: Arc<UdpSocket>,
    by_addr: foldhash::HashMap<SocketAddr, Peer>,
    writers: TaskTracker,
    runtime: tokio::runtime::Handle,
    opts: LinkOptions,
    cancel: CancellationToken,
}

impl Peers {
    fn new(sock: Arc<UdpSocket>, opts: LinkOptions, cancel: CancellationToken) -> Self {
        Peers {
            sock,
            by_addr: foldhash::HashMap::default(),
            writers: TaskTracker::new(),
            runtime: tokio::runtime::Handle::current(),
            opts,
            cancel,
        }
    }

    /// Takes a datagram from `addr`: its frames are added to `frames`. A new peer becomes a
    /// link (its writer starts) and its `Up` event is returned, for the caller to report
    /// before the frames; a peer it replaces ([`Peers::follow`]) is returned too.
    fn on_datagram(
        &mut self,
        addr: SocketAddr,
        data: &[u8],
        now: Instant,
        frames: &mut Vec<(LinkId, Frame)>,
    ) -> Arrival {
        let start = frames.len();
        let up = self.decode(addr, data, now, frames);
        let replaced = if self.opts.udp_follow_system {
            self.follow(addr, &frames[start..])
        } else {
            None
        };
        Arrival {
            replaced,
            up,
            start,
        }
    }

    /// A vehicle that comes back from a new address (a restarted process, a new NAT mapping)
    /// is the same vehicle: when the peer at `addr` sends as a system id another peer of this
    /// endpoint sent as, that peer is gone and `addr` takes over at once, as mavlink-router's
    /// UDP server follows its last sender. Returns the replaced peer's link and why it ended.
    fn follow(&mut self, addr: SocketAddr, frames: &[(LinkId, Frame)]) -> Option<(LinkId, String)> {
        let peer = self.by_addr.get_mut(&addr)?;
        let mut new = Vec::new();
        for (_, f) in frames {
            let system = f.sender().0;
            if !peer.systems.contains(&system) {
                peer.systems.push(system);
                new.push(system);
            }
        }
        if new.is_empty() {
            return None;
        }
        let old = self
            .by_addr
            .iter()
            .find(|(a, p)| **a != addr && p.systems.iter().any(|s| new.contains(s)))
            .map(|(a, _)| *a)?;
        let p = self.by_addr.remove(&old)?;
        p.writer_cancel.cancel();
        tracing::info!(id = %p.id, %old, new = %addr, "udp peer came back from a new address");
        Some((p.id, format!("udp peer {old} came back from {addr}")))
    }

    /// Decodes a datagram from `addr` into `frames`; a new peer's `Up` is returned.
    fn decode(
        &mut self,
        addr: SocketAddr,
        data: &[u8],
        now: Instant,
        frames: &mut Vec<(LinkId, Frame)>,
    ) -> Option<LinkEvent> {
        let (peer, up) = match self.by_addr.entry(addr) {
            Entry::Occupied(o) => (o.into_mut(), None),
            Entry::Vacant(v) => {
                let id = LinkId::next();
                let stats = Arc::new(LinkStats::default());
                let writer_cancel = self.cancel.child_token();
                let (tx, writer) = udp_link(
                    &self.sock,
                    addr,
                    None,
                    &stats,
                    &self.opts,
                    writer_cancel.clone(),
                );
                self.writers.spawn_on(writer, &self.runtime);
                tracing::debug!(%id, %addr, "udp peer up");
                let up = LinkEvent::Up {
                    id,
                    peer: format!("udp {addr}"),
                    tx,
                };
                let peer = v.insert(Peer {
                    id,
                    last_heard: now,
                    decoder: FrameDecoder::new(),
                    stats,
                    writer_cancel,
                    systems: Vec::new(),
                });
                (peer, Some(up))
            }
        };
        peer.last_heard = now;
        peer.stats.add_rx_bytes(data.len());
        let id = peer.id;
        peer.decoder
            .push_final_with(data, |frame| frames.push((id, frame)));
        peer.stats.add_decode(&peer.decoder.take_stats());
        up
    }

    /// Drops a peer that was not reported up (its owner is gone).
    fn forget(&mut self, addr: SocketAddr) {
        if let Some(p) = self.by_addr.remove(&addr) {
            p.writer_cancel.cancel();
        }
    }

    /// Removes the peers silent for the timeout: (id, reason) of each.
    fn expire(&mut self, now: Instant) -> Vec<(LinkId, String)> {
        let timeout = self.opts.udp_peer_timeout;
        let expired: Vec<SocketAddr> = self
            .by_addr
            .iter()
            .filter(|(_, p)| now.duration_since(p.last_heard) >= timeout)
            .map(|(a, _)| *a)
            .collect();
        expired
            .into_iter()
            .filter_map(|addr| {
                let p = self.by_addr.remove(&addr)?;
                p.writer_cancel.cancel();
                Some((p.id, format!("udp peer {addr} silent for {timeout:?}")))
            })
            .collect()
    }

    /// Removes every peer: the id of each.
    fn drain(&mut self) -> Vec<LinkId> {
        self.by_addr
            .drain()
            .map(|(_, p)| {
                p.writer_cancel.cancel();
                p.id
            })
            .collect()
    }
}

/// How often a udpin reader looks for silent peers: often enough that a peer expires within
/// ~25 % of the timeout.
fn expiry_period(opts: &LinkOptions) -> Duration {
    (opts.udp_peer_timeout / 4).clamp(Duration::from_millis(5), Duration::from_secs(1))
}

/// How a blocking reader learns that it is to stop, and is woken when no datagram comes.
///
/// The reader sleeps in its receive with no timeout, as a bare `recvfrom` loop does: a
/// receive timeout arms and cancels a kernel timer on every sleep, about 2 % of a forwarded
/// frame's CPU on this machine (BENCHMARKS.md). Instead a task of the runtime sends it an empty
/// datagram from a socket of its own (the alarm), which the reader knows by its source address
/// and discards: when the reader is to stop (cancelled, or the runtime ends), and after every
/// `idle` period in which the reader did not wake by itself (a udpin reader's peer expiry).
/// Without a loopback to send the alarm on, the reader falls back to a receive timeout.
#[derive(Debug)]
struct Wakeup {
    stopped: AtomicBool,
    /// The reader's wake-ups so far (written by the reader alone).
    count: AtomicU64,
    /// The alarm's address: datagrams from it are wake-ups, not traffic. `None`: the reader
    /// sleeps with a receive timeout instead.
    alarm: Option<SocketAddr>,
}

impl Wakeup {
    fn stopped(&self) -> bool {
        self.stopped.load(Ordering::Relaxed)
    }

    /// Notes a wake-up of the reader (`n` so far).
    fn woke(&self, n: u64) {
        self.count.store(n, Ordering::Relaxed);
    }

    /// A datagram from this address is the alarm.
    fn is_alarm(&self, from: Option<SocketAddr>) -> bool {
        from.is_some() && from == self.alarm
    }
}

/// The alarm's socket, bound on the reader's address (its loopback when the reader listens on
/// every address).
#[derive(Debug)]
struct Alarm {
    sock: UdpSocket,
    to: SocketAddr,
}

impl Alarm {
    fn new(reader: SocketAddr) -> io::Result<Alarm> {
        let ip = match reader.ip() {
            std::net::IpAddr::V4(ip) if ip.is_unspecified() => Ipv4Addr::LOCALHOST.into(),
            std::net::IpAddr::V6(ip) if ip.is_unspecified() => Ipv6Addr::LOCALHOST.into(),
            ip => ip,
        };
        let sock = UdpSocket::bind(SocketAddr::new(ip, 0))?;
        sock.set_nonblocking(true)?;
        Ok(Alarm {
            sock,
            to: SocketAddr::new(ip, reader.port()),
        })
    }

    fn ring(&self) {
        // A full receive buffer means the reader is awake anyway.
        let _ = self.sock.send_to(&[], self.to);
    }
}

/// Stops the reader when dropped: by its task at the end, or with the runtime.
struct Ring {
    stop: CancellationToken,
    wake: Arc<Wakeup>,
    alarm: Option<Alarm>,
    /// The reader's socket, when the alarm cannot reach it (connected to another address):
    /// shutting its receiving side down wakes the reader to stop.
    shut: Option<UdpSocket>,
}

impl Ring {
    fn ring(&self) {
        if let Some(a) = &self.alarm {
            a.ring();
        }
        if let Some(s) = &self.shut
            && self.wake.stopped()
        {
            let _ = rustix::net::shutdown(s, rustix::net::Shutdown::Read);
        }
    }
}

impl Drop for Ring {
    fn drop(&mut self) {
        self.stop.cancel();
        self.wake.stopped.store(true, Ordering::Relaxed);
        self.ring();
    }
}

/// Sets up the stop signal and the wake-ups of a blocking reader on `sock`: `cancel`, and also
/// the end of the runtime (the task holding the [`Ring`] is dropped then), so a runtime shut
/// down without cancelling never waits on the thread. Returns the stop token (for the
/// reader's writers) and what the reader looks at. `connected`: the socket hears only its
/// destination, so it is woken to stop by shutting its receiving side down.
fn blocking_wakeup(
    cancel: &CancellationToken,
    sock: &UdpSocket,
    idle: Option<Duration>,
    connected: bool,
) -> (CancellationToken, Arc<Wakeup>) {
    let stop = cancel.child_token();
    let alarm = sock
        .local_addr()
        .and_then(Alarm::new)
        .and_then(|a| Ok((a.sock.local_addr()?, a)));
    let alarm = match alarm {
        Ok((from, a)) => match sock.set_read_timeout(None) {
            Ok(()) => Some((from, a)),
            Err(e) => {
                tracing::debug!("udp reader without a timeout: {e}");
                None
            }
        },
        Err(e) => {
            tracing::debug!("udp reader alarm: {e}; waking on a timeout instead");
            None
        }
    };
    let wake = Arc::new(Wakeup {
        stopped: AtomicBool::new(false),
        count: AtomicU64::new(0),
        alarm: alarm.as_ref().map(|(from, _)| *from),
    });
    let ring = Ring {
        stop: stop.clone(),
        wake: Arc::clone(&wake),
        alarm: alarm.map(|(_, a)| a),
        shut: if connected {
            sock.try_clone()
                .inspect_err(|e| tracing::debug!("udp reader stop: {e}"))
                .ok()
        } else {
            None
        },
    };
    if ring.alarm.is_none() || (connected && ring.shut.is_none()) {
        let tick = idle.map_or(BLOCKING_TICK, |i| i.min(BLOCKING_TICK));
        if let Err(e) = sock.set_read_timeout(Some(tick)) {
            tracing::debug!("udp reader timeout: {e}");
        }
    }
    let idle = idle.filter(|_| ring.alarm.is_some());
    tokio::spawn(async move {
        let mut seen = 0;
        loop {
            tokio::select! {
                () = ring.stop.cancelled() => break,
                () = async {
                    match idle {
                        Some(p) => tokio::time::sleep(p).await,
                        None => std::future::pending().await,
                    }
                } => {
                    let n = ring.wake.count.load(Ordering::Relaxed);
                    // Its own ring wakes the reader once more: that is not traffic.
                    seen = if n == seen {
                        ring.ring();
                        n + 1
                    } else {
                        n
                    };
                }
            }
        }
        ring.wake.stopped.store(true, Ordering::Relaxed);
        // Until the reader is gone: an alarm may be lost to a full receive buffer.
        while Arc::strong_count(&ring.wake) > 1 {
            ring.ring();
            tokio::time::sleep(BLOCKING_TICK).await;
        }
    });
    (stop, wake)
}

/// Binds a udpin socket and starts its reader.
pub(super) async fn spawn_udpin(
    url: &LinkUrl,
    host: &str,
    port: u16,
    events: Events,
    opts: LinkOptions,
    cancel: CancellationToken,
) -> Result<(SocketAddr, JoinHandle<()>), LinkError> {
    let addrs = resolve(host, port).await?;
    let sock = bind(url, &addrs)?;
    let local = local_addr(url, &sock)?;
    tracing::info!(%url, %local, "udpin listening");
    let handler = handler(events, &cancel);
    let (stop, wake) = blocking_wakeup(&cancel, &sock, Some(expiry_period(&opts)), false);
    let peers = Peers::new(sock, opts, stop);
    let task = tokio::task::spawn_blocking(move || udpin_blocking(peers, &wake, &*handler));
    Ok((local, task))
}

/// The udpin reader on a thread of its own, routing inline.
fn udpin_blocking(mut peers: Peers, wake: &Wakeup, handler: &dyn LinkEventHandler) {
    let sock = &*Arc::clone(&peers.sock);
    let period = expiry_period(&peers.opts);
    let mut next_expiry = Instant::now() + period;
    let mut dgrams = Datagrams::new(RECV_BATCH);
    let mut frames: Vec<(LinkId, Frame)> = Vec::with_capacity(RECV_BATCH);
    let mut wakeups: u64 = 0;
    'run: while !wake.stopped() {
        wakeups += 1;
        wake.woke(wakeups);
        let mut now = None;
        match dgrams.recv(sock) {
            Ok((_, t)) => {
                now = Some(t);
                for (data, addr) in dgrams.iter() {
                    let Some(addr) = addr else { continue };
                    if wake.is_alarm(Some(addr)) {
                        continue;
                    }
                    let arrival = peers.on_datagram(addr, data, t, &mut frames);
                    if let Some((old, reason)) = arrival.replaced {
                        // The old peer's frames first, then its end, then the new link.
                        let mut new = frames.split_off(arrival.start);
                        if !handler.frames(&mut frames) {
                            break 'run;
                        }
                        handler.event(LinkEvent::Down { id: old, reason });
                        frames.append(&mut new);
                    }
                    if let Some(up) = arrival.up
                        && !handler.event(up)
                    {
                        peers.forget(addr);
                        break 'run;
                    }
                }
                // The frames of the whole wake-up go to the owner together.
                if !handler.frames(&mut frames) {
                    break;
                }
            }
            Err(e)
                if matches!(
                    e.kind(),
                    io::ErrorKind::WouldBlock | io::ErrorKind::TimedOut
                ) => {}
            Err(e) => {
                // E.g. ECONNREFUSED from an ICMP error on some platforms: not fatal.
                tracing::debug!("udpin receive error: {e}");
                std::thread::sleep(RECV_ERROR_PAUSE);
            }
        }
        let now = now.unwrap_or_else(Instant::now);
        if now >= next_expiry {
            next_expiry = now + period;
            for (id, reason) in peers.expire(now) {
                tracing::debug!(%id, %reason, "link down");
                handler.event(LinkEvent::Down { id, reason });
            }
        }
    }
    for id in peers.drain() {
        handler.event(LinkEvent::Down {
            id,
            reason: "shutdown".to_string(),
        });
    }
    peers.writers.close();
    let (runtime, writers) = (peers.runtime.clone(), peers.writers.clone());
    runtime.block_on(writers.wait());
}

/// Binds an ephemeral socket for udpout and starts its single link.
pub(super) async fn spawn_udpout(
    url: &LinkUrl,
    host: &str,
    port: u16,
    events: Events,
    opts: LinkOptions,
    cancel: CancellationToken,
) -> Result<(SocketAddr, LinkId, JoinHandle<()>), LinkError> {
    let dest = resolve(host, port).await?[0];
    // A loopback destination is answered from loopback: the socket binds there, as listeners
    // bind 127.0.0.1, instead of on every interface.
    let any: SocketAddr = match (dest.ip().is_loopback(), dest.is_ipv4()) {
        (true, _) => (dest.ip(), 0).into(),
        (false, true) => (Ipv4Addr::UNSPECIFIED, 0).into(),
        (false, false) => (Ipv6Addr::UNSPECIFIED, 0).into(),
    };
    // An inline owner's socket is connected, with a second one for the other senders (whose
    // reader is a task: it calls the owner from the runtime, which a queue owner's handler
    // must not be called from).
    let pair = match &events {
        Events::Inline(_) => connected_pair(any, dest)
            .inspect_err(|e| tracing::debug!(%url, "udpout unconnected: {e}"))
            .ok(),
        Events::Queue(_) => None,
    };
    let handler = handler(events, &cancel);
    let (sock, local, strays) = match pair {
        Some((main, local, strays)) => {
            let strays =
                tokio::net::UdpSocket::from_std(strays).map_err(|source| LinkError::Io {
                    url: url.to_string(),
                    source,
                })?;
            let connection = Arc::new(Connection {
                dest,
                on: AtomicBool::new(true),
                change: std::sync::Mutex::new(()),
            });
            (Arc::new(main), local, Some((strays, connection)))
        }
        None => {
            let sock = bind(url, &[any])?;
            let local = local_addr(url, &sock)?;
            (sock, local, None)
        }
    };
    let connection = strays.as_ref().map(|(_, c)| Arc::clone(c));
    let id = LinkId::next();
    tracing::info!(%url, %local, %id, connected = connection.is_some(), "udpout sending to {dest}");
    let stats = Arc::new(LinkStats::default());
    let (cancel, wake) = blocking_wakeup(&cancel, &sock, None, connection.is_some());
    let writer_cancel = cancel.child_token();
    let (tx, writer) = udp_link(
        &sock,
        dest,
        connection.clone(),
        &stats,
        &opts,
        writer_cancel.clone(),
    );
    let writer = tokio::spawn(writer);
    let up = LinkEvent::Up {
        id,
        peer: format!("udp {dest}"),
        tx,
    };
    let link = UdpOut {
        id,
        sock,
        wake,
        connection,
        stats,
        writer,
        writer_cancel,
        cancel,
    };
    let runtime = tokio::runtime::Handle::current();
    let task = tokio::task::spawn_blocking(move || {
        let reason = if handler.event(up) {
            let strays = strays.map(|(sock, connection)| {
                let stop = link.cancel.child_token();
                let task = runtime.spawn(udpout_strays(
                    Strays {
                        sock,
                        connection,
                        main: Arc::clone(&link.sock),
                        alarm: link.wake.alarm,
                        id,
                        stats: Arc::clone(&link.stats),
                        handler: Arc::clone(&handler),
                    },
                    stop.clone(),
                ));
                (stop, task)
            });
            let reason = udpout_blocking(&link, &*handler);
            // No frame after the link's end.
            if let Some((stop, task)) = strays {
                stop.cancel();
                let _ = runtime.block_on(task);
            }
            reason
        } else {
            "shutdown".to_string()
        };
        link.writer_cancel.cancel();
        let _ = runtime.block_on(link.writer);
        handler.event(LinkEvent::Down { id, reason });
    });
    Ok((local, id, task))
}

/// A udpout link: its socket, counters and writer.
struct UdpOut {
    id: LinkId,
    sock: Arc<UdpSocket>,
    /// The reader's stop and wake-ups.
    wake: Arc<Wakeup>,
    /// The socket is connected to the destination ([`Connection`]).
    connection: Option<Arc<Connection>>,
    stats: Arc<LinkStats>,
    writer: JoinHandle<()>,
    writer_cancel: CancellationToken,
    cancel: CancellationToken,
}

/// Hears a udpout peer's replies on a thread of its own; returns why it stopped.
fn udpout_blocking(link: &UdpOut, handler: &dyn LinkEventHandler) -> String {
    let (sock, wake) = (&*link.sock, &link.wake);
    // Replies may come from any address (the peer may answer from another port); one decoder
    // suffices since there is one logical peer.
    let mut decoder = FrameDecoder::new();
    let mut dgrams = Datagrams::new(REPLY_BATCH);
    let mut frames: Vec<(LinkId, Frame)> = Vec::new();
    let mut wakeups: u64 = 0;
    while !wake.stopped() {
        wakeups += 1;
        wake.woke(wakeups);
        match dgrams.recv(sock) {
            Ok(_) => {
                for (data, from) in dgrams.iter() {
                    if wake.is_alarm(from) {
                        continue;
                    }
                    if let Some(c) = &link.connection
                        && from == Some(c.dest)
                        && !c.is_on()
                    {
                        c.reconnect(&link.sock);
                    }
                    link.stats.add_rx_bytes(data.len());
                    decoder.push_final_with(data, |frame| frames.push((link.id, frame)));
                    link.stats.add_decode(&decoder.take_stats());
                }
                if !handler.frames(&mut frames) {
                    return "event receiver closed".to_string();
                }
            }
            Err(e)
                if matches!(
                    e.kind(),
                    io::ErrorKind::WouldBlock | io::ErrorKind::TimedOut
                ) => {}
            Err(_) if wake.stopped() => break,
            Err(e) if is_icmp_error(&e) && link.connection.is_some() => {
                // Nobody listens at the destination: an error per datagram from now on,
                // unless the socket sends with the address instead.
                if let Some(c) = &link.connection {
                    c.dissolve(&link.sock);
                }
            }
            Err(e) => {
                // Other systems may report ECONNREFUSED on unconnected sockets too, when
                // nobody listens yet: keep going, slowly.
                tracing::debug!(id = %link.id, "udpout receive error: {e}");
                std::thread::sleep(RECV_ERROR_PAUSE);
            }
        }
    }
    "shutdown".to_string()
}

/// A socket bound to the port of a socket connected to `dest`, with `SO_REUSEPORT` on both:
/// the kernel gives the connected one the datagrams from `dest` and this one the others.
/// Returns the connected socket (blocking, for a reader thread), the port's address as bound
/// (before the connection made it specific) and the other socket (non-blocking).
fn connected_pair(
    any: SocketAddr,
    dest: SocketAddr,
) -> io::Result<(UdpSocket, SocketAddr, UdpSocket)> {
    let shared = |addr: SocketAddr| -> io::Result<UdpSocket> {
        let family = if addr.is_ipv4() {
            rustix::net::AddressFamily::INET
        } else {
            rustix::net::AddressFamily::INET6
        };
        let fd = rustix::net::socket_with(
            family,
            rustix::net::SocketType::DGRAM,
            rustix::net::SocketFlags::CLOEXEC,
            None,
        )?;
        rustix::net::sockopt::set_socket_reuseport(&fd, true)?;
        rustix::net::bind(&fd, &addr)?;
        let sock = UdpSocket::from(fd);
        grow_recv_buffer(&sock);
        Ok(sock)
    };
    // The connected socket binds the port by number: one bound to port 0 would give it up
    // when its connection is dissolved, and send from another.
    let strays = shared(any)?;
    let local = strays.local_addr()?;
    let main = shared(local)?;
    strays.set_nonblocking(true)?;
    main.connect(dest)?;
    main.set_read_timeout(Some(BLOCKING_TICK))?;
    Ok((main, local, strays))
}

/// What the second socket of a connected udpout link needs ([`udpout_strays`]).
struct Strays {
    sock: tokio::net::UdpSocket,
    connection: Arc<Connection>,
    /// The connected socket, to connect again when the destination is heard here.
    main: Arc<UdpSocket>,
    /// The reader's alarm: its datagrams land here, and are not traffic.
    alarm: Option<SocketAddr>,
    id: LinkId,
    stats: Arc<LinkStats>,
    handler: Arc<dyn LinkEventHandler>,
}

/// Hears what reaches a connected udpout link's port from other addresses than its
/// destination, and the destination's own datagrams while the connection is dissolved (the
/// kernel then shares them between the two sockets). Rare, so a task rather than a thread.
async fn udpout_strays(s: Strays, stop: CancellationToken) {
    let mut decoder = FrameDecoder::new();
    let mut buf = vec![0u8; MAX_DATAGRAM_BYTES];
    let mut frames: Vec<(LinkId, Frame)> = Vec::new();
    loop {
        let r = tokio::select! {
            () = stop.cancelled() => return,
            r = s.sock.recv_from(&mut buf) => r,
        };
        let (n, from) = match r {
            Ok(r) => r,
            Err(e) => {
                tracing::debug!(id = %s.id, "udpout receive error: {e}");
                if !sleep_or_cancel(RECV_ERROR_PAUSE, &stop).await {
                    return;
                }
                continue;
            }
        };
        if Some(from) == s.alarm {
            continue;
        }
        if from == s.connection.dest {
            s.connection.reconnect(&s.main);
        }
        s.stats.add_rx_bytes(n);
        decoder.push_final_with(&buf[..n], |frame| frames.push((s.id, frame)));
        s.stats.add_decode(&decoder.take_stats());
        if !frames.is_empty() && !s.handler.frames(&mut frames) {
            return;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rustix::net::sockopt::socket_recv_buffer_size;

    #[test]
    fn a_reader_shut_down_wakes_with_an_empty_receive_and_no_sender() {
        // How a connected udpout reader is stopped: its receive returns with nothing, and no
        // address (which `UdpSocket::recv_from` would panic on).
        let sock = UdpSocket::bind("127.0.0.1:0").unwrap();
        let peer = UdpSocket::bind("127.0.0.1:0").unwrap();
        sock.connect(peer.local_addr().unwrap()).unwrap();
        rustix::net::shutdown(&sock, rustix::net::Shutdown::Read).unwrap();
        let mut d = Datagrams::new(4);
        let (n, _) = d.recv(&sock).unwrap();
        assert_eq!(n, 1);
        let got: Vec<_> = d.iter().collect();
        assert_eq!(got, vec![(&[][..], None)]);
    }

    /// What the kernel will grant without privileges: `net.core.rmem_max`, reported doubled.
    fn grantable() -> usize {
        let max: usize = std::fs::read_to_string("/proc/sys/net/core/rmem_max")
            .expect("Linux exposes rmem_max")
            .trim()
            .parse()
            .expect("a number");
        RECV_BUFFER_BYTES.min(max) * 2
    }

    #[tokio::test]
    async fn every_udp_socket_asks_for_a_large_receive_buffer() {
        let url: LinkUrl = "udpin:127.0.0.1:0".parse().unwrap();
        let addrs = ["127.0.0.1:0".parse().unwrap()];
        let default: usize = std::fs::read_to_string("/proc/sys/net/core/rmem_default")
            .expect("Linux exposes rmem_default")
            .trim()
            .parse()
            .expect("a number");
        let sock = bind(&url, &addrs).unwrap();
        let got = socket_recv_buffer_size(&*sock).unwrap();
        assert!(
            got >= grantable().max(default),
            "socket: {got} bytes, rmem_max allows {}",
            grantable()
        );
    }
}
