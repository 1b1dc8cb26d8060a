//! The fit against tracker states built from frames: a link that loses a share of every
//! stream's frames, and a radio that reports its buffer.

use vtol_link::Frame;
use vtol_link::dialect::{self as apm, MavAutopilot, MavModeFlag, MavState, MavType};

use super::*;
use crate::tap::Side;

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
}

impl Feed {
    fn new(t0: Instant) -> Self {
        Self {
            state: VehicleState::new(t0),
            seq: 0,
            sent: 0,
            lose_every: 0,
        }
    }

    fn send(&mut self, m: &MavMessage, at: Instant) {
        self.sent += 1;
        let f = Frame::encode_v2(V.0, V.1, self.seq, m);
        self.seq = self.seq.wrapping_add(1);
        if self.lose_every > 0 && self.sent.is_multiple_of(self.lose_every) {
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

#[test]
fn a_full_link_gets_rates_that_fit_and_keeps_them_once_the_loss_stops() {
    let t0 = Instant::now();
    let mut feed = Feed::new(t0);
    feed.lose_every = 5; // 20 % lost: the radio's queue overflows
    feed.run(t0, 3, 100, 50);
    let mut fit = Fitter::default();
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
    let t0 = Instant::now();
    let mut feed = Feed::new(t0);
    feed.lose_every = 4;
    feed.run(t0, 3, 100, 50);
    let mut fit = Fitter::default();
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

#[test]
fn a_clean_link_is_left_alone() {
    let t0 = Instant::now();
    let mut feed = Feed::new(t0);
    feed.run(t0, 3, 100, 50);
    let mut fit = Fitter::default();
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
    let t0 = Instant::now();
    let mut feed = Feed::new(t0);
    feed.run(t0, 3, 100, 50);
    let radio = |txbuf| {
        MavMessage::RADIO_STATUS(apm::RADIO_STATUS_DATA {
            rxerrors: 0,
            fixed: 0,
            rssi: 200,
            remrssi: 190,
            txbuf,
            noise: 40,
            remnoise: 41,
        })
    };
    // A SiK radio speaks as system 51, component 68.
    let at = t0 + Duration::from_millis(2_900);
    let plenty = Frame::encode_v2(SystemId(51), ComponentId(68), 0, &radio(90));
    feed.state.apply(L, Side::Vehicle, &plenty, at);
    let mut fit = Fitter::default();
    let now = t0 + Duration::from_secs(3);
    assert!(fit.tick(&feed.state, V, now).is_empty());
    assert_eq!(fit.report().expect("a report").radio_txbuf, Some(90));
    let low = Frame::encode_v2(SystemId(51), ComponentId(68), 1, &radio(30));
    feed.state.apply(L, Side::Vehicle, &low, now);
    let asked = fit.tick(&feed.state, V, now + FIT_PERIOD);
    let att = hz(&asked, id::ATTITUDE).expect("ATTITUDE re-rated");
    assert!(att < 80.0, "{att}");
    assert_eq!(fit.report().expect("a report").radio_txbuf, Some(30));
}

#[test]
fn a_fit_that_halves_the_loss_goes_again_from_the_rates_then_flowing() {
    let t0 = Instant::now();
    let mut feed = Feed::new(t0);
    feed.lose_every = 3;
    feed.run(t0, 3, 100, 50);
    let mut fit = Fitter::default();
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
