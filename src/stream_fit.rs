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
//! A fitted link that has room again (a radio's rate limit lifted, its buffer mostly empty) gets
//! its rates back step by step: once it has been clear (loss under [`CLEAR_PCT`], the radio's
//! buffer at least [`RADIO_TXBUF_HIGH`] % free where one reports it) for [`RAISE_HOLD`], each
//! changed stream goes [`RAISE_STEP`] of the way from its fitted rate back to its rate before the
//! first fit, the last step asking for the vehicle's default (interval 0). Each step is watched
//! for [`SETTLE`]: loss of [`STEP_LOSS_PCT`] or a filling radio buffer takes it back at once, to
//! the rates before it. A step that failed doubles the hold before the next (up to
//! [`MAX_RAISE_HOLD`]) and leaves a ceiling: the frame bytes per second the streams were asked
//! for then; later steps go at most half way to it, and none is made within [`MIN_STEP`] of it,
//! until the ceiling is [`CEILING_MEMORY`] old. A step that worked is followed by the next after
//! [`STEP_HOLD`] (doubled the same way). So a link whose capacity sits between two rates costs
//! one failed step every few minutes, not a sawtooth.
//!
//! The fit follows the daemon client's vehicle (the first one heard).

use std::collections::BTreeMap;
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
/// A radio's `txbuf` at or above which its buffer counts as empty enough to send more.
pub const RADIO_TXBUF_HIGH: u8 = 90;
/// How long a fitted link must be clear before its rates are first stepped back up.
pub const RAISE_HOLD: Duration = Duration::from_secs(15);
/// How long the link must be clear after a step that worked before the next one.
pub const STEP_HOLD: Duration = Duration::from_secs(5);
/// The longest hold before a step, however many failed.
pub const MAX_RAISE_HOLD: Duration = Duration::from_secs(160);
/// Share of the way from the fitted rates to the rates before the fit that one step goes.
pub const RAISE_STEP: f64 = 0.25;
/// A step shorter than this share of the way is not asked for.
pub const MIN_STEP: f64 = 0.05;
/// Loss over the last 2 s that takes a step back.
pub const STEP_LOSS_PCT: f64 = 2.0;
/// How long the rate of a step that failed limits the steps after it.
pub const CEILING_MEMORY: Duration = Duration::from_secs(300);
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
    /// Rates fitted (or a step taken back, or up: `step`), being asked for (one command after
    /// another, each with its retries); the loss when they were fitted.
    Asking { loss_before: f64, step: bool },
    /// Rates fitted and asked for; judged at `until`. `unasked`: some of the requests never
    /// got their answer, so a loss that did not halve says nothing of the link.
    Settling {
        until: Instant,
        loss_before: f64,
        unasked: bool,
    },
    /// Rates fitted, the loss stopped: stepped back up while the link stays clear.
    Fitted,
    /// A step up asked for: taken back at the first congestion before `until`.
    Stepping { until: Instant },
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

/// One stream the fit changed: its rate before the first fit, the rate it was fitted to (Hz,
/// frames as received) and its frame size.
#[derive(Debug, Clone, Copy, PartialEq)]
struct Plan {
    default_hz: f64,
    fitted_hz: f64,
    bytes: f64,
}

impl Plan {
    /// The rate `way` of the way from the fitted rate back to the default.
    fn hz(&self, way: f64) -> f64 {
        self.fitted_hz + way * (self.default_hz - self.fitted_hz)
    }
}

/// The fit as a state machine: a tracker snapshot in, stream intervals out.
#[derive(Debug)]
pub struct Fitter {
    phase: Phase,
    /// The streams whose interval the fit changed, by message id.
    plans: BTreeMap<u32, Plan>,
    report: Option<LinkFit>,
    /// Share of the way from the fitted rates back to the defaults the streams run at (1: the
    /// defaults asked for).
    way: f64,
    /// The way before the last step up: where a step that fails goes back to.
    stable_way: f64,
    /// Since when the link has been clear, if it is.
    clear_since: Option<Instant>,
    /// When the last change was asked for or judged: holds count from here.
    hold_from: Option<Instant>,
    /// Whether the last step up worked (the next comes after [`STEP_HOLD`]).
    stepped: bool,
    /// Steps up that failed since the streams last ran at their defaults for a while.
    failures: u32,
    /// Frame bytes per second of the changed streams at the last step that failed, and when.
    ceiling: Option<(f64, Instant)>,
    /// A request of the round being asked went unanswered.
    unasked: bool,
}

impl Default for Fitter {
    fn default() -> Self {
        Self {
            phase: Phase::Watching,
            plans: BTreeMap::new(),
            report: None,
            way: 0.0,
            stable_way: 0.0,
            clear_since: None,
            hold_from: None,
            stepped: false,
            failures: 0,
            ceiling: None,
            unasked: false,
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
            self.clear_since = None;
            return Vec::new();
        }
        let loss = h.window.recent_loss_pct(now);
        let delivered = h.bytes_per_s(now);
        let radio_full = txbuf.is_some_and(|t| t < RADIO_TXBUF_LOW);
        let full = loss >= CONGESTED_PCT || radio_full;
        // Past a step up, less loss is enough to take it back.
        let step_full = loss >= STEP_LOSS_PCT || radio_full;
        let clear = loss < CLEAR_PCT && txbuf.is_none_or(|t| t >= RADIO_TXBUF_HIGH);
        self.clear_since = clear.then(|| self.clear_since.unwrap_or(now));
        match self.phase {
            // A step up that looked fine fills the link after all: take it back.
            Phase::Fitted if step_full && self.way > 0.0 => self.back_off(loss, delivered, now),
            Phase::Watching | Phase::Fitted if full => {
                self.fit_now(state, vehicle, loss, delivered, now)
            }
            Phase::Settling {
                until,
                loss_before,
                unasked,
            } if now >= until => self.judge_fit(
                state,
                vehicle,
                (loss, loss_before, unasked),
                delivered,
                radio_full,
                now,
            ),
            Phase::Stepping { .. } if step_full => self.back_off(loss, delivered, now),
            Phase::Stepping { until } if now >= until => {
                self.stepped = true;
                self.enter_fitted(now);
                Vec::new()
            }
            Phase::Fitted => self.step_up(now),
            Phase::RandomLoss { until } if now >= until => {
                self.phase = Phase::Watching;
                Vec::new()
            }
            _ => Vec::new(),
        }
    }

    /// A fit (or a step taken back) asked for [`SETTLE`] ago, at `loss` now and `loss_before`
    /// when it was made: kept, made again from the rates flowing, or given up.
    fn judge_fit(
        &mut self,
        state: &VehicleState,
        vehicle: (SystemId, ComponentId),
        (loss, loss_before, unasked): (f64, f64, bool),
        delivered: f64,
        radio_full: bool,
        now: Instant,
    ) -> Vec<(u32, Change)> {
        if loss < CLEAR_PCT && !radio_full {
            self.enter_fitted(now);
            return Vec::new();
        }
        // Still full, but the fit helped (or the radio says its buffer is full): the first
        // estimate of what the link carries was high. Fit again from here. So too when some
        // of the fit's requests were lost on the full link: it was not all tried.
        if radio_full || unasked || loss < loss_before / 2.0 {
            return self.fit_now(state, vehicle, loss, delivered, now);
        }
        self.phase = Phase::RandomLoss {
            until: now + RANDOM_LOSS_HOLD,
        };
        self.report_mut().capacity = None;
        self.report_mut().fitted = false;
        self.forget();
        std::mem::take(&mut self.plans)
            .into_keys()
            .map(|m| (m, Change::Default))
            .collect()
    }

    fn enter_fitted(&mut self, now: Instant) {
        self.phase = Phase::Fitted;
        self.hold_from = Some(now);
    }

    /// Forgets the steps: the streams run at their defaults, or are fitted afresh.
    fn forget(&mut self) {
        self.way = 0.0;
        self.stable_way = 0.0;
        self.stepped = false;
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
        // The changed streams' present rates are the base the steps up start from again.
        let way = self.way;
        for p in self.plans.values_mut() {
            p.fitted_hz = p.hz(way);
        }
        self.forget();
        for (msgid, change) in &out {
            let (Some(s), Change::Scale { ratio, .. }) =
                (streams.iter().find(|s| s.msgid == *msgid), change)
            else {
                continue;
            };
            let plan = self.plans.entry(*msgid).or_insert(Plan {
                default_hz: s.hz,
                fitted_hz: s.hz,
                bytes: s.bytes,
            });
            plan.fitted_hz = s.hz * ratio;
            plan.bytes = s.bytes;
        }
        self.report_mut().capacity = Some(delivered);
        self.phase = Phase::Asking {
            loss_before: loss,
            step: false,
        };
        out
    }

    /// Frame bytes per second of the changed streams at `way`.
    fn offered(&self, way: f64) -> f64 {
        self.plans.values().map(|p| p.hz(way) * p.bytes).sum()
    }

    /// How long the link must be clear before the next step up.
    fn hold(&self) -> Duration {
        let base = if self.stepped { STEP_HOLD } else { RAISE_HOLD };
        (base * 2u32.pow(self.failures.min(6))).min(MAX_RAISE_HOLD)
    }

    /// The next step up, once the link has been clear long enough; nothing while it is not,
    /// at the defaults, or too close below the ceiling of a step that failed.
    fn step_up(&mut self, now: Instant) -> Vec<(u32, Change)> {
        let Some(since) = self.clear_since else {
            return Vec::new();
        };
        let clear_from = self.hold_from.map_or(since, |h| h.max(since));
        if self.way >= 1.0 {
            // Back at the defaults and clear for long: the link has room; start afresh.
            if now >= clear_from + MAX_RAISE_HOLD {
                *self = Self {
                    report: self.report,
                    ..Self::default()
                };
                self.report_mut().capacity = None;
            }
            return Vec::new();
        }
        if now < clear_from + self.hold() {
            return Vec::new();
        }
        if self
            .ceiling
            .is_some_and(|(_, at)| now >= at + CEILING_MEMORY)
        {
            self.ceiling = None;
        }
        let mut to = (self.way + RAISE_STEP).min(1.0);
        if let Some((ceiling, _)) = self.ceiling {
            let (low, high) = (self.offered(0.0), self.offered(1.0));
            let half_way = (self.offered(self.way) + ceiling) / 2.0;
            if high > low && self.offered(to) > half_way {
                to = (half_way - low) / (high - low);
            }
        }
        if to - self.way < MIN_STEP {
            return Vec::new();
        }
        self.stable_way = self.way;
        self.phase = Phase::Asking {
            loss_before: 0.0,
            step: true,
        };
        self.move_to(to)
    }

    /// A step up filled the link (`loss` %, `delivered` bytes/s carried): back to the rates
    /// before it, its rate remembered as a ceiling, the next hold doubled.
    fn back_off(&mut self, loss: f64, delivered: f64, now: Instant) -> Vec<(u32, Change)> {
        self.failures += 1;
        self.stepped = false;
        self.ceiling = Some((self.offered(self.way), now));
        self.report_mut().capacity = Some(delivered);
        self.phase = Phase::Asking {
            loss_before: loss,
            step: false,
        };
        self.move_to(self.stable_way)
    }

    /// The changes that take every changed stream from the present way to `to` (the vehicle's
    /// default at 1).
    fn move_to(&mut self, to: f64) -> Vec<(u32, Change)> {
        let from = self.way;
        self.way = to;
        self.plans
            .iter()
            .map(|(&msgid, p)| {
                if to >= 1.0 {
                    return (msgid, Change::Default);
                }
                let hz = p.hz(to);
                let change = Change::Scale {
                    ratio: hz / p.hz(from),
                    fallback_us: (1e6 / hz) as f32,
                };
                (msgid, change)
            })
            .collect()
    }

    /// A request of the last [`Fitter::tick`]'s went unanswered (given up on the full link).
    pub fn unanswered(&mut self) {
        self.unasked = true;
    }

    /// The intervals the last [`Fitter::tick`] returned have all been asked for (or given up):
    /// their effect is judged [`SETTLE`] from `now`.
    pub fn asked(&mut self, now: Instant) {
        if let Phase::Asking { loss_before, step } = self.phase {
            self.phase = if step {
                Phase::Stepping {
                    until: now + SETTLE,
                }
            } else {
                Phase::Settling {
                    until: now + SETTLE,
                    loss_before,
                    unasked: std::mem::take(&mut self.unasked),
                }
            };
            self.hold_from = Some(now);
            let fitted = self.way < 1.0;
            if let Some(r) = self.report.as_mut() {
                r.fitted = fitted;
                if !fitted {
                    r.capacity = None;
                }
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
    state: watch::Receiver<std::sync::Arc<VehicleState>>,
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
                fitter.unanswered();
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
    // The frames seen stand in for an interval the vehicle does not tell only to slow a
    // stream: a message sent as several frames would be raised past its rate.
    if matches!(change, Change::Scale { ratio, .. } if ratio > 1.0)
        && present.is_none_or(|us| us <= 0)
    {
        tracing::debug!("stream rate of message {msgid}: interval unknown, not raised");
        return Ok(());
    }
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
#[path = "stream_fit_tests.rs"]
pub(crate) mod tests;
