//! The whole-table download, built for a lossy link with a long round trip.
//!
//! PARAM_REQUEST_LIST goes out twice (its loss would cost a whole timeout, a copy costs a few
//! dozen bytes; a vehicle restarts its stream on each, so the copies arriving together cost
//! nothing more). The vehicle streams the table in index order, so an index arriving past a
//! missing one shows a hole: it is asked for by PARAM_REQUEST_READ(index) while the rest of the
//! stream still comes, once it has stayed missing for a reorder allowance (a quarter of a round
//! trip: a link with jitter delivers a burst out of order, and each false hole would cost its
//! copies); the indices after the last one heard are asked for once the stream has been quiet
//! for as long. At most [`PULL_WINDOW`] indices are outstanding ([`CLEAN_WINDOW`] while the
//! stream has lost nothing); each answer lets the next request go.
//!
//! Once the link has shown loss (holes in the stream, or requests unanswered), each request
//! goes out in several copies: one exchange fails with probability `f = 1 - (1 - p)²` at a loss
//! `p` each way, `k` independent copies with `f^k`, so the copies are chosen to leave about
//! [`HOLES_LEFT`] of the holes asked for unanswered after one round. On a clean link `k` is 1;
//! on a fast one the copies of a round stay within [`CLEAN_WINDOW`] (the vehicle's read queue).
//! A request unanswered for its timeout (1.25 × the round trip, or the slowest recent answer
//! to a request if that is longer; doubling after a few tries) is asked again.
//!
//! The vehicle's own pacing is waited out on every link (ArduPilot's stream pauses about 100 ms
//! every couple of hundred values): while it has lost nothing a stream counts as over only
//! after [`FAST_PAUSE`] of quiet (or four times its longest gap), and reads leave paced, at
//! most [`CLEAN_WINDOW`] at once and then one a [`READ_SERVICE`] (ArduPilot queues 20 for every
//! link together, takes about one a millisecond, and drops what finds its queue full). A
//! stream that ends with more than [`RELIST_MISSING`] values missing is asked for again whole
//! (in one copy more once values were lost), after [`FAST_PAUSE`] of quiet, or at once if the
//! pass reached the table's last indices: on a lossy link with a long round trip a pass of the
//! stream brings most of the rest far sooner than a window of reads a round trip. Once values
//! were lost, a pass counts as over only by the same rule, and the holes the first pass showed
//! are not read while a later one runs: ArduPilot answers reads first, out of the stream's
//! share of its link, so reads sent during a pass stop it.
//!
//! Echoes with index 65535 (a by-name answer or another client's write) update values by name.

use std::collections::{BTreeMap, HashMap, HashSet, VecDeque};
use std::time::{Duration, Instant};

use vtol_link::dialect::{self as apm, MavMessage};
use vtol_link::{ComponentId, SystemId};

use super::name_of;
use crate::client::machine::{Inbound, Machine, Rtt, retry_wait};
use crate::params::{Param, ParamSet};

/// Indices re-requested at once during a download: about the holes of a 100-value table at
/// 30 % loss, in one round.
pub const PULL_WINDOW: usize = 32;
/// Consecutive timeouts without any new value before a download gives up…
pub const PULL_STALLS: u32 = 12;
/// …and at least this long without one: a busy machine can pause a fast link for longer than
/// twelve short timeouts.
pub const PULL_GIVE_UP: Duration = Duration::from_secs(3);
/// Copies of PARAM_REQUEST_LIST.
pub const LIST_COPIES: usize = 2;
/// The most copies of one PARAM_REQUEST_READ.
pub const MAX_COPIES: u32 = 8;
/// Holes expected to be left unanswered after one round of requests: what the copies aim at.
pub const HOLES_LEFT: f64 = 0.2;
/// A request's timeout as a multiple of the smoothed round trip (before the answers' spread is
/// known): the round trip is measured before the download, and the requests' own round trips
/// then set it.
const HOLE_RTO_FACTOR: f64 = 1.25;
/// The list request's first answer also waits for the vehicle to start its stream.
const LIST_RTO_FACTOR: f64 = 1.5;
/// The least wait for the stream's first value before the list request goes again: every
/// list request restarts the stream (ArduPilot sends its banner first), so on a fast link a
/// vehicle a little slow to start would be asked over and over.
const LIST_MIN_WAIT: Duration = Duration::from_millis(100);
/// The stream counts as over after this share of a round trip without a value, and a hole is
/// asked for once it has been missing for as long (the reorder allowance)…
const QUIET_SHARE: f64 = 0.25;
/// …and at least this long: a vehicle paces its stream over a few ticks, and its main loop
/// (or the machine running it) pauses now and then.
const MIN_QUIET: Duration = Duration::from_millis(50);
/// Values added to those heard when the stream's holes give the loss.
const LOSS_PRIOR: f64 = 4.0;
/// Recent request round trips kept for the timeout.
const RECENT: usize = 16;
/// Indices asked for at once, one copy each, while the download has seen no loss. ArduPilot
/// queues 20 PARAM_REQUEST_READs, shared by all its links, and drops what finds the queue
/// full; a round of requests arrives at once on a fast link, so the window stays under that
/// queue (a larger one, or copies, would be dropped, taken for loss and asked again in more
/// copies: a flood that starves the stream).
pub const CLEAN_WINDOW: usize = 16;
/// A link whose round trip (as measured before the download) is under this is fast: the
/// vehicle's own pace is what counts, not the link's.
const FAST_LINK: Duration = Duration::from_millis(20);
/// On a fast link, a stream that has lost nothing counts as over only after this long quiet.
const FAST_PAUSE: Duration = Duration::from_millis(300);
/// While the stream has shown no loss, it counts as over only after this many times its
/// longest gap so far: a vehicle's main loop (ArduPilot's, a few values every 2.5 ms) now and
/// then pauses for longer.
const GAP_FACTOR: u32 = 4;
/// The longest pause of the vehicle's own pacing waited out as such.
const MAX_PACING_PAUSE: Duration = Duration::from_secs(1);
/// How long a vehicle takes to answer one queued read (ArduPilot's IO thread: one a
/// millisecond).
const READ_SERVICE: Duration = Duration::from_millis(1);
/// A stream that stops with more than this many values missing is asked for again
/// (PARAM_REQUEST_LIST) rather than read index by index…
const RELIST_MISSING: usize = 2 * CLEAN_WINDOW;
/// …at most this often.
const RELIST_EVERY: Duration = Duration::from_secs(1);
/// A pass of the stream that delivered one of the table's last this many indices reached its
/// end (at 30 % loss, the last four are all lost one pass in a hundred).
const TAIL_SLACK: usize = 4;
/// Restarts for a table that changed size during the download (an `*_ENABLE` written).
const MAX_RESTARTS: u8 = 3;

/// Why a download did not complete.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct PullStalled {
    /// Values received.
    pub received: usize,
    /// Values announced (0 if no value ever came).
    pub total: usize,
}

/// One index asked for.
#[derive(Debug, Clone, Copy)]
struct Ask {
    due: Instant,
    sent: Instant,
    tries: u8,
    copies: u32,
}

/// The whole-table download.
#[derive(Debug)]
pub struct PullMachine {
    target: (SystemId, ComponentId),
    /// The client's estimate, refined by this download's own samples.
    rtt: Rtt,
    rto: Duration,
    count: Option<u16>,
    values: BTreeMap<u16, (String, Param)>,
    by_name: HashMap<String, u16>,
    outstanding: BTreeMap<u16, Ask>,
    /// Indices asked at least once.
    asked: HashSet<u16>,
    /// The highest index the list stream delivered; `stream_over` once it has been quiet.
    highest: Option<u16>,
    /// The last index the present pass of the stream delivered, held already or not: a pass
    /// that reached the table's last indices is over once quiet, without waiting out a pause.
    pass_last: Option<u16>,
    stream_over: bool,
    /// Holes the stream showed and not yet asked for, with when.
    shown: BTreeMap<u16, Instant>,
    /// Holes the stream showed: the loss one way.
    holes_seen: u32,
    /// Requests answered and timed out, and their copies in all: the loss of an exchange.
    answered: u32,
    timed_out: u32,
    copies_resolved: u32,
    /// Round trips of requests answered (newest last).
    recent: VecDeque<Duration>,
    samples: Vec<Duration>,
    started: Instant,
    last_rx: Instant,
    list_due: Instant,
    /// The next check for a stall (a timeout without any value).
    check: Instant,
    stalls: u32,
    list_sends: u8,
    /// Whether the link is fast ([`FAST_LINK`]), from the round trip known at the start: the
    /// answers' own round trips grow with a busy vehicle's queue, not the link.
    fast: bool,
    /// The last value of the list stream and the longest gap between two so far.
    last_streamed: Option<Instant>,
    gap_max: Duration,
    restarts: u8,
    /// When the stream may be asked for again ([`RELIST_MISSING`]).
    relist_due: Instant,
    /// Sizes the table had before it changed: values announcing them are from before.
    stale_counts: Vec<u16>,
    /// PARAM_REQUEST_READs sent, copies included (for the benchmark's report).
    pub rerequests: usize,
    done: Option<Result<ParamSet, PullStalled>>,
    /// Reads waiting for their turn: they leave at most one a [`READ_SERVICE`] after a burst of
    /// [`CLEAN_WINDOW`], the pace ArduPilot takes them from its 20-deep queue.
    paced: VecDeque<MavMessage>,
    /// The time credit of the reads that may leave ([`READ_SERVICE`] each, at most
    /// [`CLEAN_WINDOW`] of them), and when it was counted.
    credit: Duration,
    credit_at: Instant,
}

impl PullMachine {
    /// A download from `target`, starting from the client's round-trip estimate.
    #[must_use]
    pub fn new(target: (SystemId, ComponentId), rtt: Rtt) -> Self {
        let now = Instant::now();
        Self {
            target,
            rtt,
            rto: rtt.rto(),
            count: None,
            values: BTreeMap::new(),
            by_name: HashMap::new(),
            outstanding: BTreeMap::new(),
            asked: HashSet::new(),
            highest: None,
            stream_over: false,
            shown: BTreeMap::new(),
            holes_seen: 0,
            answered: 0,
            timed_out: 0,
            copies_resolved: 0,
            recent: VecDeque::new(),
            samples: Vec::new(),
            started: now,
            last_rx: now,
            list_due: now,
            check: now,
            stalls: 0,
            list_sends: 0,
            fast: rtt.srtt().is_some_and(|s| s < FAST_LINK),
            last_streamed: None,
            pass_last: None,
            gap_max: Duration::ZERO,
            restarts: 0,
            relist_due: now,
            stale_counts: Vec::new(),
            rerequests: 0,
            done: None,
            paced: VecDeque::new(),
            credit: READ_SERVICE * CLEAN_WINDOW as u32,
            credit_at: now,
        }
    }

    /// What the download did, for the debug log.
    #[must_use]
    pub fn summary(&self) -> String {
        format!(
            "{} reads, {} holes seen, {} timed out, {} lists, {} restarts, srtt {:?}, longest gap {:?}",
            self.rerequests,
            self.holes_seen,
            self.timed_out,
            self.list_sends,
            self.restarts,
            self.rtt.srtt(),
            self.gap_max
        )
    }

    /// (received, total) for a progress bar; total is 0 until the first value.
    #[must_use]
    pub fn progress(&self) -> (usize, usize) {
        (self.values.len(), self.count.map_or(0, usize::from))
    }

    /// The smoothed round trip, or the initial timeout before any is known.
    fn srtt(&self) -> Duration {
        self.rtt.srtt().unwrap_or(Rtt::INITIAL_RTO)
    }

    /// A request's timeout before backing off: 1.25 round trips, or longer if a recent answer
    /// took longer; never beyond the plain retransmission timeout.
    fn hole_rto(&self) -> Duration {
        let slowest = self
            .recent
            .iter()
            .max()
            .map_or(Duration::ZERO, |s| *s * 11 / 10);
        self.srtt()
            .mul_f64(HOLE_RTO_FACTOR)
            .max(slowest)
            .min(self.rto)
            .max(Rtt::MIN_RTO)
    }

    fn quiet(&self) -> Duration {
        let quiet = self.srtt().mul_f64(QUIET_SHARE).max(MIN_QUIET);
        if self.holes_seen == 0 {
            // Nothing lost: a pause is the vehicle's pacing (ArduPilot's stream stops for
            // about 100 ms every couple of hundred values), not its end.
            quiet
                .max((self.gap_max * GAP_FACTOR).min(MAX_PACING_PAUSE))
                .max(FAST_PAUSE)
        } else {
            // Values lost: a gap may be a loss as well as a pause. A pause taken for the end
            // costs little: the reads of the last indices start early, and the stream is asked
            // for again only after a vehicle's own pause of quiet (see `on_time`).
            quiet
        }
    }

    /// How long the stream must be quiet to count as over. Once it has lost values, a pass
    /// that has not reached the table's last indices is still running through a vehicle's own
    /// pause: reads sent then would take its place (ArduPilot answers them first, out of the
    /// same share of its link) and stop it.
    fn stream_end_quiet(&self) -> Duration {
        if self.holes_seen == 0 {
            self.quiet()
        } else {
            self.relist_quiet()
        }
    }

    /// How long the stream must be quiet before it is asked for again: a vehicle's own pause
    /// ([`FAST_PAUSE`]), unless the pass reached the table's last indices (within
    /// [`TAIL_SLACK`], as many as may all be lost at once), when it is simply over.
    fn relist_quiet(&self) -> Duration {
        let count = self.count.map_or(0, usize::from);
        match self.pass_last {
            Some(i) if usize::from(i) + TAIL_SLACK + 1 >= count => self.quiet().min(FAST_PAUSE),
            _ => FAST_PAUSE,
        }
    }

    /// How long a hole the stream showed waits before it is asked for, the stream still
    /// running: a link with jitter delivers a burst out of order (a reorder allowance, a quarter
    /// of a round trip), and on a fast link the vehicle's pacing is waited out first.
    fn hole_allowance(&self) -> Duration {
        if self.fast {
            self.quiet()
        } else {
            self.srtt().mul_f64(QUIET_SHARE).max(MIN_QUIET)
        }
    }

    /// Indices that may be outstanding at once (their copies leave paced, see `paced`).
    fn window(&self, _copies: u32) -> usize {
        if self.fast { CLEAN_WINDOW } else { PULL_WINDOW }
    }

    /// The reads whose turn has come ([`READ_SERVICE`] apart after a burst of
    /// [`CLEAN_WINDOW`]).
    fn flush(&mut self, now: Instant, mut out: Vec<MavMessage>) -> Vec<MavMessage> {
        let elapsed = now.saturating_duration_since(self.credit_at);
        self.credit = (self.credit + elapsed).min(READ_SERVICE * CLEAN_WINDOW as u32);
        self.credit_at = now;
        while self.credit >= READ_SERVICE
            && let Some(m) = self.paced.pop_front()
        {
            self.credit -= READ_SERVICE;
            out.push(m);
        }
        out
    }

    /// When the next paced read may leave, if one waits.
    fn pace_due(&self) -> Option<Instant> {
        (!self.paced.is_empty()).then(|| self.credit_at + READ_SERVICE.saturating_sub(self.credit))
    }

    /// The table changed size (an enable parameter written while the download ran): its
    /// indices moved, so the download starts again.
    fn restart(&mut self, now: Instant) -> Vec<MavMessage> {
        self.restarts += 1;
        if let Some(old) = self.count.take() {
            self.stale_counts.push(old);
        }
        self.values.clear();
        self.by_name.clear();
        self.outstanding.clear();
        self.asked.clear();
        self.shown.clear();
        self.highest = None;
        self.stream_over = false;
        self.last_streamed = None;
        self.pass_last = None;
        self.list_sends = 0;
        self.last_rx = now;
        self.list(now)
    }

    /// One exchange's chance of failing, from what the download has seen so far: the stream's
    /// holes give the loss one way (`p`, taken for both ways), and the requests that timed out
    /// give it as well: a request of `k` copies fails with `f^k`.
    fn exchange_loss(&self) -> f64 {
        let stream = match self.highest {
            Some(h) if self.holes_seen > 0 => {
                // A few values more than heard: one hole in the first two is no 50 % loss.
                let p = f64::from(self.holes_seen) / (f64::from(h) + 1.0 + LOSS_PRIOR);
                1.0 - (1.0 - p.min(1.0)).powi(2)
            }
            _ => 0.0,
        };
        let asks = self.answered + self.timed_out;
        let requests = if self.timed_out == 0 {
            0.0
        } else {
            let per_request = f64::from(self.timed_out) / f64::from(asks);
            per_request.powf(f64::from(asks) / f64::from(self.copies_resolved.max(1)))
        };
        stream.max(requests)
    }

    /// Copies for each request of a round of `holes`.
    fn copies(&self, holes: usize) -> u32 {
        let f = self.exchange_loss();
        if f <= 0.0 {
            return 1;
        }
        if f >= 1.0 {
            return MAX_COPIES;
        }
        let k = (HOLES_LEFT / holes.max(1) as f64).ln() / f.ln();
        let k = (k.ceil() as u32).clamp(1, MAX_COPIES);
        if self.fast {
            // On a fast link the copies of a round stay within the vehicle's read queue: a
            // request it drops from a full queue is no loss of the link's, and would be taken
            // for one. The last few holes of a lossy link still go in copies: one copy at a
            // time, a lone hole fails half its tries at 30 % loss each way.
            let room = u32::try_from(CLEAN_WINDOW / holes.max(1)).unwrap_or(1);
            return k.min(room.max(1));
        }
        k
    }

    fn list(&mut self, now: Instant) -> Vec<MavMessage> {
        self.list_sends = self.list_sends.saturating_add(1);
        // Never below the floor: on loopback the round trip is well under the vehicle's own
        // tick, which paces the start of its stream.
        let first_wait = self
            .srtt()
            .mul_f64(LIST_RTO_FACTOR)
            .min(self.rto)
            .max(LIST_MIN_WAIT);
        self.list_due = now + retry_wait(first_wait, self.list_sends);
        // Once the stream has lost values, one copy more: a pass asked for and lost costs a
        // second before the next is asked for.
        let copies = LIST_COPIES
            + usize::from(self.list_sends - 1).min(2)
            + usize::from(self.holes_seen > 0);
        let m = MavMessage::PARAM_REQUEST_LIST(apm::PARAM_REQUEST_LIST_DATA {
            target_system: self.target.0.0,
            target_component: self.target.1.0,
        });
        vec![m; copies]
    }

    /// PARAM_REQUEST_READ of each index in `indices`, in `copies` copies.
    fn read(&mut self, indices: &[u16], copies: u32, now: Instant) -> Vec<MavMessage> {
        // The vehicle answers queued reads one at a time: on a fast link the last of a round
        // waits for the others more than for the link (ArduPilot's IO thread takes one a
        // millisecond).
        let queued = if self.fast {
            self.outstanding.values().map(|a| a.copies).sum::<u32>()
                + copies * u32::try_from(indices.len()).unwrap_or(u32::MAX)
        } else {
            // The reads paced out before the last of these.
            u32::try_from(self.paced.len()).unwrap_or(u32::MAX)
                + copies * u32::try_from(indices.len()).unwrap_or(u32::MAX)
        };
        let rto = self.hole_rto() + READ_SERVICE * queued;
        let mut out = Vec::new();
        for &index in indices {
            self.asked.insert(index);
            self.shown.remove(&index);
            let tries = self
                .outstanding
                .get(&index)
                .map_or(1, |a| a.tries.saturating_add(1));
            // When its first copy leaves, after the reads paced out before it.
            let free = (self.credit.as_nanos() / READ_SERVICE.as_nanos()) as usize;
            let ahead = (self.paced.len() + out.len()).saturating_sub(free);
            let sent = now + READ_SERVICE * u32::try_from(ahead).unwrap_or(u32::MAX);
            let ask = Ask {
                due: now + retry_wait(rto, tries),
                sent,
                tries,
                copies,
            };
            self.outstanding.insert(index, ask);
            for _ in 0..copies {
                self.rerequests += 1;
                out.push(MavMessage::PARAM_REQUEST_READ(
                    apm::PARAM_REQUEST_READ_DATA {
                        param_index: index as i16,
                        target_system: self.target.0.0,
                        target_component: self.target.1.0,
                        param_id: "".into(),
                    },
                ));
            }
        }
        self.paced.extend(out);
        self.flush(now, Vec::new())
    }

    /// Asks for missing indices not already asked for, up to the window: the holes the stream
    /// showed a reorder allowance ago while it runs, every one once it is over.
    fn refill(&mut self, now: Instant) -> Vec<MavMessage> {
        let Some(count) = self.count else {
            return Vec::new();
        };
        let missing = usize::from(count) - self.values.len();
        if self.stream_over && missing > RELIST_MISSING {
            return Vec::new();
        }
        let copies = self.copies(missing);
        let room = self.window(copies).saturating_sub(self.outstanding.len());
        if room == 0 {
            return Vec::new();
        }
        let holes: Vec<u16> = if self.stream_over {
            (0..count)
                .filter(|i| !self.values.contains_key(i) && !self.outstanding.contains_key(i))
                .take(room)
                .collect()
        } else if self.shown.len() + self.outstanding.len() > RELIST_MISSING {
            // So many holes already that the stream will be asked for again when it ends.
            return Vec::new();
        } else {
            let allowance = self.hole_allowance();
            self.shown
                .iter()
                .filter(|(_, at)| now.duration_since(**at) >= allowance)
                .map(|(i, _)| *i)
                .take(room)
                .collect()
        };
        if holes.is_empty() {
            return Vec::new();
        }
        self.read(&holes, copies, now)
    }

    fn complete(&mut self) {
        if let Some(count) = self.count
            && self.values.len() >= usize::from(count)
        {
            let set = self.values.values().map(|(n, p)| (n.clone(), *p)).collect();
            self.done = Some(Ok(set));
        }
    }

    fn sample(&mut self, s: Duration) {
        self.samples.push(s);
        self.rtt.sample(s);
        self.rto = self.rtt.rto();
    }

    /// A value from the list stream (not an answer to a request): the indices it passed over
    /// are holes; one that fills a hole shown before was late, not lost.
    fn streamed(&mut self, index: u16, now: Instant) {
        if let Some(last) = self.last_streamed {
            self.gap_max = self.gap_max.max(now.duration_since(last));
        }
        self.last_streamed = Some(now);
        let from = self.highest.map_or(0, |h| h + 1);
        if index >= from {
            // The stream goes on after a pause that looked like its end.
            self.stream_over = false;
            self.holes_seen += u32::from(index - from);
            for i in from..index {
                self.shown.insert(i, now);
            }
            self.highest = Some(index);
        } else if self.shown.remove(&index).is_some() {
            self.holes_seen = self.holes_seen.saturating_sub(1);
        }
    }
}

impl Machine for PullMachine {
    type Output = Result<ParamSet, PullStalled>;

    fn start(&mut self, now: Instant) -> Vec<MavMessage> {
        self.last_rx = now;
        self.started = now;
        self.check = now + self.rto;
        self.list(now)
    }

    fn on_message(&mut self, now: Instant, m: &Inbound) -> Vec<MavMessage> {
        if self.done.is_some() || (m.sys, m.comp) != self.target {
            return Vec::new();
        }
        let MavMessage::PARAM_VALUE(v) = &m.msg else {
            return Vec::new();
        };
        let name = name_of(&v.param_id);
        let param = Param {
            value: v.param_value,
            ty: v.param_type,
        };
        if self.stale_counts.contains(&v.param_count) {
            return Vec::new();
        }
        let count = *self.count.get_or_insert(v.param_count);
        if v.param_count != count && self.restarts < MAX_RESTARTS {
            return self.restart(now);
        }
        let index = if v.param_index == u16::MAX {
            match self.by_name.get(&name) {
                Some(&i) => i,
                None => return Vec::new(),
            }
        } else {
            v.param_index
        };
        if index >= count {
            return Vec::new();
        }
        self.last_rx = now;
        self.check = now + self.rto;
        self.stalls = 0;
        self.by_name.insert(name.clone(), index);
        let new = self.values.insert(index, (name, param)).is_none();
        if self.values.len() == 1 && self.list_sends == 1 {
            self.sample(now.duration_since(self.started));
        }
        match self.outstanding.remove(&index) {
            // Sooner than half a round trip after the first request it cannot be the answer:
            // the stream's own value, late (reordered), and the hole was none.
            Some(ask) if ask.tries == 1 && now.duration_since(ask.sent) < self.srtt() / 2 => {
                self.holes_seen = self.holes_seen.saturating_sub(1);
            }
            Some(ask) => {
                self.answered += 1;
                self.copies_resolved += ask.copies;
                if ask.tries == 1 {
                    let s = now.duration_since(ask.sent);
                    self.recent.push_back(s);
                    if self.recent.len() > RECENT {
                        self.recent.pop_front();
                    }
                    self.sample(s);
                }
            }
            None if !self.asked.contains(&index) && v.param_index != u16::MAX => {
                if new {
                    self.streamed(index, now);
                } else {
                    // A value held already, streamed again by a later pass: the stream is
                    // still coming.
                    self.last_streamed = Some(now);
                }
                self.pass_last = Some(index);
            }
            None => {}
        }
        self.shown.remove(&index);
        self.complete();
        if self.done.is_some() {
            return Vec::new();
        }
        let out = self.refill(now);
        self.flush(now, out)
    }

    fn on_time(&mut self, now: Instant) -> Vec<MavMessage> {
        if self.done.is_some() || now < self.deadline() {
            return Vec::new();
        }
        let out = self.on_time_inner(now);
        if self.done.is_some() {
            return out;
        }
        self.flush(now, out)
    }

    fn deadline(&self) -> Instant {
        self.next_deadline()
    }

    fn result(&mut self) -> Option<Self::Output> {
        self.done.take()
    }

    fn take_rtt_samples(&mut self) -> Vec<Duration> {
        std::mem::take(&mut self.samples)
    }
}

impl PullMachine {
    /// What is due at `now` (the reads paced out by the caller).
    fn on_time_inner(&mut self, now: Instant) -> Vec<MavMessage> {
        let silent = now.duration_since(self.last_rx);
        if now >= self.check {
            self.check = now + self.rto;
            self.stalls += 1;
            if self.stalls > PULL_STALLS && silent >= PULL_GIVE_UP {
                let (received, total) = self.progress();
                self.done = Some(Err(PullStalled { received, total }));
                return Vec::new();
            }
        }
        if self.count.is_none() {
            return if now >= self.list_due {
                self.list(now)
            } else {
                Vec::new()
            };
        }
        // The stream's own end: answers to reads go on arriving after it.
        let stream_silent = now.duration_since(self.last_streamed.unwrap_or(self.last_rx));
        if !self.stream_over && stream_silent >= self.stream_end_quiet() {
            self.stream_over = true;
        }
        let missing = self.count.map_or(0, usize::from) - self.values.len();
        if self.stream_over && missing > RELIST_MISSING {
            // The stream brings the rest sooner than reads one at a time (a window of them a
            // round trip; and ArduPilot sends no stream while it answers reads): ask for it
            // again, once it has been quiet for longer than a vehicle's own pause (a new list
            // request restarts the stream from its first value).
            if now >= self.relist_due && stream_silent >= self.relist_quiet() {
                self.relist_due = now + RELIST_EVERY.max(self.srtt() * 2);
                // The stream answers what the reads waiting to leave would have asked.
                self.paced.clear();
                self.stream_over = false;
                // The pause before the new stream is no gap of it.
                self.last_streamed = None;
                self.pass_last = None;
                // The holes the first pass showed are the new pass's to bring: read while it
                // runs, they would take its place (ArduPilot sends the answers to reads out of
                // the same share of its link as the stream, first), and be answered far slower.
                self.shown.clear();
                self.list_sends = 0;
                return self.list(now);
            }
            return Vec::new();
        }
        // Requests whose answer is overdue are asked again.
        let overdue: Vec<u16> = self
            .outstanding
            .iter()
            .filter(|(_, a)| a.due <= now)
            .map(|(i, _)| *i)
            .collect();
        for i in &overdue {
            self.timed_out += 1;
            self.copies_resolved += self.outstanding.get(i).map_or(1, |a| a.copies);
        }
        let copies = self.copies(missing);
        let mut out = self.read(&overdue, copies, now);
        out.extend(self.refill(now));
        self.flush(now, out)
    }

    fn next_deadline(&self) -> Instant {
        // The next stall check, at the latest; the next paced read.
        let mut d = self.pace_due().map_or(self.check, |p| p.min(self.check));
        let missing = self.count.map_or(0, usize::from) - self.values.len();
        if self.stream_over && missing > RELIST_MISSING {
            // Waiting to ask for the stream again: the reads outstanding wait with it.
            let silent_enough = self.last_streamed.unwrap_or(self.last_rx) + self.relist_quiet();
            return d.min(self.relist_due.max(silent_enough));
        }
        if self.count.is_none() {
            d = d.min(self.list_due);
        } else if !self.stream_over {
            d = d.min(self.last_streamed.unwrap_or(self.last_rx) + self.stream_end_quiet());
            // Holes are asked for when they have waited, if the window has room (else an
            // answer or a timeout makes room).
            let room = self.window(self.copies(missing)) > self.outstanding.len();
            if let Some(at) = self.shown.values().min()
                && room
                && self.shown.len() + self.outstanding.len() <= RELIST_MISSING
            {
                d = d.min(*at + self.hole_allowance());
            }
        }
        if let Some(due) = self.outstanding.values().map(|a| a.due).min() {
            d = d.min(due);
        }
        d
    }
}

#[cfg(test)]
#[path = "pull_tests.rs"]
mod tests;
