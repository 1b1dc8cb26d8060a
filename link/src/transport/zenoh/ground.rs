//! The ground end of a fleet (`--vehicle zenoh:FLEET/*`): one link per vehicle.
//!
//! With an inline owner ([`Events::Inline`], the daemon's router) a sample is decoded and
//! routed in the Zenoh thread that received it, as a UDP reader routes a datagram on its own
//! thread: no queue and no wake-up of another task per sample. With a queue owner the samples
//! go through a subscriber queue to the ground task, which hands the frames on.
//!
//! A vehicle's link goes down [`LEAVE_GRACE`] after its liveliness token goes away: the token's
//! removal may overtake the vehicle's last samples (they are separate subscriptions, and the
//! liveliness goes through the ground task while the data may be routed inline), and what it
//! published before it left still reaches its link; each of its samples in the grace extends
//! it. Samples later still, or a returning vehicle's first samples ahead of its new token, bring
//! its link back up at once (the same vehicle, on a new link) with a grace of its own that a new
//! token ends; nothing the network delivered is dropped. A new token (or, without one, a
//! vehicle's first samples) brings a link up. The ground end remembers a departed vehicle for
//! [`GONE_MEMORY`] only, so a fleet whose vehicles come and go keeps a bounded state.

use std::collections::HashMap;
use std::sync::{Arc, Mutex, PoisonError};
use std::time::Duration;

use tokio::sync::mpsc;
use tokio::task::JoinHandle;
use tokio::time::Instant;
use tokio_util::sync::CancellationToken;
use zenoh::key_expr::KeyExpr;
use zenoh::sample::{Sample, SampleKind};
use zenoh::{Session, Wait};

use super::{
    SUBSCRIBER_DEPTH, decode_sample, from_vehicle_key, liveliness_key, publish_loop,
    to_vehicle_key, vehicle_of, zerr,
};
use crate::frame::Frame;
use crate::transport::{
    Events, LinkError, LinkEvent, LinkEventHandler, LinkId, LinkOptions, LinkSender, LinkStats,
    emit, emit_frames,
};

/// How long a vehicle's link outlives its liveliness token.
pub(crate) const LEAVE_GRACE: Duration = Duration::from_millis(500);

/// How long the ground end remembers that a vehicle left (its late samples then get a link with
/// a grace, not one that lasts until a token goes away).
pub(crate) const GONE_MEMORY: Duration = Duration::from_secs(60);

/// Most vehicles whose data key the ground end declares in the session.
///
/// Each declaration takes one of the session's key ids, which are 16-bit on the wire and which
/// Zenoh hands out from a counter that never reuses a freed one: past 65 535 declarations it
/// wraps onto ids that are still in use. A vehicle's key is therefore declared once, when it
/// is first seen, and kept for the ground end's life (a returning vehicle's link finds it
/// declared), and no more than this many: declared per link, a fleet's departures and returns
/// would use the ids up in hours (the thousand's soak: about 2.5 a second per daemon). The
/// vehicles past it are matched against the subscription, as every sample was before keys
/// were declared.
pub(crate) const MAX_DECLARED_KEYS: usize = 1024;

/// One vehicle as the ground end sees it.
struct GroundLink {
    id: LinkId,
    stats: Arc<LinkStats>,
    decoder: crate::decoder::FrameDecoder,
    stop: CancellationToken,
    /// Its token went away: the link goes down at this time.
    leaving: Option<Instant>,
}

/// The ground end's vehicles, shared by the sample handler and the liveliness task.
struct Ground {
    fleet: String,
    session: Session,
    opts: LinkOptions,
    cancel: CancellationToken,
    runtime: tokio::runtime::Handle,
    links: HashMap<String, GroundLink>,
    /// Vehicles whose link went down after their token went away, and when: a sample of theirs
    /// brings a link up with a grace (no token is known to be live). Forgotten after
    /// [`GONE_MEMORY`].
    gone: HashMap<String, Instant>,
    /// Samples that came after their vehicle's link went down (each brought it back up).
    late: u64,
    /// Vehicles' data keys declared in the session, by vehicle, for the ground end's life (at
    /// most [`MAX_DECLARED_KEYS`]): a sample on a declared key takes the session's cached
    /// route to the subscriber instead of matching the key against every subscription.
    declared: HashMap<String, KeyExpr<'static>>,
    /// Wakes the ground task when a sample handler set a grace (an earlier expiry).
    wake: Arc<tokio::sync::Notify>,
}

impl Ground {
    /// A new link for `vehicle`, its publisher started; its Up event.
    fn open(&mut self, vehicle: &str) -> LinkEvent {
        let id = LinkId::next();
        let stats = Arc::new(LinkStats::default());
        let (tx, rx) = mpsc::channel(self.opts.queue_len.max(1));
        tracing::debug!(%id, fleet = %self.fleet, %vehicle, "fleet vehicle up");
        let stop = self.cancel.child_token();
        let writer = publish_loop(
            self.session.clone(),
            to_vehicle_key(&self.fleet, vehicle),
            rx,
            stats.clone(),
        );
        if !self.declared.contains_key(vehicle) && self.declared.len() < MAX_DECLARED_KEYS {
            match self
                .session
                .declare_keyexpr(from_vehicle_key(&self.fleet, vehicle))
                .wait()
            {
                Ok(k) => {
                    self.declared.insert(vehicle.to_string(), k);
                }
                Err(e) => tracing::debug!(%vehicle, "data key not declared: {e}"),
            }
        }
        let s = stop.clone();
        self.runtime.spawn(async move {
            tokio::select! {
                _ = s.cancelled() => {}
                _ = writer => {}
            }
        });
        self.links.insert(
            vehicle.to_string(),
            GroundLink {
                id,
                stats: stats.clone(),
                decoder: crate::decoder::FrameDecoder::new(),
                stop,
                leaving: None,
            },
        );
        LinkEvent::Up {
            id,
            peer: format!("zenoh {}/{vehicle}", self.fleet),
            tx: LinkSender::new(tx, stats, self.opts.accept.clone()),
        }
    }

    /// Decodes a data sample into `frames`; a new link's Up event goes first in `events`.
    fn data(
        &mut self,
        sample: &Sample,
        events: &mut Vec<LinkEvent>,
        frames: &mut Vec<(LinkId, Frame)>,
    ) {
        let Some(v) = vehicle_of(sample.key_expr().as_str(), 3) else {
            return;
        };
        let now = Instant::now();
        if self.gone.remove(v).is_some() {
            // Its last samples after the grace, or its first ones back ahead of its new token.
            self.late += 1;
            tracing::debug!(fleet = %self.fleet, vehicle = %v, "sample after the vehicle left: back up");
            let up = self.open(v);
            events.push(up);
            if let Some(l) = self.links.get_mut(v) {
                l.leaving = Some(now);
            }
        } else if !self.links.contains_key(v) {
            let up = self.open(v);
            events.push(up);
        }
        if let Some(l) = self.links.get_mut(v) {
            if let Some(t) = &mut l.leaving {
                let was = *t;
                *t = was.max(now + LEAVE_GRACE);
                if was <= now {
                    self.wake.notify_one();
                }
            }
            decode_sample(l.id, sample, &mut l.decoder, &l.stats, frames);
        }
    }

    /// A liveliness sample: a new token brings a link up (or keeps a leaving one), a removed
    /// one starts its link's grace.
    fn liveliness(&mut self, sample: &Sample, events: &mut Vec<LinkEvent>) {
        let Some(v) = vehicle_of(sample.key_expr().as_str(), 2) else {
            return;
        };
        let v = v.to_string();
        match sample.kind() {
            SampleKind::Put => {
                self.gone.remove(&v);
                match self.links.get_mut(&v) {
                    Some(l) => l.leaving = None,
                    None => events.push(self.open(&v)),
                }
            }
            SampleKind::Delete => {
                if let Some(l) = self.links.get_mut(&v) {
                    l.leaving.get_or_insert(Instant::now() + LEAVE_GRACE);
                }
            }
        }
    }

    /// The links whose grace is over: down, their vehicles gone; departures older than
    /// [`GONE_MEMORY`] forgotten.
    fn expire(&mut self, now: Instant, events: &mut Vec<LinkEvent>) {
        self.gone
            .retain(|_, at| now.duration_since(*at) < GONE_MEMORY);
        let over: Vec<String> = self
            .links
            .iter()
            .filter(|(_, l)| l.leaving.is_some_and(|t| t <= now))
            .map(|(v, _)| v.clone())
            .collect();
        for v in over {
            if let Some(l) = self.links.remove(&v) {
                l.stop.cancel();
                let reason = format!(
                    "{}/{v} left the fleet (its liveliness token is gone)",
                    self.fleet
                );
                tracing::debug!(id = %l.id, %reason, "link down");
                events.push(LinkEvent::Down { id: l.id, reason });
                self.gone.insert(v, now);
            }
        }
    }

    fn next_expiry(&self) -> Option<Instant> {
        let forget = self.gone.values().min().map(|t| *t + GONE_MEMORY);
        self.links
            .values()
            .filter_map(|l| l.leaving)
            .chain(forget)
            .min()
    }
}

type Shared = Arc<Mutex<Ground>>;

fn lock(g: &Shared) -> std::sync::MutexGuard<'_, Ground> {
    g.lock().unwrap_or_else(PoisonError::into_inner)
}

/// Hands events, then frames, to an inline owner; false when it is gone.
fn deliver_inline(
    h: &dyn LinkEventHandler,
    events: &mut Vec<LinkEvent>,
    frames: &mut Vec<(LinkId, Frame)>,
) -> bool {
    let mut ok = true;
    for e in events.drain(..) {
        ok &= h.event(e);
    }
    ok && (frames.is_empty() || h.frames(frames))
}

/// Hands events, then frames, to the owner; false when it is gone.
async fn deliver(
    events: &Events,
    evs: &mut Vec<LinkEvent>,
    frames: &mut Vec<(LinkId, Frame)>,
    cancel: &CancellationToken,
) -> bool {
    for e in evs.drain(..) {
        if !emit(events, e, cancel).await {
            return false;
        }
    }
    emit_frames(events, frames, cancel).await
}

/// Subscribes to the fleet's data and liveliness and starts the ground task.
// Over 80 lines: the subscriptions' set-up (the data's two forms, inline and queued) and the one
// task that owns them; split, the task would take seven handles from the set-up.
pub(crate) async fn spawn_ground_end(
    session: Session,
    fleet: &str,
    vehicle: Option<&str>,
    events: Events,
    opts: LinkOptions,
    cancel: CancellationToken,
) -> Result<JoinHandle<()>, LinkError> {
    let name = vehicle.unwrap_or("*");
    let data_key = from_vehicle_key(fleet, name);
    let live_key = liveliness_key(fleet, name);
    let wake = Arc::new(tokio::sync::Notify::new());
    let ground: Shared = Arc::new(Mutex::new(Ground {
        fleet: fleet.to_string(),
        session: session.clone(),
        opts,
        cancel: cancel.clone(),
        runtime: tokio::runtime::Handle::current(),
        links: HashMap::new(),
        gone: HashMap::new(),
        late: 0,
        declared: HashMap::new(),
        wake: wake.clone(),
    }));
    // The owner gone (an inline handler said so): the ground task stops.
    let owner_gone = cancel.child_token();
    let sub_err = |e| zerr(&format!("cannot subscribe to {data_key}"), e);
    let (inline_sub, queued_sub) = match &events {
        Events::Inline(h) => {
            let (h, g, gone) = (h.clone(), ground.clone(), owner_gone.clone());
            let sub = session
                .declare_subscriber(data_key.clone())
                .callback(move |sample: Sample| {
                    if gone.is_cancelled() {
                        return;
                    }
                    let (mut evs, mut frames) = (Vec::new(), Vec::new());
                    let mut g = lock(&g);
                    g.data(&sample, &mut evs, &mut frames);
                    // Routed under the ground's lock: a link's Up, its frames and its Down
                    // reach the owner in order.
                    if !deliver_inline(h.as_ref(), &mut evs, &mut frames) {
                        gone.cancel();
                    }
                })
                .await
                .map_err(sub_err)?;
            (Some(sub), None)
        }
        Events::Queue(_) => {
            let sub = session
                .declare_subscriber(data_key.clone())
                .with(zenoh::handlers::FifoChannel::new(SUBSCRIBER_DEPTH))
                .await
                .map_err(sub_err)?;
            (None, Some(sub))
        }
    };
    let live = session
        .liveliness()
        .declare_subscriber(live_key.clone())
        .history(true)
        .await
        .map_err(|e| zerr(&format!("cannot watch the liveliness of {live_key}"), e))?;
    Ok(tokio::spawn(async move {
        let _inline_sub = inline_sub;
        let (mut evs, mut frames) = (Vec::new(), Vec::new());
        loop {
            let expiry = lock(&ground).next_expiry();
            let next_data = async {
                match &queued_sub {
                    Some(s) => s.recv_async().await.ok(),
                    None => std::future::pending().await,
                }
            };
            let what = tokio::select! {
                biased;
                _ = owner_gone.cancelled() => break,
                s = live.recv_async() => match s {
                    Ok(sample) => Wake::Liveliness(sample),
                    Err(_) => break,
                },
                () = sleep_until_opt(expiry) => Wake::Expiry,
                () = wake.notified() => Wake::Expiry,
                s = next_data => match s {
                    Some(sample) => Wake::Data(sample),
                    None => break,
                },
            };
            let inline = {
                let mut g = lock(&ground);
                match &what {
                    Wake::Liveliness(s) => g.liveliness(s, &mut evs),
                    Wake::Expiry => g.expire(Instant::now(), &mut evs),
                    Wake::Data(s) => g.data(s, &mut evs, &mut frames),
                }
                // Under the ground's lock, as the sample handler delivers.
                match &events {
                    Events::Inline(h) => Some(deliver_inline(h.as_ref(), &mut evs, &mut frames)),
                    Events::Queue(_) => None,
                }
            };
            let ok = match inline {
                Some(ok) => ok,
                None => deliver(&events, &mut evs, &mut frames, &cancel).await,
            };
            if !ok {
                break;
            }
        }
        owner_gone.cancel();
        let late = lock(&ground).late;
        if late > 0 {
            tracing::debug!(late, "samples that came after their vehicle left");
        }
        let links: Vec<GroundLink> = lock(&ground).links.drain().map(|(_, l)| l).collect();
        for l in links {
            l.stop.cancel();
            super::emit_down(&events, l.id, "shutdown".to_string(), &cancel).await;
        }
    }))
}

/// What woke the ground task.
enum Wake {
    Liveliness(Sample),
    Expiry,
    Data(Sample),
}

async fn sleep_until_opt(t: Option<Instant>) {
    match t {
        Some(t) => tokio::time::sleep_until(t).await,
        None => std::future::pending().await,
    }
}

#[cfg(test)]
#[path = "ground_tests.rs"]
mod tests;
