//! The fit against tracker states built from frames: a link that loses a share of every
//! stream's frames, and a radio that reports its buffer; then a vehicle that does what the fit
//! asks over a link of a given capacity, a second at a time, for the steps back up.

use vtol_link::Frame;
use vtol_link::dialect::{self as apm, MavAutopilot, MavModeFlag, MavState, MavType};

use super::*;
use crate::client::test_frames::radio_status;
use crate::links::Side;

const V: (SystemId, ComponentId) = (SystemId(1), ComponentId(1));
const L: LinkId = LinkId(1);

fn heartbeat() -> MavMessage {
    MavMessage::HEARTBEAT(apm::HEARTBEAT_DATA {
        custom_mode: 0,
        mavtype: MavType::MAV_TYPE_VTOL_TAILSITTER_DUOROTOR,
        autopilot: MavAutopilot::MAV_AUTOPILOT_ARDUPILOTMEGA,
        base_mode: MavModeFlag::empty(),
        system_status: MavState::MAV_STATE_STANDBY,
        mavlink_version: 3,
    })
}

fn attitude() -> MavMessage {
    MavMessage::ATTITUDE(apm::ATTITUDE_DATA::default())
}

fn servo() -> MavMessage {
    MavMessage::SERVO_OUTPUT_RAW(apm::SERVO_OUTPUT_RAW_DATA::default())
}

/// A vehicle sending ATTITUDE at `att_hz` and SERVO_OUTPUT_RAW at `servo_hz` for `secs` from
/// `t0`, a heartbeat a second, of which every `lose_every`-th frame (0: none) is lost.
struct Feed {
    state: VehicleState,
    seq: u8,
    sent: u64,
    lose_every: u64,
    /// Share of frames lost at random (seeded), besides `lose_every`.
    lose_share: f64,
    rng: u64,
}

impl Feed {
    fn new(t0: Instant) -> Self {
        Self {
            state: VehicleState::new(t0),
            seq: 0,
            sent: 0,
            lose_every: 0,
            lose_share: 0.0,
            rng: 0x9e37_79b9_7f4a_7c15,
        }
    }

    fn send(&mut self, m: &MavMessage, at: Instant) {
        self.sent += 1;
        let f = Frame::encode_v2(V.0, V.1, self.seq, m);
        self.seq = self.seq.wrapping_add(1);
        if self.lose_every > 0 && self.sent.is_multiple_of(self.lose_every) {
            return;
        }
        // xorshift64: a loss that falls on no message more than another.
        self.rng ^= self.rng << 13;
        self.rng ^= self.rng >> 7;
        self.rng ^= self.rng << 17;
        if (self.rng >> 11) as f64 / (1u64 << 53) as f64 <= self.lose_share {
            return;
        }
        self.state.apply(L, Side::Vehicle, &f, at);
    }

    /// `secs` of traffic from `from`, at 1 ms resolution.
    fn run(&mut self, from: Instant, secs: u64, att_hz: u64, servo_hz: u64) {
        for ms in 0..secs * 1000 {
            let at = from + Duration::from_millis(ms);
            if ms % 1000 == 0 {
                self.send(&heartbeat(), at);
            }
            if att_hz > 0 && ms % (1000 / att_hz) == 0 {
                self.send(&attitude(), at);
            }
            if servo_hz > 0 && ms % (1000 / servo_hz) == 0 {
                self.send(&servo(), at);
            }
        }
    }
}

/// The rate asked for `msgid`, from a vehicle that does not tell its intervals.
fn hz(asked: &[(u32, Change)], msgid: u32) -> Option<f64> {
    asked
        .iter()
        .find(|(m, _)| *m == msgid)
        .map(|(_, c)| 1e6 / f64::from(c.interval_us(None)))
}

/// Three seconds of the vehicle's default streams (ATTITUDE 100 Hz, SERVO_OUTPUT_RAW 50 Hz) with
/// every `lose_every`-th frame lost (0: none): the start, the feed and a fresh fit.
fn three_seconds(lose_every: u64) -> (Instant, Feed, Fitter) {
    let t0 = Instant::now();
    let mut feed = Feed::new(t0);
    feed.lose_every = lose_every;
    feed.run(t0, 3, 100, 50);
    (t0, feed, Fitter::default())
}

#[test]
fn a_full_link_gets_rates_that_fit_and_keeps_them_once_the_loss_stops() {
    let (t0, mut feed, mut fit) = three_seconds(5); // 20 % lost: the radio's queue overflows
    let now = t0 + Duration::from_secs(3);
    let asked = fit.tick(&feed.state, V, now);
    let att = hz(&asked, id::ATTITUDE).expect("ATTITUDE re-rated");
    let servo = hz(&asked, id::SERVO_OUTPUT_RAW).expect("SERVO_OUTPUT_RAW re-rated");
    assert!(hz(&asked, id::HEARTBEAT).is_none(), "{asked:?}");
    // Delivered 80 % of what was sent; 75 % of that is the budget: the streams get about
    // 0.8 × 0.75 = 60 % of their rates (a little less: the heartbeat is not scaled).
    assert!((50.0..62.0).contains(&att), "{att}");
    assert!((25.0..31.0).contains(&servo), "{servo}");
    // A vehicle that tells its interval gets it stretched: a message sent as four frames every
    // 100 ms (40 frames a second) goes to four every 100 / 0.6 ms, not to one every 1 / 24 s.
    let Some((_, c)) = asked.iter().find(|(m, _)| *m == id::ATTITUDE) else {
        unreachable!()
    };
    let stretched = f64::from(c.interval_us(Some(100_000)));
    assert!(
        (100_000.0 / 0.62..100_000.0 / 0.5).contains(&stretched),
        "{stretched}"
    );
    assert_eq!(
        c.interval_us(Some(0)),
        c.interval_us(None),
        "not sent: from the frames"
    );
    // The biggest stream first.
    assert_eq!(asked[0].0, id::ATTITUDE);
    assert!(
        !fit.report().expect("a report").fitted,
        "not before it is asked for"
    );
    fit.asked(now);
    let report = fit.report().expect("a report");
    assert!(report.fitted);
    let capacity = report.capacity.expect("measured");
    let delivered = feed.state.links[&L].bytes_per_s(now);
    assert!((capacity - delivered).abs() < 1e-6);
    // The vehicle follows; the loss stops: the fit stands.
    feed.lose_every = 0;
    feed.run(now, 4, 50, 25);
    let later = now + Duration::from_secs(4);
    assert!(fit.tick(&feed.state, V, later).is_empty());
    assert!(fit.report().expect("a report").fitted);
    assert!(fit.tick(&feed.state, V, later + FIT_PERIOD).is_empty());
}

#[test]
fn loss_that_does_not_stop_with_the_rates_gives_the_defaults_back() {
    let (t0, mut feed, mut fit) = three_seconds(4);
    let now = t0 + Duration::from_secs(3);
    let asked = fit.tick(&feed.state, V, now);
    assert_eq!(asked.len(), 2, "{asked:?}");
    fit.asked(now);
    // Slower, and still losing a quarter: a lossy link, not a full one.
    feed.run(now, 4, 50, 25);
    let later = now + Duration::from_secs(4);
    let back = fit.tick(&feed.state, V, later);
    let mut ids: Vec<u32> = back.iter().map(|(m, _)| *m).collect();
    ids.sort_unstable();
    assert_eq!(ids, [id::ATTITUDE, id::SERVO_OUTPUT_RAW]);
    assert!(back.iter().all(|(_, c)| *c == Change::Default), "{back:?}");
    let report = fit.report().expect("a report");
    assert!(!report.fitted && report.capacity.is_none());
    // Left alone while the loss goes on...
    feed.run(later, 5, 100, 50);
    assert!(
        fit.tick(&feed.state, V, later + Duration::from_secs(5))
            .is_empty()
    );
}

/// The same loss, but one of the fit's requests went unanswered on the full link: the fit was
/// not all tried, so it goes again instead of calling the loss random.
#[test]
fn a_fit_whose_requests_went_unanswered_goes_again() {
    let (t0, mut feed, mut fit) = three_seconds(4);
    let now = t0 + Duration::from_secs(3);
    assert_eq!(fit.tick(&feed.state, V, now).len(), 2);
    fit.unanswered();
    fit.asked(now);
    feed.run(now, 4, 50, 25);
    let again = fit.tick(&feed.state, V, now + Duration::from_secs(4));
    assert!(!again.is_empty(), "fitted again");
    assert!(
        again.iter().all(|(_, c)| matches!(c, Change::Scale { .. })),
        "{again:?}"
    );
}

#[test]
fn a_clean_link_is_left_alone() {
    let (t0, feed, mut fit) = three_seconds(0);
    assert!(
        fit.tick(&feed.state, V, t0 + Duration::from_secs(3))
            .is_empty()
    );
    let report = fit.report().expect("a report");
    assert_eq!(
        report,
        LinkFit {
            link: L,
            capacity: None,
            fitted: false,
            radio_txbuf: None
        }
    );
}

#[test]
fn a_radio_reporting_its_buffer_filling_is_a_full_link_before_any_loss() {
    let (t0, mut feed, mut fit) = three_seconds(0);
    let at = t0 + Duration::from_millis(2_900);
    let plenty = radio_status(90, 0);
    feed.state.apply(L, Side::Vehicle, &plenty, at);
    let now = t0 + Duration::from_secs(3);
    assert!(fit.tick(&feed.state, V, now).is_empty());
    assert_eq!(fit.report().expect("a report").radio_txbuf, Some(90));
    let low = radio_status(30, 1);
    feed.state.apply(L, Side::Vehicle, &low, now);
    let asked = fit.tick(&feed.state, V, now + FIT_PERIOD);
    let att = hz(&asked, id::ATTITUDE).expect("ATTITUDE re-rated");
    assert!(att < 80.0, "{att}");
    assert_eq!(fit.report().expect("a report").radio_txbuf, Some(30));
}

#[test]
fn a_fit_that_halves_the_loss_goes_again_from_the_rates_then_flowing() {
    let (t0, mut feed, mut fit) = three_seconds(3);
    let now = t0 + Duration::from_secs(3);
    assert!(!fit.tick(&feed.state, V, now).is_empty());
    fit.asked(now);
    // A third lost before, a tenth after: the link carries less than first thought.
    feed.lose_every = 10;
    feed.run(now, 4, 50, 25);
    let later = now + Duration::from_secs(4);
    let again = fit.tick(&feed.state, V, later);
    assert!(
        again
            .iter()
            .all(|(_, c)| matches!(c, Change::Scale { ratio, .. } if *ratio < 1.0)),
        "{again:?}"
    );
    let att = hz(&again, id::ATTITUDE).expect("ATTITUDE re-rated");
    assert!(att < 50.0, "{att}");
}

/// A vehicle that does what the fit asks of its ATTITUDE and SERVO_OUTPUT_RAW, over a link
/// that carries `capacity` frames a second (the rest lost evenly), a second at a time.
struct Loop {
    feed: Feed,
    fit: Fitter,
    now: Instant,
    defaults: [f64; 2],
    rates: [f64; 2],
    capacity: Option<f64>,
}

impl Loop {
    fn new(capacity: Option<f64>) -> Self {
        let t0 = Instant::now();
        Self {
            feed: Feed::new(t0),
            fit: Fitter::default(),
            now: t0,
            defaults: [100.0, 50.0],
            rates: [100.0, 50.0],
            capacity,
        }
    }

    /// One second of traffic, then a look by the fit; what it asked, done by the vehicle.
    fn second(&mut self) -> Vec<(u32, Change)> {
        let offered = self.rates[0] + self.rates[1] + 1.0;
        self.feed.lose_share = match self.capacity {
            Some(c) if offered > c => (offered - c) / offered,
            _ => 0.0,
        };
        let hz = |r: f64| r.round().max(1.0) as u64;
        let (att, servo) = (hz(self.rates[0]), hz(self.rates[1]));
        self.feed.run(self.now, 1, att, servo);
        self.now += Duration::from_secs(1);
        let asked = self.fit.tick(&self.feed.state, V, self.now);
        for (msgid, change) in &asked {
            let i = usize::from(*msgid != id::ATTITUDE);
            self.rates[i] = match *change {
                Change::Scale { ratio, .. } => self.rates[i] * ratio,
                Change::Default => self.defaults[i],
            };
        }
        if !asked.is_empty() {
            self.fit.asked(self.now);
        }
        asked
    }

    /// Seconds until the fit asks something (at most `limit`), and what.
    fn until_asked(&mut self, limit: u64) -> Option<(u64, Vec<(u32, Change)>)> {
        (1..=limit).find_map(|s| {
            let asked = self.second();
            (!asked.is_empty()).then_some((s, asked))
        })
    }
}

fn ratio(asked: &[(u32, Change)], msgid: u32) -> f64 {
    match asked.iter().find(|(m, _)| *m == msgid) {
        Some((_, Change::Scale { ratio, .. })) => *ratio,
        other => panic!("{other:?} in {asked:?}"),
    }
}

#[test]
fn a_fitted_link_that_clears_gets_its_rates_back_step_by_step_up_to_the_defaults() {
    // A radio whose rate limit is lifted as soon as the streams are fitted.
    let mut l = Loop::new(Some(100.0));
    let (_, fitted) = l.until_asked(5).expect("fitted");
    assert!(ratio(&fitted, id::ATTITUDE) < 0.7, "{fitted:?}");
    l.capacity = None;
    let low = l.rates[0];
    // Nothing until the link has been clear for the hold (after the fit's own settling).
    let (waited, first) = l.until_asked(60).expect("a step up");
    assert!(
        waited >= RAISE_HOLD.as_secs(),
        "after {waited} s: {first:?}"
    );
    // A quarter of the way back, every changed stream alike.
    let step = ratio(&first, id::ATTITUDE);
    let expected = (low + RAISE_STEP * (100.0 - low)) / low;
    assert!((step - expected).abs() < 1e-9, "{step} != {expected}");
    assert!(ratio(&first, id::SERVO_OUTPUT_RAW) > 1.0, "{first:?}");
    assert!(l.fit.report().expect("a report").fitted);
    // The next steps come sooner once one has worked, each higher, the last to the defaults.
    let mut rates = vec![l.rates[0]];
    let last = loop {
        let (waited, asked) = l.until_asked(60).expect("another step");
        assert!(waited < RAISE_HOLD.as_secs(), "after {waited} s");
        if asked.iter().all(|(_, c)| *c == Change::Default) {
            break asked;
        }
        assert!(l.rates[0] > rates[rates.len() - 1], "{asked:?}");
        rates.push(l.rates[0]);
    };
    assert_eq!(rates.len(), 3, "{rates:?}");
    assert_eq!(last.len(), 2, "{last:?}");
    let report = l.fit.report().expect("a report");
    assert!(!report.fitted && report.capacity.is_none(), "{report:?}");
    // And then left alone.
    assert!(l.until_asked(240).is_none());
}

#[test]
fn a_step_that_fills_the_link_is_taken_back_and_the_steps_after_it_stay_below_it() {
    let mut l = Loop::new(Some(100.0));
    l.until_asked(5).expect("fitted");
    let mut backs = Vec::new();
    let mut ups = Vec::new();
    for s in 0..600u64 {
        let before = l.rates[0];
        let asked = l.second();
        if asked.is_empty() || asked.iter().any(|(_, c)| *c == Change::Default) {
            assert!(asked.is_empty(), "the defaults never fit: {asked:?}");
            continue;
        }
        if ratio(&asked, id::ATTITUDE) > 1.0 {
            ups.push((s, l.rates[0]));
        } else {
            backs.push((s, before, l.rates[0]));
        }
    }
    // The first step that overfilled the link went back to the rates before it...
    let (at, failed, back) = backs[0];
    let before = ups
        .iter()
        .rev()
        .find(|(s, _)| *s < at)
        .expect("a step first");
    assert!(failed > back, "{backs:?}");
    let prior = ups
        .iter()
        .rev()
        .filter(|(s, _)| *s < before.0)
        .map(|&(_, r)| r)
        .next();
    if let Some(p) = prior {
        assert!((back - p).abs() < 1e-6, "{back} != {p}");
    }
    // ...and the steps after it stayed below its rate while it was remembered, the first one
    // only after a doubled hold.
    let next = ups.iter().find(|(s, _)| *s > at).expect("a later step");
    assert!(next.0 - at >= 2 * RAISE_HOLD.as_secs(), "{ups:?} {backs:?}");
    let remembered = at..at + CEILING_MEMORY.as_secs();
    assert!(
        ups.iter()
            .filter(|(s, _)| remembered.contains(s))
            .all(|&(_, r)| r < failed),
        "{ups:?} {backs:?}"
    );
    // Ten minutes on a link that cannot carry the defaults: a handful of failed steps, not a
    // sawtooth; and the capacity is the link's.
    assert!(backs.len() <= 4, "{backs:?}");
    assert!(l.rates[0] + l.rates[1] < 100.0, "{:?}", l.rates);
    let capacity = l.fit.report().and_then(|r| r.capacity).expect("measured");
    assert!(capacity > 0.0);
}

#[test]
fn a_radio_buffer_that_is_not_mostly_empty_holds_the_rates() {
    let mut l = Loop::new(None);
    let mut seq = 0u8;
    let mut say = |l: &mut Loop, txbuf| {
        seq = seq.wrapping_add(1);
        l.feed
            .state
            .apply(L, Side::Vehicle, &radio_status(txbuf, seq), l.now);
    };
    l.second();
    say(&mut l, 30);
    assert!(!l.second().is_empty(), "fitted on the radio's word");
    // Half to nine tenths free: neither full nor clear, for a minute.
    for _ in 0..60 {
        say(&mut l, 70);
        assert!(l.second().is_empty());
    }
    // Mostly empty: a step up after the hold.
    let mut waited = 0;
    loop {
        say(&mut l, 95);
        waited += 1;
        let asked = l.second();
        if !asked.is_empty() {
            assert!(ratio(&asked, id::ATTITUDE) > 1.0, "{asked:?}");
            break;
        }
        assert!(waited < 60);
    }
    assert!(waited >= RAISE_HOLD.as_secs(), "{waited}");
    // The buffer filling during the step takes it back at once.
    say(&mut l, 40);
    let back = l.second();
    assert!(ratio(&back, id::ATTITUDE) < 1.0, "{back:?}");
}

#[test]
fn a_ceiling_is_forgotten_in_time_so_a_link_that_got_faster_gets_the_defaults_back() {
    let mut l = Loop::new(Some(100.0));
    l.until_asked(5).expect("fitted");
    // Long enough for a step to fail and the rates to settle below it.
    for _ in 0..120 {
        l.second();
    }
    assert!(l.fit.ceiling.is_some(), "a step failed");
    l.capacity = None;
    let mut t = 0;
    while l.rates != l.defaults {
        l.second();
        t += 1;
        assert!(
            t < CEILING_MEMORY.as_secs() + 2 * MAX_RAISE_HOLD.as_secs(),
            "{:?} after {t} s",
            l.rates
        );
    }
}
