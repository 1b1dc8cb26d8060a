//! The twin's vehicle loop ([`Shell`]): link events and harness calls as they come, the clock's
//! batches that advance the endpoint, the radio's impairment, replies before telemetry, the
//! tlog. The radio is `radio`'s; [`super::serve::Twin`] starts the loop.

use std::collections::{HashMap, HashSet};

use tokio::sync::mpsc;
use tokio::time::Instant;
use tokio_util::sync::CancellationToken;
use vtol_link::{Frame, LinkEvent, LinkId, LinkSender};

use crate::endpoint::{Endpoint, LinkKey, Outbound};
use crate::shell::clock::{BATCH, SimClock};
use crate::shell::harness::{Call, Reply, Request};
use crate::shell::radio::{Radio, Way};
use crate::shell::signing::{Admit, SetupOutcome, TwinSigning};
use crate::shell::tlog::TlogSink;

pub(crate) struct LinkEntry {
    tx: LinkSender,
    /// Bad frames already reported to the endpoint.
    bad_seen: u64,
    /// Telemetry frames left out because the link was short of room (kept for replies).
    shed: u64,
    /// Replies that found the queue full, oldest first: they go before anything else.
    backlog: std::collections::VecDeque<Frame>,
    /// Replies lost because even the backlog was full (a peer that reads nothing).
    replies_lost: u64,
}

impl LinkEntry {
    fn new(tx: LinkSender) -> Self {
        Self {
            tx,
            bad_seen: 0,
            shed: 0,
            backlog: std::collections::VecDeque::new(),
            replies_lost: 0,
        }
    }

    /// Moves backlogged replies into the queue while it has room.
    fn flush_backlog(&mut self) {
        while self.tx.room() > 0 {
            let Some(f) = self.backlog.pop_front() else {
                return;
            };
            let _ = self.tx.try_send(f);
        }
    }
}

/// Replies a link keeps waiting for room, frames; beyond it a reply is lost (and counted).
const REPLY_BACKLOG: usize = 4096;

/// Sim time one chunk of an `advance` runs before its frames go out, µs: the real-time
/// loop's batch, so a lockstep twin ticks its streams and events as finely as a real-time one.
const ADVANCE_CHUNK_US: u64 = BATCH.as_micros() as u64;

/// The vehicle loop's state: the endpoint, its clock, its links, the radio and the log.
pub(crate) struct Shell {
    pub(crate) endpoint: Endpoint,
    pub(crate) clock: SimClock,
    pub(crate) lockstep: bool,
    pub(crate) links: HashMap<LinkId, LinkEntry>,
    pub(crate) radio: Radio,
    pub(crate) tlog: Option<TlogSink>,
    /// Verifies what comes in and signs what goes out when keyed; handles SETUP_SIGNING.
    pub(crate) signing: TwinSigning,
    /// Links on serial devices, where SETUP_SIGNING is taken unsigned.
    pub(crate) local_links: HashSet<LinkId>,
    /// Free queue places kept for replies: below this, telemetry is shed.
    pub(crate) reserve: usize,
    /// Stops the loop, also while it waits for a lockstep reader.
    pub(crate) cancel: CancellationToken,
}

impl Shell {
    /// The vehicle loop: link events and harness calls are handled as they come; every clock
    /// batch advances the twin to the due sim time and sends what became due.
    pub(crate) async fn run(
        mut self,
        mut events: mpsc::Receiver<LinkEvent>,
        mut calls: mpsc::Receiver<Call>,
    ) -> Endpoint {
        let cancel = self.cancel.clone();
        let mut batch = self.clock.pause().map(|p| {
            let mut i = tokio::time::interval(p);
            i.set_missed_tick_behavior(tokio::time::MissedTickBehavior::Delay);
            i
        });
        let mut calls_open = true;
        loop {
            tokio::select! {
                biased;
                () = cancel.cancelled() => break,
                ev = events.recv() => match ev {
                    Some(ev) => self.on_link_event(ev).await,
                    // Only reachable once every sender is gone; keep flying for attached streams.
                    None => cancel.cancelled().await,
                },
                call = calls.recv(), if calls_open => match call {
                    Some(Call { request, reply }) => {
                        let r = self.on_request(request).await;
                        let _ = reply.send(r);
                    }
                    None => calls_open = false,
                },
                () = next_batch(&mut batch) => {
                    for entry in self.links.values_mut() {
                        entry.flush_backlog();
                    }
                    self.note_bad_frames();
                    self.signing.save_if_due();
                    self.tick().await;
                    if let Some(t) = &mut self.tlog {
                        t.hand_over();
                    }
                }
                () = self.radio.next_due() => {
                    let now = Instant::now();
                    while let Some((way, id, frame, telemetry)) = self.radio.pop_due(now) {
                        match way {
                            Way::In => self.on_frame(id, &frame).await,
                            Way::Out => self.deliver(id, frame, telemetry).await,
                        }
                    }
                }
            }
        }
        if let Some(t) = self.tlog.take() {
            let _ = tokio::task::spawn_blocking(move || t.finish()).await;
        }
        self.signing.finish();
        self.endpoint
    }

    async fn on_link_event(&mut self, ev: LinkEvent) {
        match ev {
            LinkEvent::Up { id, peer, tx } => {
                tracing::info!(%id, %peer, "link up");
                self.links.insert(id, LinkEntry::new(tx));
                self.endpoint.add_link(key(id));
                // The first frames (HEARTBEAT and every stream) go out now, not a batch later.
                self.tick().await;
            }
            LinkEvent::Frame { id, frame } => {
                if let Some(frame) = self.radio.pass(Way::In, id, frame, false) {
                    self.on_frame(id, &frame).await;
                }
            }
            LinkEvent::Down { id, reason } => {
                let (shed, replies_lost) = self
                    .links
                    .remove(&id)
                    .map_or((0, 0), |e| (e.shed, e.replies_lost));
                tracing::info!(%id, %reason, shed, replies_lost, "link down");
                self.endpoint.remove_link(key(id));
            }
        }
    }

    /// The time a tlog record carries: sim time under lockstep (the same on every run), Unix
    /// time otherwise.
    fn stamp_us(&self) -> u64 {
        if self.lockstep {
            self.endpoint.now_us()
        } else {
            crate::shell::tlog::unix_now_us()
        }
    }

    async fn on_frame(&mut self, id: LinkId, frame: &Frame) {
        // A keyed twin takes only rightly signed, fresh frames (and unsigned RADIO_STATUS):
        // anything else changes nothing and gets no answer. SETUP_SIGNING stops here, whatever
        // becomes of it: it carries a key, so neither the vehicle nor the tlog sees it.
        let local = self.local_links.contains(&id);
        let sysid = self.endpoint.sysid();
        match self
            .signing
            .admit(frame, local, sysid, std::time::SystemTime::now())
        {
            Admit::Pass => {}
            Admit::Refused(refusal) => {
                tracing::debug!(%id, %refusal, "frame refused");
                return;
            }
            Admit::SetupSigning(outcome) => {
                match outcome {
                    SetupOutcome::Keyed => {
                        tracing::info!(%id, "signing: new key from SETUP_SIGNING")
                    }
                    SetupOutcome::Disabled => {
                        tracing::info!(%id, "signing: switched off by SETUP_SIGNING")
                    }
                    SetupOutcome::Refused => tracing::warn!(
                        %id,
                        local,
                        "SETUP_SIGNING refused: not signed with the current key and not on a local (serial) link"
                    ),
                    SetupOutcome::NotForUs => {}
                }
                return;
            }
        }
        if self.tlog.is_some() {
            let stamp = self.stamp_us();
            if let Some(t) = &mut self.tlog {
                t.record(stamp, false, frame.as_bytes());
            }
        }
        let out = self.endpoint.handle(key(id), frame);
        self.dispatch(out).await;
        self.settle().await;
    }

    /// Lockstep: sends at once whatever the last event made due at the sim time standing (a
    /// message whose interval was just set, an event's text), so it follows its cause the same
    /// way on every run rather than whenever the next batch wakes.
    async fn settle(&mut self) {
        if self.lockstep {
            let now = self.endpoint.now_us();
            let out = self.endpoint.tick_at(now, now);
            self.dispatch(out).await;
        }
    }

    fn note_bad_frames(&mut self) {
        for entry in self.links.values_mut() {
            let s = entry.tx.stats().snapshot();
            let bad = s.bad_crc + s.bad_incompat;
            self.endpoint
                .note_bad_frames(bad.saturating_sub(entry.bad_seen));
            entry.bad_seen = bad;
        }
    }

    /// Runs the twin to the sim time the clock says is due and sends what became due.
    async fn tick(&mut self) {
        let now = Instant::now();
        let sim_us = self.clock.due_sim_us(now);
        let stream_us = self.clock.stream_us(now);
        let out = self.endpoint.tick_at(sim_us, stream_us);
        self.dispatch(out).await;
        let reports = match &mut self.radio.sik {
            Some(sik) => sik.reports(now, self.links.keys().copied()),
            None => Vec::new(),
        };
        for (id, f) in reports {
            self.deliver(id, f, false).await;
        }
    }

    async fn on_request(&mut self, request: Request) -> Reply {
        match request {
            Request::Advance { seconds } => self.advance(seconds).await,
            Request::State => Reply::State(crate::shell::harness::TrueState::of(
                self.endpoint.vehicle().telemetry(),
            )),
            Request::Param { name, value } => {
                let r = self.endpoint.set_param_announced(&name, value);
                let out = self.endpoint.take_outbound();
                self.dispatch(out).await;
                self.settle().await;
                match r {
                    Ok(value) => Reply::Param { name, value },
                    Err(e) => Reply::Error(e.to_string()),
                }
            }
        }
    }

    /// Lockstep: flies `seconds` more of sim time in chunks, sending each chunk's frames
    /// (waiting for room, never dropping) before the next.
    async fn advance(&mut self, seconds: f64) -> Reply {
        if !self.lockstep {
            return Reply::Error(
                "advance needs a lockstep twin (firmware-sim serve --lockstep)".into(),
            );
        }
        let step_us = crate::model::vehicle::PHYSICS_DT_US;
        let target =
            self.endpoint.now_us() + (seconds * 1e6 / step_us as f64).round() as u64 * step_us;
        while self.endpoint.now_us() < target && !self.cancel.is_cancelled() {
            let next = (self.endpoint.now_us() + ADVANCE_CHUNK_US).min(target);
            self.clock.advance_to(next);
            let out = self.endpoint.tick_at(next, next);
            self.dispatch(out).await;
            // A long advance still lets the links' writers and other tasks run.
            tokio::task::consume_budget().await;
        }
        if let Some(t) = &mut self.tlog {
            t.hand_over();
        }
        Reply::Time(self.endpoint.now_us())
    }

    async fn dispatch(&mut self, out: Vec<Outbound>) {
        if out.is_empty() {
            return;
        }
        let stamp = self.stamp_us();
        for o in out {
            let id = LinkId(o.link.0 as u32);
            let f = match self.signing.outgoing(o.frame, std::time::SystemTime::now()) {
                Ok(f) => f,
                Err(e) => {
                    tracing::error!("cannot sign an outgoing frame: {e}");
                    continue;
                }
            };
            if let Some(t) = &mut self.tlog {
                t.record(stamp, true, f.as_bytes());
            }
            if let Some(sik) = &mut self.radio.sik
                && !sik.admit(id, f.as_bytes().len(), Instant::now())
            {
                continue;
            }
            if let Some(f) = self.radio.pass(Way::Out, id, f, o.telemetry) {
                self.deliver(id, f, o.telemetry).await;
            }
        }
    }

    /// Queues a frame on its link. Under lockstep it waits for room (nothing is lost, the run
    /// stays the same). Otherwise the vehicle never waits for one slow peer: a link short of
    /// room sheds telemetry, keeping its last places for replies, and a reply that finds the
    /// queue full waits in the link's backlog, in order, for the next batch.
    async fn deliver(&mut self, id: LinkId, frame: Frame, telemetry: bool) {
        let Some(entry) = self.links.get_mut(&id) else {
            return;
        };
        if self.lockstep {
            // Waits for the reader, but not past a shutdown.
            tokio::select! {
                _ = entry.tx.send(frame) => {}
                () = self.cancel.cancelled() => {}
            }
            return;
        }
        // This loop is the queue's only producer, so room seen here is room at the send.
        if telemetry {
            if entry.backlog.is_empty() && entry.tx.room() > self.reserve {
                let _ = entry.tx.try_send(frame);
            } else {
                entry.shed += 1;
            }
            return;
        }
        entry.flush_backlog();
        if entry.backlog.is_empty() && entry.tx.room() > 0 {
            let _ = entry.tx.try_send(frame);
        } else if entry.backlog.len() < REPLY_BACKLOG {
            entry.backlog.push_back(frame);
        } else {
            entry.replies_lost += 1;
        }
    }
}

async fn next_batch(batch: &mut Option<tokio::time::Interval>) {
    match batch {
        Some(i) => {
            i.tick().await;
        }
        // As fast as possible: still yield so link events get their turn.
        None => tokio::task::yield_now().await,
    }
}

fn key(id: LinkId) -> LinkKey {
    LinkKey(u64::from(id.0))
}
