//! `udpin`: a server socket, one link per peer address heard; a vehicle back from a new address
//! followed ([`LinkOptions::udp_follow_system`]).

use std::collections::hash_map::Entry;
use std::io::{self};
use std::net::{SocketAddr, UdpSocket};
use std::sync::Arc;
use std::time::{Duration, Instant};

use tokio::task::JoinHandle;
use tokio_util::sync::CancellationToken;
use tokio_util::task::TaskTracker;

use super::{
    Datagrams, RECV_BATCH, RECV_ERROR_PAUSE, Wakeup, bind, blocking_wakeup, handler, local_addr,
    udp_link,
};
use super::{LinkError, LinkEvent, LinkEventHandler, LinkId, LinkOptions, LinkStats};
use crate::decoder::FrameDecoder;
use crate::frame::Frame;
use crate::ids::SystemId;
use crate::transport::SocketEndpoint;

/// State of one UDP peer (one link) of a udpin socket.
pub(crate) struct Peer {
    pub(crate) id: LinkId,
    pub(crate) last_heard: Instant,
    pub(crate) decoder: FrameDecoder,
    pub(crate) stats: Arc<LinkStats>,
    pub(crate) writer_cancel: CancellationToken,
    /// The system ids it sent as, when the endpoint follows its vehicles
    /// ([`LinkOptions::udp_follow_system`]).
    pub(crate) systems: Vec<SystemId>,
    /// System ids it sent as that another peer, still sending, sent as first: it is followed
    /// for them once that peer falls silent ([`FOLLOW_AFTER_SILENCE`]).
    pub(crate) contested: Vec<SystemId>,
}

/// How long the old address of a system id must have been silent for a new address sending as
/// that system to be the same vehicle come back (a restarted process, a new NAT mapping). A
/// vehicle's telemetry never pauses this long while it is up: a new address heard while the old
/// one still sends is a second vehicle (a conflict for the router), until the old one falls
/// silent.
pub(crate) const FOLLOW_AFTER_SILENCE: Duration = Duration::from_millis(500);

/// What a datagram changed in the peers of a udpin socket ([`Peers::on_datagram`]).
#[derive(Default)]
pub(crate) struct Arrival {
    /// A peer that came back from the datagram's address: its old link is down, for the
    /// caller to report after the frames before `start` and before the new link's `Up`.
    pub(crate) replaced: Option<(LinkId, String)>,
    /// A new link, for the caller to report before the datagram's frames.
    pub(crate) up: Option<LinkEvent>,
    /// Where the datagram's frames start in the caller's list.
    pub(crate) start: usize,
}

/// The peers of a udpin socket.
pub(crate) struct Peers {
    pub(crate) sock: Arc<UdpSocket>,
    pub(crate) by_addr: foldhash::HashMap<SocketAddr, Peer>,
    pub(crate) writers: TaskTracker,
    pub(crate) runtime: tokio::runtime::Handle,
    pub(crate) opts: LinkOptions,
    pub(crate) cancel: CancellationToken,
}

impl Peers {
    pub(crate) fn new(sock: Arc<UdpSocket>, opts: LinkOptions, cancel: CancellationToken) -> Self {
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
    pub(crate) fn on_datagram(
        &mut self,
        addr: SocketAddr,
        data: &[u8],
        now: Instant,
        frames: &mut Vec<(LinkId, Frame)>,
    ) -> Arrival {
        let start = frames.len();
        let (up, new_systems) = self.decode(addr, data, now, frames);
        let replaced = new_systems.and_then(|new| self.follow(addr, &new, now));
        Arrival {
            replaced,
            up,
            start,
        }
    }

    /// A vehicle that comes back from a new address (a restarted process, a new NAT mapping)
    /// is the same vehicle: when the peer at `addr` sends as a system id another peer of this
    /// endpoint sent as, and that peer has been silent [`FOLLOW_AFTER_SILENCE`], that peer is
    /// gone and `addr` takes over at once, as mavlink-router's UDP server follows its last
    /// sender. While the other peer still sends, `addr` is a second vehicle (the router's
    /// conflict) and asks again with each datagram. `new`: the system ids the peer at `addr`
    /// just sent as for the first time, or still contests ([`Peers::decode`]). Returns the
    /// replaced peer's link and why it ended.
    pub(crate) fn follow(
        &mut self,
        addr: SocketAddr,
        new: &[SystemId],
        now: Instant,
    ) -> Option<(LinkId, String)> {
        let Some((old, heard)) = self
            .by_addr
            .iter()
            .find(|(a, p)| **a != addr && p.systems.iter().any(|s| new.contains(s)))
            .map(|(a, p)| (*a, p.last_heard))
        else {
            if let Some(p) = self.by_addr.get_mut(&addr) {
                p.contested.clear();
            }
            return None;
        };
        if now.saturating_duration_since(heard) < FOLLOW_AFTER_SILENCE {
            // The old address still sends: a second vehicle, not this one come back.
            if let Some(p) = self.by_addr.get_mut(&addr) {
                p.contested = new.to_vec();
            }
            return None;
        }
        let p = self.by_addr.remove(&old)?;
        p.writer_cancel.cancel();
        if let Some(p) = self.by_addr.get_mut(&addr) {
            p.contested.clear();
        }
        tracing::info!(id = %p.id, %old, new = %addr, "udp peer came back from a new address");
        Some((p.id, format!("udp peer {old} came back from {addr}")))
    }

    /// Decodes a datagram from `addr` into `frames`; a new peer's `Up` is returned, and, when
    /// the endpoint follows its vehicles, the system ids the peer sent as for the first time.
    pub(crate) fn decode(
        &mut self,
        addr: SocketAddr,
        data: &[u8],
        now: Instant,
        frames: &mut Vec<(LinkId, Frame)>,
    ) -> (Option<LinkEvent>, Option<Vec<SystemId>>) {
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
                    contested: Vec::new(),
                });
                (peer, Some(up))
            }
        };
        peer.last_heard = now;
        peer.stats.add_rx_bytes(data.len());
        let id = peer.id;
        let start = frames.len();
        peer.decoder
            .push_final_with(data, |frame| frames.push((id, frame)));
        peer.stats.add_decode(&peer.decoder.take_stats());
        if !self.opts.udp_follow_system {
            return (up, None);
        }
        // Almost always the one system id the peer has sent as all along: nothing new.
        let mut new = Vec::new();
        for (_, f) in &frames[start..] {
            let system = f.sender().0;
            if !peer.systems.contains(&system) {
                peer.systems.push(system);
                new.push(system);
            }
        }
        // A contested peer asks again with every datagram, until the other address is silent.
        for s in &peer.contested {
            if !new.contains(s) {
                new.push(*s);
            }
        }
        (up, Some(new).filter(|n| !n.is_empty()))
    }

    /// Drops a peer that was not reported up (its owner is gone).
    pub(crate) fn forget(&mut self, addr: SocketAddr) {
        if let Some(p) = self.by_addr.remove(&addr) {
            p.writer_cancel.cancel();
        }
    }

    /// Removes the peers silent for the timeout: (id, reason) of each.
    pub(crate) fn expire(&mut self, now: Instant) -> Vec<(LinkId, String)> {
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
    pub(crate) fn drain(&mut self) -> Vec<LinkId> {
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
pub(crate) fn expiry_period(opts: &LinkOptions) -> Duration {
    (opts.udp_peer_timeout / 4).clamp(Duration::from_millis(5), Duration::from_secs(1))
}

/// Binds a udpin socket and starts its reader.
pub(crate) fn spawn_udpin(
    at: SocketEndpoint<'_>,
) -> Result<(SocketAddr, JoinHandle<()>), LinkError> {
    let url = at.url;
    let sock = bind(url, &at.addrs)?;
    let local = local_addr(url, &sock)?;
    tracing::info!(%url, %local, "udpin listening");
    let handler = handler(at.events, &at.cancel);
    let expiry = Some(expiry_period(&at.opts));
    let (stop, wake) = blocking_wakeup(&at.cancel, &sock, expiry, false);
    let peers = Peers::new(sock, at.opts, stop);
    let task = tokio::task::spawn_blocking(move || udpin_blocking(peers, &wake, &*handler));
    Ok((local, task))
}

/// The udpin reader on a thread of its own, routing inline.
pub(crate) fn udpin_blocking(mut peers: Peers, wake: &Wakeup, handler: &dyn LinkEventHandler) {
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
