//! Sending to one UDP peer: straight from the producer while its writer has nothing queued,
//! the writer task otherwise; a udpout socket connected to its destination while someone listens.

use std::io::{self, IoSlice};
use std::net::{SocketAddr, UdpSocket};
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};

use tokio::sync::mpsc;
use tokio_util::sync::CancellationToken;

use super::{FULL_RETRY, SEND_BATCH, WRITE_BATCH};
use super::{LinkOptions, LinkSender, LinkStats, sleep_or_cancel};
use crate::frame::Frame;

/// A UDP peer that producers may send to themselves while nothing is queued for the peer's
/// writer: a datagram then leaves without waking the writer task, which costs a task hop per
/// frame. Frames queued while the writer is busy keep their order, because a producer only
/// goes direct once the writer has sent everything it was given.
#[derive(Debug)]
pub(crate) struct DirectUdp {
    pub(crate) sock: Arc<UdpSocket>,
    pub(crate) dest: SocketAddr,
    /// Frames handed to the writer's queue and not yet sent by it.
    pub(crate) queued: AtomicUsize,
    /// A udpout socket connected to `dest`: send without an address while it is.
    pub(crate) connection: Option<Arc<Connection>>,
}

/// Whether a udpout socket is connected to its destination; see the module's documentation.
#[derive(Debug)]
pub(crate) struct Connection {
    pub(crate) dest: SocketAddr,
    /// True while the socket is connected: sends go without an address.
    pub(crate) on: AtomicBool,
    /// Serialises connecting and dissolving, so that `on` is true only while the socket is
    /// connected (a send may still meet a connection dissolved since it looked: it then sends
    /// with the address).
    pub(crate) change: std::sync::Mutex<()>,
}

impl Connection {
    pub(crate) fn is_on(&self) -> bool {
        self.on.load(Ordering::Relaxed)
    }

    /// Nobody listens at the destination (the kernel reported an ICMP error): send with the
    /// address from now on, which the kernel does not answer with errors.
    pub(crate) fn dissolve(&self, sock: &UdpSocket) {
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
    pub(crate) fn reconnect(&self, sock: &UdpSocket) {
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
pub(crate) fn is_icmp_error(e: &io::Error) -> bool {
    use rustix::io::Errno;
    matches!(
        Errno::from_io_error(e),
        Some(Errno::CONNREFUSED | Errno::HOSTUNREACH | Errno::NETUNREACH | Errno::HOSTDOWN)
    )
}

/// The errors of a send on a socket that is no longer connected.
pub(crate) fn is_unconnected(e: &io::Error) -> bool {
    matches!(
        rustix::io::Errno::from_io_error(e),
        Some(rustix::io::Errno::DESTADDRREQ | rustix::io::Errno::NOTCONN)
    )
}

impl DirectUdp {
    pub(crate) fn connected(&self) -> Option<&Connection> {
        self.connection.as_deref().filter(|c| c.is_on())
    }

    /// One datagram: without the address on a connected socket.
    pub(crate) fn send_one(&self, bytes: &[u8]) -> io::Result<usize> {
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

/// Writes what producers could not send directly (the socket buffer was full), in order, one
/// datagram per frame, until cancelled.
pub(crate) async fn udp_writer(
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
pub(crate) fn udp_link(
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
