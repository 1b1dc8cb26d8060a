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

mod direct;
mod recv;
mod udpin;
mod udpout;
mod wakeup;

use std::net::{SocketAddr, UdpSocket};
use std::sync::Arc;
use std::time::Duration;

use tokio::sync::mpsc;
use tokio_util::sync::CancellationToken;

use super::{
    Events, LinkError, LinkEvent, LinkEventHandler, LinkId, LinkOptions, LinkSender, LinkStats,
    sleep_or_cancel,
};
use crate::url::LinkUrl;

pub(crate) use direct::DirectUdp;
use direct::{Connection, is_icmp_error, udp_link};
use recv::Datagrams;
pub(super) use udpin::spawn_udpin;
pub(super) use udpout::spawn_udpout;
use wakeup::{Wakeup, blocking_wakeup};

/// Largest UDP payload: one receive slot, so no datagram is ever truncated.
pub(crate) const MAX_DATAGRAM_BYTES: usize = 65_536;
/// Pause after a receive error so a persistent error cannot become a busy loop.
pub(crate) const RECV_ERROR_PAUSE: Duration = Duration::from_millis(50);
/// Most datagrams a socket's reader takes per wake-up before it looks at its timers again.
pub(crate) const RECV_BATCH: usize = 32;
/// The same for a udpout socket, which only hears its peer's replies.
pub(crate) const REPLY_BATCH: usize = 8;
/// Most datagrams per `sendmmsg`.
pub(crate) const SEND_BATCH: usize = 64;
/// Most frames a UDP writer takes from its queue per wake-up.
pub(crate) const WRITE_BATCH: usize = 64;
/// How often a stopping blocking reader is woken again until it is gone, and its receive
/// timeout when it cannot be woken by a datagram ([`Wakeup`]).
pub(crate) const BLOCKING_TICK: Duration = Duration::from_millis(100);
/// How long a writer whose blocking socket's buffer is full waits before it tries again (a
/// blocking socket has no readiness events to wait on; a full UDP send buffer is rare).
pub(crate) const FULL_RETRY: Duration = Duration::from_millis(1);

/// A queue owner's events, from a reader's thread: a full queue makes the reader wait, as it
/// makes any link of a queue owner wait, unless the endpoint is stopping.
pub(crate) struct QueueHandler {
    pub(crate) tx: mpsc::Sender<LinkEvent>,
    pub(crate) cancel: CancellationToken,
    pub(crate) runtime: tokio::runtime::Handle,
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
pub(crate) fn handler(events: Events, cancel: &CancellationToken) -> Arc<dyn LinkEventHandler> {
    match events {
        Events::Inline(h) => h,
        Events::Queue(tx) => Arc::new(QueueHandler {
            tx,
            cancel: cancel.clone(),
            runtime: tokio::runtime::Handle::current(),
        }),
    }
}

/// Binds `addrs` in turn: a socket for a blocking reader.
pub(crate) fn bind(url: &LinkUrl, addrs: &[SocketAddr]) -> Result<Arc<UdpSocket>, LinkError> {
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
pub(crate) fn grow_recv_buffer(s: &UdpSocket) {
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

pub(crate) fn local_addr(url: &LinkUrl, sock: &UdpSocket) -> Result<SocketAddr, LinkError> {
    sock.local_addr().map_err(|source| LinkError::Io {
        url: url.to_string(),
        source,
    })
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
