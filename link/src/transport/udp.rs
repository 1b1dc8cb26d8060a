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

use std::collections::HashMap;
use std::collections::hash_map::Entry;
use std::net::{Ipv4Addr, Ipv6Addr, SocketAddr};
use std::sync::Arc;
use std::sync::atomic::{AtomicUsize, Ordering};
use std::time::Duration;

use tokio::net::UdpSocket;
use tokio::sync::mpsc;
use tokio::task::JoinHandle;
use tokio::time::Instant;
use tokio_util::sync::CancellationToken;
use tokio_util::task::TaskTracker;

use super::{
    DirectUdp, LinkError, LinkEvent, LinkId, LinkOptions, LinkSender, LinkStats, emit, emit_down,
    resolve, sleep_or_cancel,
};
use crate::decoder::FrameDecoder;
use crate::frame::Frame;
use crate::url::LinkUrl;

/// Largest UDP payload.
const MAX_DATAGRAM_BYTES: usize = 65_536;
/// Pause after a receive error so a persistent error cannot become a busy loop.
const RECV_ERROR_PAUSE: Duration = Duration::from_millis(50);

/// State of one UDP peer (one link) of a udpin socket.
struct Peer {
    id: LinkId,
    last_heard: Instant,
    decoder: FrameDecoder,
    stats: Arc<LinkStats>,
    writer_cancel: CancellationToken,
}

async fn bind(url: &LinkUrl, addrs: &[SocketAddr]) -> Result<UdpSocket, LinkError> {
    let mut last = None;
    for &addr in addrs {
        match UdpSocket::bind(addr).await {
            Ok(s) => return Ok(s),
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

fn local_addr(url: &LinkUrl, sock: &UdpSocket) -> Result<SocketAddr, LinkError> {
    sock.local_addr().map_err(|source| LinkError::Io {
        url: url.to_string(),
        source,
    })
}

/// Most frames a UDP writer takes from its queue per wake-up.
const WRITE_BATCH: usize = 64;

/// Writes one link's queue to `dest`, one datagram per frame, until cancelled.
async fn udp_writer(
    direct: Arc<DirectUdp>,
    mut rx: mpsc::Receiver<Frame>,
    stats: Arc<LinkStats>,
    cancel: CancellationToken,
) {
    // Frames are taken from the queue a run at a time: under load one wake-up sends many
    // datagrams (still one datagram per frame, as pymavlink expects).
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
        for frame in batch.drain(..) {
            // Try without waiting first; only a full socket buffer needs the readiness await.
            if direct.try_send_now(&frame, &stats).is_none() {
                match direct.sock.send_to(frame.as_bytes(), direct.dest).await {
                    Ok(n) => stats.add_tx(1, n),
                    Err(e) => {
                        tracing::debug!(dest = %direct.dest, "udp send error: {e}");
                        stats.add_tx_error();
                    }
                }
            }
            // Only now may producers send directly again: this frame is out, in order.
            direct.queued.fetch_sub(1, Ordering::AcqRel);
        }
    }
}

/// The writer of one UDP peer and the sender the router uses for it.
fn udp_link(
    sock: &Arc<UdpSocket>,
    dest: SocketAddr,
    stats: &Arc<LinkStats>,
    queue_len: usize,
    cancel: CancellationToken,
) -> (
    LinkSender,
    impl std::future::Future<Output = ()> + Send + 'static,
) {
    let (tx, rx) = mpsc::channel(queue_len.max(1));
    let direct = Arc::new(DirectUdp {
        sock: sock.clone(),
        dest,
        queued: AtomicUsize::new(0),
    });
    let sender = LinkSender::with_direct_udp(tx, stats.clone(), direct.clone());
    (sender, udp_writer(direct, rx, stats.clone(), cancel))
}

/// Creates the state of a newly heard peer, spawns its writer and returns its `Up` event.
fn new_peer(
    sock: &Arc<UdpSocket>,
    addr: SocketAddr,
    writers: &TaskTracker,
    opts: &LinkOptions,
    cancel: &CancellationToken,
) -> (Peer, LinkEvent) {
    let id = LinkId::next();
    let stats = Arc::new(LinkStats::default());
    let writer_cancel = cancel.child_token();
    let (tx, writer) = udp_link(sock, addr, &stats, opts.queue_len, writer_cancel.clone());
    writers.spawn(writer);
    tracing::debug!(%id, %addr, "udp peer up");
    let up = LinkEvent::Up {
        id,
        peer: format!("udp {addr}"),
        tx,
    };
    let peer = Peer {
        id,
        last_heard: Instant::now(),
        decoder: FrameDecoder::new(),
        stats,
        writer_cancel,
    };
    (peer, up)
}

/// Binds a udpin socket and spawns its task.
pub(super) async fn spawn_udpin(
    url: &LinkUrl,
    host: &str,
    port: u16,
    events: mpsc::Sender<LinkEvent>,
    opts: LinkOptions,
    cancel: CancellationToken,
) -> Result<(SocketAddr, JoinHandle<()>), LinkError> {
    let addrs = resolve(host, port).await?;
    let sock = Arc::new(bind(url, &addrs).await?);
    let local = local_addr(url, &sock)?;
    tracing::info!(%url, %local, "udpin listening");
    let task = tokio::spawn(udpin_task(sock, events, opts, cancel));
    Ok((local, task))
}

async fn udpin_task(
    sock: Arc<UdpSocket>,
    events: mpsc::Sender<LinkEvent>,
    opts: LinkOptions,
    cancel: CancellationToken,
) {
    let writers = TaskTracker::new();
    let mut peers: HashMap<SocketAddr, Peer> = HashMap::new();
    let mut buf = vec![0u8; MAX_DATAGRAM_BYTES];
    let timeout = opts.udp_peer_timeout;
    // Check often enough that a peer expires within ~25 % of the timeout.
    let period = (timeout / 4).clamp(Duration::from_millis(5), Duration::from_secs(1));
    let mut tick = tokio::time::interval(period);
    tick.set_missed_tick_behavior(tokio::time::MissedTickBehavior::Delay);
    'run: loop {
        tokio::select! {
            _ = cancel.cancelled() => break,
            _ = tick.tick() => {
                let now = Instant::now();
                let expired: Vec<SocketAddr> = peers
                    .iter()
                    .filter(|(_, p)| now.duration_since(p.last_heard) >= timeout)
                    .map(|(a, _)| *a)
                    .collect();
                for addr in expired {
                    if let Some(p) = peers.remove(&addr) {
                        p.writer_cancel.cancel();
                        let reason = format!("udp peer {addr} silent for {timeout:?}");
                        emit_down(&events, p.id, reason, &cancel).await;
                    }
                }
            }
            r = sock.recv_from(&mut buf) => {
                let (n, addr) = match r {
                    Ok(x) => x,
                    Err(e) => {
                        // E.g. ECONNREFUSED from an ICMP error on some platforms: not fatal.
                        tracing::debug!("udpin receive error: {e}");
                        if !sleep_or_cancel(RECV_ERROR_PAUSE, &cancel).await {
                            break;
                        }
                        continue;
                    }
                };
                let ctx = PeerContext { sock: &sock, writers: &writers, opts: &opts, events: &events, cancel: &cancel };
                if !on_datagram(&mut peers, &buf[..n], addr, &ctx).await {
                    break 'run;
                }
                // Under load more datagrams are already waiting: take a run of them before going
                // back to the select, which costs more than the receive itself.
                for _ in 1..RECV_BATCH {
                    let Ok((n, addr)) = sock.try_recv_from(&mut buf) else {
                        break;
                    };
                    if !on_datagram(&mut peers, &buf[..n], addr, &ctx).await {
                        break 'run;
                    }
                }
            }
        }
    }
    for (_, p) in peers.drain() {
        p.writer_cancel.cancel();
        emit_down(&events, p.id, "shutdown".to_string(), &cancel).await;
    }
    writers.close();
    writers.wait().await;
}

/// Most datagrams a udpin task takes per wake-up before it looks at its timers again.
const RECV_BATCH: usize = 32;

/// What handling a datagram needs besides the peer table.
struct PeerContext<'a> {
    sock: &'a Arc<UdpSocket>,
    writers: &'a TaskTracker,
    opts: &'a LinkOptions,
    events: &'a mpsc::Sender<LinkEvent>,
    cancel: &'a CancellationToken,
}

/// Handles one datagram from `addr`: a new peer becomes a link (Up), then the frames it holds
/// go to the owner. False when the owner is gone or the task is cancelled.
async fn on_datagram(
    peers: &mut HashMap<SocketAddr, Peer>,
    data: &[u8],
    addr: SocketAddr,
    ctx: &PeerContext<'_>,
) -> bool {
    let peer = match peers.entry(addr) {
        Entry::Occupied(o) => o.into_mut(),
        Entry::Vacant(v) => {
            let (peer, up) = new_peer(ctx.sock, addr, ctx.writers, ctx.opts, ctx.cancel);
            if !emit(ctx.events, up, ctx.cancel).await {
                peer.writer_cancel.cancel();
                return false;
            }
            v.insert(peer)
        }
    };
    peer.last_heard = Instant::now();
    peer.stats.add_rx_bytes(data.len());
    peer.decoder.push(data);
    let frames = peer.decoder.finish();
    peer.stats.add_decode(&peer.decoder.take_stats());
    for frame in frames {
        if !emit(
            ctx.events,
            LinkEvent::Frame { id: peer.id, frame },
            ctx.cancel,
        )
        .await
        {
            return false;
        }
    }
    true
}

/// Binds an ephemeral socket for udpout and spawns its single link.
pub(super) async fn spawn_udpout(
    url: &LinkUrl,
    host: &str,
    port: u16,
    events: mpsc::Sender<LinkEvent>,
    opts: LinkOptions,
    cancel: CancellationToken,
) -> Result<(SocketAddr, LinkId, JoinHandle<()>), LinkError> {
    let dest = resolve(host, port).await?[0];
    let any: SocketAddr = if dest.is_ipv4() {
        (Ipv4Addr::UNSPECIFIED, 0).into()
    } else {
        (Ipv6Addr::UNSPECIFIED, 0).into()
    };
    let sock = Arc::new(bind(url, &[any]).await?);
    let local = local_addr(url, &sock)?;
    let id = LinkId::next();
    tracing::info!(%url, %local, %id, "udpout sending to {dest}");
    let task = tokio::spawn(udpout_task(id, sock, dest, events, opts, cancel));
    Ok((local, id, task))
}

async fn udpout_task(
    id: LinkId,
    sock: Arc<UdpSocket>,
    dest: SocketAddr,
    events: mpsc::Sender<LinkEvent>,
    opts: LinkOptions,
    cancel: CancellationToken,
) {
    let stats = Arc::new(LinkStats::default());
    let writer_cancel = cancel.child_token();
    let (tx, writer) = udp_link(&sock, dest, &stats, opts.queue_len, writer_cancel.clone());
    let writer = tokio::spawn(writer);
    let up = LinkEvent::Up {
        id,
        peer: format!("udp {dest}"),
        tx,
    };
    let mut reason = "shutdown".to_string();
    if emit(&events, up, &cancel).await {
        // Replies may come from any address (the peer may answer from another port); one
        // decoder suffices since there is one logical peer.
        let mut decoder = FrameDecoder::new();
        let mut buf = vec![0u8; MAX_DATAGRAM_BYTES];
        'run: loop {
            let r = tokio::select! {
                _ = cancel.cancelled() => break,
                r = sock.recv_from(&mut buf) => r,
            };
            let n = match r {
                Ok((n, _from)) => n,
                Err(e) => {
                    // Linux reports ECONNREFUSED only on connected sockets, others may report
                    // it here when nobody listens yet: keep going, slowly.
                    tracing::debug!(%id, "udpout receive error: {e}");
                    if !sleep_or_cancel(RECV_ERROR_PAUSE, &cancel).await {
                        break;
                    }
                    continue;
                }
            };
            stats.add_rx_bytes(n);
            decoder.push(&buf[..n]);
            let frames = decoder.finish();
            stats.add_decode(&decoder.take_stats());
            for frame in frames {
                if !emit(&events, LinkEvent::Frame { id, frame }, &cancel).await {
                    reason = "event receiver closed".to_string();
                    break 'run;
                }
            }
        }
    }
    writer_cancel.cancel();
    let _ = writer.await;
    emit_down(&events, id, reason, &cancel).await;
}
