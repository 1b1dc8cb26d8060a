//! The router: takes every frame from every link, learns where each sender sits, and forwards
//! the raw bytes per the routing table's rules ([`crate::links::table`]). It also feeds the
//! taps: the tlog writer (both directions) and the vehicle tracker.
//!
//! Links are on one of two sides: the vehicle side and the client side (scripts, other ground
//! stations, and the daemon's own traffic). The side fixes the tlog direction and which link
//! health the tracker reports. Every egress is a bounded queue filled without waiting, so a
//! slow client never blocks the vehicle link; each drop is counted per link and per reason.
//!
//! Each client link carries its endpoint's [`policy::EndpointPolicy`] (trust and rate limit),
//! given when the endpoint is spawned ([`SharedRouter::events_with`]): `read-only` links are not
//! routed from, `sign` links' unsigned frames are signed with the daemon's key, and a rate
//! limit drops what a link cannot take (counted for that link). With a key
//! ([`Router::set_signing`]) frames from the vehicle are verified first and refused ones go
//! nowhere: not to clients, not to the tlog, not to the tracker. SETUP_SIGNING (it carries a
//! key) is never forwarded, logged or tapped, from any side.
//!
//! It is driven one way, [`Router::share`]: the router state sits behind a lock and each link
//! task routes the frames it received itself, before it reads its socket again: no queue and
//! no task hop between a link and the router. A run of frames (one wake-up of a link task) is
//! routed under one lock, each egress link gets the run's frames for it in one go (one
//! `sendmmsg` for a UDP peer whose queue is empty); then the tlog gets the run's records in
//! one hand-off, and the tracker's tap gets the run's copies in one hand-off too. The lock is
//! then released, and only then does the link's thread apply the tapped frames to the
//! tracker's state, once a run of them waits and the state is free ([`crate::tap::queue`]):
//! it takes the tracker's state without waiting, swaps the frames out of the tap under the
//! tap's lock (the innermost, held by the router only to hand a run over) and decodes them
//! holding the tracker's locks only, so another link's routing never waits on a decode.
//!
//! Crate-private: the daemon is its only caller ([`crate::daemon::Routing`] for tests). What
//! others read of it (its counters, the live links, the disputed system ids) is in
//! [`crate::links`].

use std::collections::BTreeMap;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Arc, Mutex, MutexGuard, PoisonError};
use std::time::Instant;

use tokio::sync::watch;
use vtol_link::{
    Events, Frame, LinkEvent, LinkEventHandler, LinkId, LinkSender, SendSummary, SystemId,
};

use crate::links::table::{Route, RoutingTable, addressing};
use crate::links::{LinkInfo, RouterHandle, RouterStats, Side, SysidConflict};
use crate::tap::{Handed, TapApplier, TapSender, Tapped, clock};
use crate::tlog::{Direction, Record, TlogHandle, unix_time_us};
use crate::trust::policy::{EndpointPolicy, PolicyCounters, TokenBucket, Trust};
use crate::trust::signing::{DaemonSigning, SigningCounters};

/// Records and tapped copies a run's buffers hold before they grow.
const RUN_CAPACITY: usize = 64;

struct Egress {
    side: Side,
    peer: String,
    tx: LinkSender,
    /// Frames of the run being routed that go out on this link, in order.
    run: Vec<Frame>,
    policy: EndpointPolicy,
    bucket: Option<TokenBucket>,
    counters: Arc<PolicyCounters>,
}

/// The router's state, shared by the link tasks ([`Router::share`]).
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
    tap: Option<TapSender>,
    /// Copies of the current run for the tap, handed over after the run.
    pending_tap: Vec<Tapped>,
    signing: Option<DaemonSigning>,
    conflicts_tx: watch::Sender<Vec<SysidConflict>>,
}

impl std::fmt::Debug for Router {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Router")
            .field("links", &self.live)
            .finish_non_exhaustive()
    }
}

impl Router {
    /// A router that logs to `tlog` (if any) and copies every frame to `tap` (if any). The tap
    /// is filled without waiting and without caring whether its reader is awake: a full tap
    /// drops the copy and counts it.
    #[must_use]
    pub fn new(tlog: Option<TlogHandle>, tap: Option<TapSender>) -> (Self, RouterHandle) {
        let (links_tx, links) = watch::channel(Vec::new());
        let stats = Arc::new(RouterStats::default());
        let (conflicts_tx, conflicts) = watch::channel(Vec::new());
        let router = Self {
            table: RoutingTable::new(),
            egress: BTreeMap::new(),
            live: Vec::new(),
            out: Vec::new(),
            stats: Arc::clone(&stats),
            links_tx,
            tlog,
            pending_log: Vec::with_capacity(RUN_CAPACITY),
            tap,
            pending_tap: Vec::with_capacity(RUN_CAPACITY),
            signing: None,
            conflicts_tx,
        };
        (
            router,
            RouterHandle {
                stats,
                links,
                signing: None,
                conflicts,
            },
        )
    }

    /// Gives the router the daemon's key: it verifies the vehicle's frames and signs for
    /// `sign` links. Returns the counters to put in the [`RouterHandle`].
    pub fn set_signing(&mut self, signing: DaemonSigning) -> Arc<SigningCounters> {
        let counters = Arc::clone(signing.counters());
        self.signing = Some(signing);
        counters
    }

    /// Shares the router between the link tasks: each routes what it receives itself. Hand
    /// [`SharedRouter::events`] to the links of each side; call [`SharedRouter::close`] at
    /// shutdown (it closes the tlog, flushing it).
    #[must_use]
    pub fn share(self) -> SharedRouter {
        let tap = self.tap.as_ref().map(TapSender::applier);
        SharedRouter {
            router: Arc::new(Mutex::new(Some(self))),
            tap,
        }
    }

    /// Applies one link event at once (its frame forwarded, its record handed to the tlog), a
    /// new link getting `policy`. Returns what became of the tapped copies
    /// ([`Router::end_run`]).
    fn handle(&mut self, side: Side, policy: EndpointPolicy, event: LinkEvent) -> Handed {
        let now = clock();
        self.apply(side, policy, event, unix_time_us(), now);
        self.end_run()
    }

    /// Routes a run of frames (one wake-up of a link task) and empties `frames`. Returns what
    /// became of the tapped copies ([`Router::end_run`]).
    fn route_run(&mut self, side: Side, frames: &mut Vec<(LinkId, Frame)>) -> Handed {
        // One clock read per run: its frames arrived together.
        let t_us = unix_time_us();
        let now = clock();
        for (id, frame) in frames.drain(..) {
            self.route(id, side, frame, t_us, now);
        }
        self.end_run()
    }

    /// Saves the signing state (if signing); errors are logged, routing goes on.
    fn save_signing(&self) {
        if let Some(s) = &self.signing
            && let Err(e) = s.save()
        {
            tracing::warn!("{e}");
        }
    }

    /// Sends what the run routed to each egress link, then hands the run's records to the tlog
    /// and its copies to the tracker's tap. The sends come first: nothing a frame's bookkeeping
    /// costs, or a thread it wakes, comes between its arrival and its departure. The caller
    /// applies the tapped frames waiting for the tracker's state (if a run of them waits) once
    /// the router's lock is released ([`TapApplier::apply_waiting`]).
    fn end_run(&mut self) -> Handed {
        self.send_runs();
        if let Some(tlog) = &self.tlog
            && !self.pending_log.is_empty()
        {
            tlog.log_many(self.pending_log.drain(..));
        }
        let Some(tap) = &self.tap else {
            return Handed::default();
        };
        let handed = tap.hand_over(&mut self.pending_tap);
        if handed.dropped > 0 {
            self.stats
                .dropped_tap
                .fetch_add(handed.dropped as u64, Ordering::Relaxed);
        }
        handed
    }

    /// Hands each egress link the frames routed to it in this run.
    fn send_runs(&mut self) {
        let mut total = SendSummary::default();
        for e in self.egress.values_mut() {
            if !e.run.is_empty() {
                total += e.tx.try_send_many(&mut e.run);
            }
        }
        // Queue-full drops are counted by the links themselves (tx_dropped_queue_full).
        let add = |a: &AtomicU64, n: usize| {
            if n > 0 {
                a.fetch_add(n as u64, Ordering::Relaxed);
            }
        };
        add(&self.stats.frames_out, total.taken);
        add(&self.stats.dropped_link_closed, total.closed);
    }

    fn close(&mut self) {
        self.send_runs();
        self.save_signing();
        if let Some(tlog) = self.tlog.take() {
            tlog.log_many(self.pending_log.drain(..));
            tlog.close();
        }
    }

    /// Applies one link event; its copies and record wait for [`Router::end_run`].
    fn apply(
        &mut self,
        side: Side,
        policy: EndpointPolicy,
        event: LinkEvent,
        t_us: u64,
        now: Instant,
    ) {
        match event {
            LinkEvent::Up { id, peer, tx } => {
                tracing::info!(%id, %peer, ?side, %policy, "link up");
                self.send_runs();
                self.egress.insert(
                    id,
                    Egress {
                        side,
                        peer,
                        tx,
                        run: Vec::new(),
                        policy,
                        bucket: policy.rate.map(|r| TokenBucket::new(r, now)),
                        counters: Arc::default(),
                    },
                );
                self.publish_links();
            }
            LinkEvent::Down { id, reason } => {
                tracing::info!(%id, %reason, "link down");
                self.send_runs();
                self.egress.remove(&id);
                self.table.forget_link(id);
                self.conflicts_tx.send_if_modified(|c| {
                    let before = c.len();
                    c.retain(|x| x.owner != id && x.claimant != id);
                    c.len() != before
                });
                self.publish_links();
            }
            LinkEvent::Frame { id, frame } => self.route(id, side, frame, t_us, now),
        }
    }

    /// Counts a frame refused for a disputed system id; a new dispute is logged and published.
    fn note_conflict(&mut self, system: SystemId, owner: LinkId, claimant: LinkId) {
        self.stats.sysid_conflicts.fetch_add(1, Ordering::Relaxed);
        let c = SysidConflict {
            system,
            owner,
            claimant,
        };
        self.conflicts_tx.send_if_modified(|all| {
            if all.contains(&c) {
                return false;
            }
            tracing::warn!(%system, %owner, %claimant, "system id claimed by two vehicle links");
            all.push(c);
            all.sort();
            true
        });
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
                policy: e.policy,
                policy_counters: Arc::clone(&e.counters),
            })
            .collect();
        self.links_tx.send_replace(infos);
    }

    /// Applies the ingress side's rules before routing: the vehicle's signatures, a client
    /// link's trust. `None` when the frame goes nowhere (counted).
    fn admit(&mut self, ingress: LinkId, side: Side, frame: Frame) -> Option<Frame> {
        if frame.message_id() == vtol_link::protocol::id::SETUP_SIGNING {
            // It carries a key: never forwarded, logged or shown, from any side.
            self.stats.withheld_signing.fetch_add(1, Ordering::Relaxed);
            return None;
        }
        if side == Side::Vehicle {
            if let Some(s) = &mut self.signing
                && let Err(refusal) = s.verify_vehicle(&frame)
            {
                tracing::debug!(%ingress, %refusal, "vehicle frame refused");
                return None;
            }
            return Some(frame);
        }
        let Some(e) = self.egress.get(&ingress) else {
            return Some(frame);
        };
        match e.policy.trust {
            Trust::Trusted => Some(frame),
            Trust::ReadOnly => {
                e.counters.refused_read_only.fetch_add(1, Ordering::Relaxed);
                self.stats.refused_read_only.fetch_add(1, Ordering::Relaxed);
                None
            }
            Trust::Sign => {
                let Some(s) = self.signing.as_mut().filter(|_| !frame.is_signed()) else {
                    return Some(frame);
                };
                match s.sign(&frame, ingress) {
                    Ok(signed) => {
                        e.counters.signed.fetch_add(1, Ordering::Relaxed);
                        Some(signed)
                    }
                    Err(err) => {
                        tracing::debug!(%ingress, %err, "client frame not signed, not routed");
                        e.counters.unsignable.fetch_add(1, Ordering::Relaxed);
                        self.stats.unsignable.fetch_add(1, Ordering::Relaxed);
                        None
                    }
                }
            }
        }
    }

    /// Routes one frame: applies the ingress link's policy, learns its sender, feeds the taps,
    /// and adds it to the run of each egress link it goes to (within the link's rate limit).
    fn route(&mut self, ingress: LinkId, side: Side, frame: Frame, t_us: u64, now: Instant) {
        self.stats.frames_in.fetch_add(1, Ordering::Relaxed);
        let Some(frame) = self.admit(ingress, side, frame) else {
            return;
        };
        let (system, component) = frame.sender();
        // Every frame received is logged, a disputed one too.
        if self.tlog.is_some() {
            let direction = match side {
                Side::Vehicle => Direction::FromVehicle,
                Side::Client => Direction::ToVehicle,
            };
            self.pending_log.push(Record {
                t_us,
                direction,
                frame: frame.clone(),
            });
        }
        if side == Side::Vehicle {
            match self.table.claim(ingress, system, now) {
                Ok(None) => {}
                Ok(Some(previous)) => {
                    tracing::info!(%system, %previous, link = %ingress, "system id taken over from a silent link");
                    self.conflicts_tx.send_if_modified(|c| {
                        let before = c.len();
                        c.retain(|x| x.system != system);
                        c.len() != before
                    });
                }
                Err(owner) => {
                    self.note_conflict(system, owner, ingress);
                    return;
                }
            }
        }
        self.table.learn(ingress, system, component);
        let addressing = addressing(&frame);
        if let Some(command) = addressing.command {
            self.table.note_command(ingress, system, component, command);
        }
        if self.tap.is_some() {
            self.pending_tap.push(Tapped {
                link: ingress,
                side,
                frame: frame.clone(),
                at: now,
            });
        }
        let route = self
            .table
            .route(ingress, &addressing, &self.live, &mut self.out);
        if route == Route::Unroutable {
            self.stats.unroutable.fetch_add(1, Ordering::Relaxed);
        }
        // A vehicle's broadcasts go to the clients, not to the other vehicles: a fleet's
        // telemetry would otherwise reach every vehicle (N² traffic over their radios). What
        // one vehicle addresses to another still goes there.
        let clients_only = side == Side::Vehicle && route == Route::Broadcast;
        for link in &self.out {
            if let Some(e) = self.egress.get_mut(link) {
                // What the link does not want (the daemon's own link reads a few message
                // types) is not copied for it at all.
                if (clients_only && e.side == Side::Vehicle) || !e.tx.accepts(&frame) {
                    continue;
                }
                if let Some(bucket) = &mut e.bucket
                    && !bucket.take(now)
                {
                    e.counters.dropped_rate.fetch_add(1, Ordering::Relaxed);
                    self.stats.dropped_rate.fetch_add(1, Ordering::Relaxed);
                    continue;
                }
                e.run.push(frame.clone());
            }
        }
    }
}

/// The router shared by the link tasks ([`Router::share`]).
#[derive(Debug, Clone)]
pub struct SharedRouter {
    router: Arc<Mutex<Option<Router>>>,
    /// Applies the tracker's tapped frames once the router's lock is released.
    tap: Option<TapApplier>,
}

impl SharedRouter {
    /// Where the links of `side` report: each calls the router from its own task.
    #[must_use]
    pub fn events(&self, side: Side) -> Events {
        self.events_with(side, EndpointPolicy::default())
    }

    /// Where the links of one endpoint report: each link it opens carries `policy`.
    #[must_use]
    pub fn events_with(&self, side: Side, policy: EndpointPolicy) -> Events {
        let handler: Arc<dyn LinkEventHandler> = Arc::new(SideHandler {
            router: self.clone(),
            side,
            policy,
        });
        Events::Inline(handler)
    }

    /// Saves the signing state now (the daemon calls it every [`crate::trust::signing::SAVE_EVERY`]).
    pub fn save_signing(&self) {
        // The state is taken under the lock; the file is written outside it.
        let job = self
            .lock()
            .as_ref()
            .and_then(|r| r.signing.as_ref())
            .and_then(|s| s.file().map(|f| (s.state(), f.to_owned())));
        if let Some((state, file)) = job
            && let Err(e) = state.save(&file)
        {
            tracing::warn!("{e}");
        }
    }

    /// Stops routing: later events are refused (their links stop), what the last run routed is
    /// sent, and the tlog is closed (everything logged reaches the file).
    pub fn close(&self) {
        let router = self.lock().take();
        if let Some(mut router) = router {
            router.close();
        }
    }

    fn lock(&self) -> MutexGuard<'_, Option<Router>> {
        // A panic while routing leaves the table and queues usable: keep routing.
        self.router.lock().unwrap_or_else(PoisonError::into_inner)
    }

    /// Applies the tracker's waiting frames after a run that left a run of them; called with
    /// the router's lock released, so the tracker's work never holds up another link.
    fn apply_tap(&self, handed: Handed) {
        if let Some(tap) = &self.tap {
            tap.apply_waiting(handed);
        }
    }
}

/// The links of one side, calling into the shared router.
struct SideHandler {
    router: SharedRouter,
    side: Side,
    policy: EndpointPolicy,
}

impl LinkEventHandler for SideHandler {
    fn event(&self, event: LinkEvent) -> bool {
        let mut guard = self.router.lock();
        let Some(router) = guard.as_mut() else {
            return false;
        };
        let handed = router.handle(self.side, self.policy, event);
        drop(guard);
        self.router.apply_tap(handed);
        true
    }

    fn frames(&self, frames: &mut Vec<(LinkId, Frame)>) -> bool {
        let mut guard = self.router.lock();
        let Some(router) = guard.as_mut() else {
            frames.clear();
            return false;
        };
        let handed = router.route_run(self.side, frames);
        drop(guard);
        self.router.apply_tap(handed);
        true
    }

    fn is_closed(&self) -> bool {
        self.router.lock().is_none()
    }
}
