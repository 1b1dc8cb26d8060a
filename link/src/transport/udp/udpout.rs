//! `udpout`: one link to a fixed destination, its socket connected while someone listens there.

use std::io::{self};
use std::net::{Ipv4Addr, Ipv6Addr, SocketAddr, UdpSocket};
use std::sync::Arc;
use std::sync::atomic::AtomicBool;

use tokio::task::JoinHandle;
use tokio_util::sync::CancellationToken;

use super::{
    BLOCKING_TICK, Connection, Datagrams, MAX_DATAGRAM_BYTES, RECV_ERROR_PAUSE, REPLY_BATCH,
    Wakeup, bind, blocking_wakeup, grow_recv_buffer, handler, is_icmp_error, local_addr, udp_link,
};
use super::{Events, LinkError, LinkEvent, LinkEventHandler, LinkId, LinkStats, sleep_or_cancel};
use crate::decoder::FrameDecoder;
use crate::frame::Frame;
use crate::transport::SocketEndpoint;
use crate::url::LinkUrl;

/// The sockets of a udpout link: the one it sends from, its local address, and for a connected
/// socket the second one that hears other senders, with the connection they share.
type Sockets = (
    Arc<UdpSocket>,
    SocketAddr,
    Option<(tokio::net::UdpSocket, Arc<Connection>)>,
);

/// Binds an ephemeral socket for udpout and starts its single link.
pub(crate) fn spawn_udpout(
    at: SocketEndpoint<'_>,
) -> Result<(SocketAddr, LinkId, JoinHandle<()>), LinkError> {
    let url = at.url;
    let dest = at.addrs[0];
    let inline = matches!(at.events, Events::Inline(_));
    let (sock, local, strays) = open_sockets(url, dest, inline)?;
    let handler = handler(at.events, &at.cancel);
    let connection = strays.as_ref().map(|(_, c)| Arc::clone(c));
    let id = LinkId::next();
    tracing::info!(%url, %local, %id, connected = connection.is_some(), "udpout sending to {dest}");
    let stats = Arc::new(LinkStats::default());
    let (cancel, wake) = blocking_wakeup(&at.cancel, &sock, None, connection.is_some());
    let writer_cancel = cancel.child_token();
    let (tx, writer) = udp_link(
        &sock,
        dest,
        connection.clone(),
        &stats,
        &at.opts,
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
    let task =
        tokio::task::spawn_blocking(move || run_udpout(link, up, strays, &handler, &runtime));
    Ok((local, id, task))
}

/// Opens the sockets of a udpout link to `dest`. A loopback destination is answered from
/// loopback: the socket binds there, as listeners bind 127.0.0.1, instead of on every interface.
/// An `inline` owner's socket is connected, with a second one for the other senders (whose
/// reader is a task: it calls the owner from the runtime, which a queue owner's handler must not
/// be called from); if connecting fails, or for a queue owner, one unconnected socket.
fn open_sockets(url: &LinkUrl, dest: SocketAddr, inline: bool) -> Result<Sockets, LinkError> {
    let any: SocketAddr = match (dest.ip().is_loopback(), dest.is_ipv4()) {
        (true, _) => (dest.ip(), 0).into(),
        (false, true) => (Ipv4Addr::UNSPECIFIED, 0).into(),
        (false, false) => (Ipv6Addr::UNSPECIFIED, 0).into(),
    };
    let pair = if inline {
        connected_pair(any, dest)
            .inspect_err(|e| tracing::debug!(%url, "udpout unconnected: {e}"))
            .ok()
    } else {
        None
    };
    Ok(match pair {
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
    })
}

/// The link's thread: announces it, reads until it ends (with the strays' reader beside it on
/// the runtime, stopped first: no frame after the link's end), then stops its writer and says
/// it is down.
fn run_udpout(
    link: UdpOut,
    up: LinkEvent,
    strays: Option<(tokio::net::UdpSocket, Arc<Connection>)>,
    handler: &Arc<dyn LinkEventHandler>,
    runtime: &tokio::runtime::Handle,
) {
    let id = link.id;
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
                    handler: Arc::clone(handler),
                },
                stop.clone(),
            ));
            (stop, task)
        });
        let reason = udpout_blocking(&link, &**handler);
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
}

/// A udpout link: its socket, counters and writer.
pub(crate) struct UdpOut {
    pub(crate) id: LinkId,
    pub(crate) sock: Arc<UdpSocket>,
    /// The reader's stop and wake-ups.
    pub(crate) wake: Arc<Wakeup>,
    /// The socket is connected to the destination ([`Connection`]).
    pub(crate) connection: Option<Arc<Connection>>,
    pub(crate) stats: Arc<LinkStats>,
    pub(crate) writer: JoinHandle<()>,
    pub(crate) writer_cancel: CancellationToken,
    pub(crate) cancel: CancellationToken,
}

/// Hears a udpout peer's replies on a thread of its own; returns why it stopped.
pub(crate) fn udpout_blocking(link: &UdpOut, handler: &dyn LinkEventHandler) -> String {
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
pub(crate) fn connected_pair(
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
pub(crate) struct Strays {
    pub(crate) sock: tokio::net::UdpSocket,
    pub(crate) connection: Arc<Connection>,
    /// The connected socket, to connect again when the destination is heard here.
    pub(crate) main: Arc<UdpSocket>,
    /// The reader's alarm: its datagrams land here, and are not traffic.
    pub(crate) alarm: Option<SocketAddr>,
    pub(crate) id: LinkId,
    pub(crate) stats: Arc<LinkStats>,
    pub(crate) handler: Arc<dyn LinkEventHandler>,
}

/// Hears what reaches a connected udpout link's port from other addresses than its
/// destination, and the destination's own datagrams while the connection is dissolved (the
/// kernel then shares them between the two sockets). Rare, so a task rather than a thread.
pub(crate) async fn udpout_strays(s: Strays, stop: CancellationToken) {
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
