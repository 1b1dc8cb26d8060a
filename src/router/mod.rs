//! The router task: takes every frame from every link, learns where each sender sits, and
//! forwards the raw bytes per [`table`]'s rules. It also feeds the taps: the tlog writer (both
//! directions) and the vehicle tracker.
//!
//! Links arrive on two channels: the vehicle side and the client side (scripts, other ground
//! stations, and the daemon's own traffic). The side fixes the tlog direction and which link
//! health the tracker reports. Every egress is a bounded queue filled with `try_send`, so a slow
//! client never blocks the vehicle link; each drop is counted per link and per reason.

pub mod table;

use std::collections::BTreeMap;
use std::sync::Arc;
use std::sync::atomic::{AtomicU64, Ordering};

use tokio::sync::{mpsc, watch};
use tokio_util::sync::CancellationToken;
use vtol_link::{Frame, LinkEvent, LinkId, LinkSender, LinkStats};

use crate::tlog::{Direction, Record, TlogHandle};
use table::{Addressing, Route, RoutingTable};

const MSG_ID_COMMAND_ACK: u32 = 77;
/// Events taken from a channel per wake-up. Under load the router routes a run of frames per
/// wake-up and hands their tlog records over together (one wake-up of the writer thread per run
/// instead of one per frame); at low rates a run is one frame and nothing waits.
const BATCH: usize = 64;
const MSG_ID_SETUP_SIGNING: u32 = 256;

/// Which side of the daemon a link is on.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Side {
    /// The vehicle link.
    Vehicle,
    /// A client: script, ground station, or the daemon itself.
    Client,
}

/// One live link, as the status line and the TUI show it.
#[derive(Debug, Clone)]
pub struct LinkInfo {
    /// The link.
    pub id: LinkId,
    /// Vehicle or client side.
    pub side: Side,
    /// Peer description.
    pub peer: String,
    /// Its counters (rx/tx frames and bytes, queue-full drops, decode errors).
    pub stats: Arc<LinkStats>,
}

/// Router-wide counters (per-link ones live in each link's [`LinkStats`]).
#[derive(Debug, Default)]
pub struct RouterStats {
    /// Frames received from all links.
    pub frames_in: AtomicU64,
    /// Frame copies queued to egress links.
    pub frames_out: AtomicU64,
    /// Targeted frames whose target system was never seen.
    pub unroutable: AtomicU64,
    /// SETUP_SIGNING frames not forwarded (they carry a key).
    pub withheld_signing: AtomicU64,
    /// Copies lost because the link went down between routing and queueing.
    pub dropped_link_closed: AtomicU64,
    /// Frames the tracker tap could not take (it was behind).
    pub dropped_tap: AtomicU64,
}

/// A frame as the taps see it.
#[derive(Debug, Clone)]
pub struct Tapped {
    /// Ingress link.
    pub link: LinkId,
    /// Its side.
    pub side: Side,
    /// The frame.
    pub frame: Frame,
}

/// What the router publishes for others.
#[derive(Debug, Clone)]
pub struct RouterHandle {
    /// Counters.
    pub stats: Arc<RouterStats>,
    /// The live links.
    pub links: watch::Receiver<Vec<LinkInfo>>,
}

struct Egress {
    side: Side,
    peer: String,
    tx: LinkSender,
}

/// The router's state, driven by [`Router::run`].
pub struct Router {
    table: RoutingTable,
    egress: BTreeMap<LinkId, Egress>,
    live: Vec<LinkId>,
    out: Vec<LinkId>,
    stats: Arc<RouterStats>,
    links_tx: watch::Sender<Vec<LinkInfo>>,
    tlog: Option<TlogHandle>,
    /// Records of the current run, handed to the tlog writer after the run is forwarded.
    pending_log: Vec<Record>,
    /// Whether the run being routed is a lone frame (see [`Router::route`]).
    send_inline: bool,
    tap: Option<mpsc::Sender<Tapped>>,
}

impl std::fmt::Debug for Router {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Router")
            .field("links", &self.live)
            .finish_non_exhaustive()
    }
}

impl Router {
    /// A router that logs to `tlog` (if any) and copies every frame to `tap` (if any).
    #[must_use]
    pub fn new(
        tlog: Option<TlogHandle>,
        tap: Option<mpsc::Sender<Tapped>>,
    ) -> (Self, RouterHandle) {
        let (links_tx, links) = watch::channel(Vec::new());
        let stats = Arc::new(RouterStats::default());
        let router = Self {
            table: RoutingTable::new(),
            egress: BTreeMap::new(),
            live: Vec::new(),
            out: Vec::new(),
            stats: Arc::clone(&stats),
            links_tx,
            tlog,
            pending_log: Vec::with_capacity(BATCH),
            send_inline: true,
            tap,
        };
        (router, RouterHandle { stats, links })
    }

    /// Routes until `cancel` fires or both channels close; then closes the tlog (flushing it).
    pub async fn run(
        mut self,
        mut vehicle: mpsc::Receiver<LinkEvent>,
        mut clients: mpsc::Receiver<LinkEvent>,
        cancel: CancellationToken,
    ) {
        let (mut vehicle_open, mut clients_open) = (true, true);
        let (mut from_vehicle, mut from_clients) =
            (Vec::with_capacity(BATCH), Vec::with_capacity(BATCH));
        while vehicle_open || clients_open {
            tokio::select! {
                biased;
                () = cancel.cancelled() => break,
                n = vehicle.recv_many(&mut from_vehicle, BATCH), if vehicle_open => {
                    vehicle_open = n > 0;
                    self.send_inline = n == 1;
                    for ev in from_vehicle.drain(..) {
                        self.apply(Side::Vehicle, ev);
                    }
                }
                n = clients.recv_many(&mut from_clients, BATCH), if clients_open => {
                    clients_open = n > 0;
                    self.send_inline = n == 1;
                    for ev in from_clients.drain(..) {
                        self.apply(Side::Client, ev);
                    }
                }
            }
            self.flush_log();
        }
        if let Some(tlog) = self.tlog.take() {
            tlog.close();
        }
    }

    /// Hands the records of the run just routed to the tlog writer.
    fn flush_log(&mut self) {
        if let Some(tlog) = &self.tlog {
            for record in self.pending_log.drain(..) {
                tlog.log(record);
            }
        }
    }

    /// Applies one link event (and hands its tlog record over at once).
    pub fn handle(&mut self, side: Side, event: LinkEvent) {
        self.apply(side, event);
        self.flush_log();
    }

    /// Applies one link event; its tlog record waits for [`Router::flush_log`].
    fn apply(&mut self, side: Side, event: LinkEvent) {
        match event {
            LinkEvent::Up { id, peer, tx } => {
                tracing::info!(%id, %peer, ?side, "link up");
                self.egress.insert(id, Egress { side, peer, tx });
                self.publish_links();
            }
            LinkEvent::Down { id, reason } => {
                tracing::info!(%id, %reason, "link down");
                self.egress.remove(&id);
                self.table.forget_link(id);
                self.publish_links();
            }
            LinkEvent::Frame { id, frame } => self.route(id, side, frame),
        }
    }

    fn publish_links(&mut self) {
        self.live = self.egress.keys().copied().collect();
        let infos = self
            .egress
            .iter()
            .map(|(id, e)| LinkInfo {
                id: *id,
                side: e.side,
                peer: e.peer.clone(),
                stats: Arc::clone(e.tx.stats()),
            })
            .collect();
        self.links_tx.send_replace(infos);
    }

    fn route(&mut self, ingress: LinkId, side: Side, frame: Frame) {
        self.stats.frames_in.fetch_add(1, Ordering::Relaxed);
        self.table
            .learn(ingress, frame.system_id(), frame.component_id());
        let addressing = addressing(&frame);
        if let Some(command) = addressing.command {
            self.table
                .note_command(ingress, frame.system_id(), frame.component_id(), command);
        }
        if let Some(tap) = &self.tap
            && tap
                .try_send(Tapped {
                    link: ingress,
                    side,
                    frame: frame.clone(),
                })
                .is_err()
        {
            self.stats.dropped_tap.fetch_add(1, Ordering::Relaxed);
        }
        if frame.message_id() == MSG_ID_SETUP_SIGNING {
            self.stats.withheld_signing.fetch_add(1, Ordering::Relaxed);
            return;
        }
        if self.tlog.is_some() {
            let direction = match side {
                Side::Vehicle => Direction::FromVehicle,
                Side::Client => Direction::ToVehicle,
            };
            // Stamped now, handed over after the run is forwarded (see `flush_log`).
            self.pending_log.push(Record::now(direction, frame.clone()));
        }
        let route = self
            .table
            .route(ingress, &addressing, &self.live, &mut self.out);
        if route == Route::Unroutable {
            self.stats.unroutable.fetch_add(1, Ordering::Relaxed);
        }
        let single = self.out.len() == 1;
        for link in &self.out {
            let Some(e) = self.egress.get(link) else {
                continue;
            };
            // A lone frame (an idle router), or a frame for one link only, goes out from here
            // when the link allows it, which saves a task hop; a run of frames fanned out to
            // several links goes through the queues, so each link's writer sends in parallel.
            let sent = if self.send_inline || single {
                e.tx.try_send(frame.clone())
            } else {
                e.tx.try_send_queued(frame.clone())
            };
            match sent {
                Ok(()) => {
                    self.stats.frames_out.fetch_add(1, Ordering::Relaxed);
                }
                // Counted by the link itself (tx_dropped_queue_full).
                Err(vtol_link::SendError::Full) => {}
                Err(vtol_link::SendError::Closed) => {
                    self.stats
                        .dropped_link_closed
                        .fetch_add(1, Ordering::Relaxed);
                }
            }
        }
    }
}

/// Reads what routing needs from a frame without decoding it.
#[must_use]
pub fn addressing(frame: &Frame) -> Addressing {
    let mut a = Addressing {
        target: frame.target(),
        ..Addressing::default()
    };
    if let Some(cmd) = frame.raw_command() {
        a.command = Some(cmd.command);
    } else if frame.message_id() == MSG_ID_COMMAND_ACK {
        let p = frame.payload();
        a.ack_of_command = Some(u16::from_le_bytes([
            p.first().copied().unwrap_or(0),
            p.get(1).copied().unwrap_or(0),
        ]));
    }
    a
}
