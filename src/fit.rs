//! Fits the vehicle's telemetry streams to what its link carries.
//!
//! A telemetry radio (57 600 baud is about 5.7 kB/s of frames) carries less than a vehicle's
//! default streams: its queue overflows and frames are lost at random among all messages. The
//! daemon watches its vehicle link (the tracker's figures, every second) and, when the loss over
//! the last 2 s reaches [`CONGESTED_PCT`] (or a radio on the link reports its transmit buffer
//! below [`RADIO_TXBUF_LOW`] % free in RADIO_STATUS, as SiK radios do), takes what the link
//! delivered over those 2 s as its capacity and asks the vehicle (SET_MESSAGE_INTERVAL, through
//! the daemon's own client) for stream rates that use [`HEADROOM`] of it: every stream of 1 Hz
//! or more scaled by one factor, none below [`MIN_HZ`]; the heartbeat and the answers to
//! requests (parameters, missions, commands, text) are left alone. Each stream's new interval
//! is its present one (GET_MESSAGE_INTERVAL) stretched by the factor: a message id may carry
//! several frames a send (the twin's four NAMED_VALUE_FLOATs), so frames per second are not
//! sends per second. A vehicle that does not tell its interval gets one from the frames seen.
//!
//! Loss that is not congestion (a lossy link with room to spare) does not stop when the rates
//! fall: if the loss is still there [`SETTLE`] after the fit, not halved, and no radio says its
//! buffer is full, the streams go back to the vehicle's defaults (interval 0) and the link is
//! left alone for [`RANDOM_LOSS_HOLD`]. If it halved, or the radio's buffer is still full, the
//! link carries less than the first estimate: the fit goes again from the rates then flowing.
//! If the loss stopped, the capacity stands, and a later loss fits again the same way.
//!
//! The fit follows the daemon client's vehicle (the first one heard).

use std::collections::BTreeSet;
use std::time::{Duration, Instant};

use mavlink::MessageData;
use tokio::sync::watch;
use tokio_util::sync::CancellationToken;
use vtol_link::dialect::{self as apm, MavCmd, MavMessage};
use vtol_link::protocol::id;
use vtol_link::{ComponentId, LinkId, SystemId};

use crate::client::ClientHandle;
use crate::tracker::VehicleState;

/// Loss over the last 2 s that counts as the link being full.
pub const CONGESTED_PCT: f64 = 5.0;
/// Loss over the last 2 s below which a fit worked.
pub const CLEAR_PCT: f64 = 1.0;
/// Share of the measured capacity the fitted streams use.
pub const HEADROOM: f64 = 0.75;
/// The slowest rate a fitted stream gets.
pub const MIN_HZ: f64 = 0.5;
/// How long after a fit its effect is judged (the loss is taken over the last 2 s).
pub const SETTLE: Duration = Duration::from_secs(3);
/// A link whose loss did not stop with the rates is left alone this long.
pub const RANDOM_LOSS_HOLD: Duration = Duration::from_secs(30);
/// A radio's RADIO_STATUS `txbuf` (percent of its transmit buffer free) below which the link
/// counts as full.
pub const RADIO_TXBUF_LOW: u8 = 50;
/// A RADIO_STATUS older than this says nothing about the link now.
const RADIO_STATUS_FRESH: Duration = Duration::from_secs(3);
/// How often the fit looks at the link.
pub const FIT_PERIOD: Duration = Duration::from_secs(1);
/// Frames a link must have carried before its loss means anything.
const MIN_FRAMES: u64 = 50;

/// Messages that are answers or events, not streams: never re-rated.
const NOT_STREAMS: [u32; 15] = [
    id::HEARTBEAT,
    id::PARAM_VALUE,
    id::STATUSTEXT,
    id::COMMAND_ACK,
    id::RADIO_STATUS,
    id::MISSION_ITEM,
    id::MISSION_ITEM_INT,
    id::MISSION_CURRENT,
    id::AUTOPILOT_VERSION,
    id::HOME_POSITION,
    <apm::TIMESYNC_DATA as MessageData>::ID,
    <apm::MISSION_COUNT_DATA as MessageData>::ID,
    <apm::MISSION_REQUEST_INT_DATA as MessageData>::ID,
    <apm::MISSION_ACK_DATA as MessageData>::ID,
    <apm::FILE_TRANSFER_PROTOCOL_DATA as MessageData>::ID,
];

/// What the fit knows of the vehicle link, for the status line.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LinkFit {
    /// The vehicle link.
    pub link: LinkId,
    /// Frame bytes per second the link carried when it was full, once measured.
    pub capacity: Option<f64>,
    /// Whether the streams run at fitted rates now (asked for).
    pub fitted: bool,
    /// The last fresh RADIO_STATUS `txbuf` (percent free), if the link reports one.
    pub radio_txbuf: Option<u8>,
}

#[derive(Debug, Clone, Copy, PartialEq)]
enum Phase {
    /// Default rates, watching for loss.
    Watching,
    /// Rates fitted, being asked for (one command after another, each with its retries); the
    /// loss when they were fitted.
    Asking { loss_before: f64 },
    /// Rates fitted and asked for; judged at `until`.
    Settling { until: Instant, loss_before: f64 },
    /// Rates fitted, the loss stopped.
    Fitted,
    /// The loss did not stop with the rates: defaults again, left alone until `until`.
    RandomLoss { until: Instant },
}

/// What to ask of one stream.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Change {
    /// Send it `ratio` times as often (below 1: slower): its present interval divided by
    /// `ratio`, or `fallback_us` if the vehicle does not tell its interval.
    Scale {
        /// New rate over the present one.
        ratio: f64,
        /// The interval from the frames seen, in µs.
        fallback_us: f32,
    },
    /// Back to the vehicle's default (interval 0).
    Default,
}

impl Change {
    /// The interval to ask for, given the present one as the vehicle reports it (µs; 0 or
    /// less when not sent, unknown or disabled).
    #[must_use]
    pub fn interval_us(&self, present: Option<i32>) -> f32 {
        match *self {
            Self::Default => 0.0,
            Self::Scale { ratio, fallback_us } => match present {
                Some(us) if us > 0 => ((f64::from(us) / ratio).min(1e6 / MIN_HZ)) as f32,
                _ => fallback_us,
            },
        }
    }
}

/// The fit as a state machine: a tracker snapshot in, stream intervals out.
#[derive(Debug)]
pub struct Fitter {
    phase: Phase,
    /// Message ids whose interval the fit changed.
    changed: BTreeSet<u32>,
    report: Option<LinkFit>,
}

impl Default for Fitter {
    fn default() -> Self {
        Self {
            phase: Phase::Watching,
            changed: BTreeSet::new(),
            report: None,
        }
    }
}

/// One stream: its message id, the rate the vehicle sends it at (Hz) and its frame size.
#[derive(Debug, Clone, Copy)]
struct Stream {
    msgid: u32,
    hz: f64,
    bytes: f64,
}

impl Fitter {
    /// What the fit knows of the link, once a vehicle is heard.
    #[must_use]
    pub fn report(&self) -> Option<LinkFit> {
        self.report
    }

    /// Looks at `state` for `vehicle`; returns what to ask of which message ids.
    pub fn tick(
        &mut self,
        state: &VehicleState,
        vehicle: (SystemId, ComponentId),
        now: Instant,
    ) -> Vec<(u32, Change)> {
        let Some(v) = state.vehicles.get(&vehicle) else {
            return Vec::new();
        };
        let Some(h) = state.links.get(&v.link) else {
            return Vec::new();
        };
        let txbuf = radio_txbuf(state, now);
        let report = self.report.get_or_insert(LinkFit {
            link: v.link,
            capacity: None,
            fitted: false,
            radio_txbuf: None,
        });
        report.link = v.link;
        report.radio_txbuf = txbuf;
        if v.is_lost(now) || h.frames < MIN_FRAMES {
            return Vec::new();
        }
        let loss = h.window.recent_loss_pct(now);
        let delivered = h.bytes_per_s(now);
        let full = loss >= CONGESTED_PCT || txbuf.is_some_and(|t| t < RADIO_TXBUF_LOW);
        let radio_full = txbuf.is_some_and(|t| t < RADIO_TXBUF_LOW);
        match self.phase {
            Phase::Watching | Phase::Fitted if full => {
                self.fit_now(state, vehicle, loss, delivered, now)
            }
            Phase::Settling { until, loss_before } if now >= until => {
                if loss < CLEAR_PCT && !radio_full {
                    self.phase = Phase::Fitted;
                    return Vec::new();
                }
                // Still full, but the fit helped (or the radio says its buffer is full): the
                // first estimate of what the link carries was high. Fit again from here.
                if radio_full || loss < loss_before / 2.0 {
                    return self.fit_now(state, vehicle, loss, delivered, now);
                }
                self.phase = Phase::RandomLoss {
                    until: now + RANDOM_LOSS_HOLD,
                };
                self.report_mut().capacity = None;
                self.report_mut().fitted = false;
                std::mem::take(&mut self.changed)
                    .into_iter()
                    .map(|m| (m, Change::Default))
                    .collect()
            }
            Phase::RandomLoss { until } if now >= until => {
                self.phase = Phase::Watching;
                Vec::new()
            }
            _ => Vec::new(),
        }
    }

    /// Fits the streams to `delivered` bytes/s, seen at `loss` %.
    fn fit_now(
        &mut self,
        state: &VehicleState,
        vehicle: (SystemId, ComponentId),
        loss: f64,
        delivered: f64,
        now: Instant,
    ) -> Vec<(u32, Change)> {
        let streams = streams(state, vehicle, loss, now);
        let offered = delivered / (1.0 - loss / 100.0).max(0.05);
        let out = fit(&streams, offered, delivered * HEADROOM);
        if out.is_empty() {
            // Nothing to scale down: the loss is not the streams' doing.
            self.phase = Phase::RandomLoss {
                until: now + RANDOM_LOSS_HOLD,
            };
            return Vec::new();
        }
        self.changed.extend(out.iter().map(|(m, _)| *m));
        self.report_mut().capacity = Some(delivered);
        self.phase = Phase::Asking { loss_before: loss };
        out
    }

    /// The intervals the last [`Fitter::tick`] returned have all been asked for (or given up):
    /// their effect is judged [`SETTLE`] from `now`.
    pub fn asked(&mut self, now: Instant) {
        if let Phase::Asking { loss_before } = self.phase {
            self.phase = Phase::Settling {
                until: now + SETTLE,
                loss_before,
            };
            if let Some(r) = self.report.as_mut() {
                r.fitted = true;
            }
        }
    }

    fn report_mut(&mut self) -> &mut LinkFit {
        self.report.as_mut().expect("set by tick first")
    }
}

/// The last fresh RADIO_STATUS `txbuf` heard, if any.
fn radio_txbuf(state: &VehicleState, now: Instant) -> Option<u8> {
    state
        .messages
        .iter()
        .filter(|((_, _, m), s)| {
            *m == id::RADIO_STATUS && now.duration_since(s.last_at) < RADIO_STATUS_FRESH
        })
        .max_by_key(|(_, s)| s.last_at)
        .and_then(|(_, s)| match s.last.decode() {
            Ok(MavMessage::RADIO_STATUS(r)) => Some(r.txbuf),
            _ => None,
        })
}

/// The vehicle's messages as the vehicle sends them: the rate received over the last 2 s
/// raised by the link's loss.
fn streams(
    state: &VehicleState,
    (sys, comp): (SystemId, ComponentId),
    loss_pct: f64,
    now: Instant,
) -> Vec<Stream> {
    let kept = (1.0 - loss_pct / 100.0).max(0.05);
    state
        .messages
        .range((sys, comp, 0)..=(sys, comp, u32::MAX))
        .map(|(&(_, _, msgid), s)| Stream {
            msgid,
            hz: s.window.rate_hz(now) / kept,
            bytes: s.last.as_bytes().len() as f64,
        })
        .collect()
}

/// Intervals for the streams of 1 Hz or more so that everything fits in `budget` bytes/s, of
/// `offered` now, the biggest streams first (they relieve the link soonest); empty when it
/// fits already or nothing can be scaled.
fn fit(streams: &[Stream], offered: f64, budget: f64) -> Vec<(u32, Change)> {
    let scalable = |s: &&Stream| s.hz >= 1.0 && !NOT_STREAMS.contains(&s.msgid);
    let scaled: f64 = streams
        .iter()
        .filter(scalable)
        .map(|s| s.hz * s.bytes)
        .sum();
    if scaled <= 0.0 || offered <= budget {
        return Vec::new();
    }
    let fixed = (offered - scaled).max(0.0);
    let factor = ((budget - fixed) / scaled).clamp(0.0, 1.0);
    let mut big_first: Vec<&Stream> = streams.iter().filter(scalable).collect();
    big_first.sort_by(|a, b| (b.hz * b.bytes).total_cmp(&(a.hz * a.bytes)));
    big_first
        .into_iter()
        .map(|s| {
            let hz = (s.hz * factor).max(MIN_HZ);
            let change = Change::Scale {
                ratio: hz / s.hz,
                fallback_us: (1e6 / hz) as f32,
            };
            (s.msgid, change)
        })
        .collect()
}

/// Runs the fit for the daemon client's vehicle until `cancel` fires, asking for each interval
/// through `client` and publishing what it knows of the link on `report`.
pub async fn run(
    state: watch::Receiver<VehicleState>,
    client: ClientHandle,
    report: watch::Sender<Option<LinkFit>>,
    cancel: CancellationToken,
) {
    let mut fitter = Fitter::default();
    let mut tick = tokio::time::interval(FIT_PERIOD);
    tick.set_missed_tick_behavior(tokio::time::MissedTickBehavior::Delay);
    loop {
        tokio::select! {
            () = cancel.cancelled() => return,
            _ = tick.tick() => {}
        }
        let Some(vehicle) = client.target() else {
            continue;
        };
        let now = crate::tracker::now();
        let intervals = fitter.tick(&state.borrow(), vehicle, now);
        report.send_if_modified(|r| {
            let changed = *r != fitter.report();
            *r = fitter.report();
            changed
        });
        for (msgid, change) in intervals {
            let outcome = tokio::select! {
                () = cancel.cancelled() => return,
                r = ask(&client, msgid, change) => r,
            };
            if let Err(e) = outcome {
                tracing::warn!("stream rate of message {msgid}: {e}");
            }
        }
        fitter.asked(crate::tracker::now());
    }
}

/// Asks the vehicle for `change` of `msgid`'s interval (reading the present one first when it
/// is scaled).
async fn ask(
    client: &ClientHandle,
    msgid: u32,
    change: Change,
) -> Result<(), crate::client::ClientError> {
    let present = match change {
        Change::Scale { .. } => client.message_interval(msgid).await?,
        Change::Default => None,
    };
    let params = [
        msgid as f32,
        change.interval_us(present),
        0.0,
        0.0,
        0.0,
        0.0,
        0.0,
    ];
    let outcome = client
        .command_long(MavCmd::MAV_CMD_SET_MESSAGE_INTERVAL, params)
        .await?;
    if !outcome.accepted() {
        tracing::warn!("stream rate of message {msgid}: {:?}", outcome.result);
    }
    Ok(())
}

#[cfg(test)]
#[path = "fit_tests.rs"]
mod tests;
