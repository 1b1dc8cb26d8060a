//! The mission machines against a vehicle model that behaves as ArduPilot does (it asks with
//! MISSION_REQUEST and asks again after a second of silence), over a link that drops frames.

use std::time::{Duration, Instant};

use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use vtol_link::dialect::{self as apm, MavMessage, MavMissionResult, MavMissionType};
use vtol_link::{ComponentId, SystemId};

use super::super::machine::{Inbound, Machine};
use super::*;
use crate::mission::Item;

const V: (SystemId, ComponentId) = (SystemId(1), ComponentId(1));
const ME: (SystemId, ComponentId) = (SystemId(255), ComponentId(190));
const HOP: Duration = Duration::from_millis(5);
const RE_REQUEST: Duration = Duration::from_secs(1);

/// The vehicle's side of the mission protocol, mission list only.
#[derive(Default)]
struct Vehicle {
    stored: Vec<apm::MISSION_ITEM_INT_DATA>,
    upload: Option<(u16, Vec<apm::MISSION_ITEM_INT_DATA>, Instant)>,
    items_received: usize,
}

fn request(seq: u16) -> MavMessage {
    MavMessage::MISSION_REQUEST(apm::MISSION_REQUEST_DATA {
        seq,
        target_system: 255,
        target_component: 190,
        mission_type: MavMissionType::MAV_MISSION_TYPE_MISSION,
    })
}

fn ack(r: MavMissionResult) -> MavMessage {
    MavMessage::MISSION_ACK(apm::MISSION_ACK_DATA {
        target_system: 255,
        target_component: 190,
        mavtype: r,
        mission_type: MavMissionType::MAV_MISSION_TYPE_MISSION,
        opaque_id: 0,
    })
}

impl Vehicle {
    fn on(&mut self, now: Instant, msg: &MavMessage) -> Vec<MavMessage> {
        match msg {
            MavMessage::MISSION_COUNT(c) => {
                if c.count == 0 {
                    self.stored.clear();
                    return vec![ack(MavMissionResult::MAV_MISSION_ACCEPTED)];
                }
                self.upload = Some((c.count, Vec::new(), now));
                vec![request(0)]
            }
            MavMessage::MISSION_ITEM_INT(i) => {
                self.items_received += 1;
                let Some((count, got, at)) = &mut self.upload else {
                    // A repeated last item: our ACK was lost; the same again (as the twin).
                    if usize::from(i.seq) + 1 == self.stored.len() {
                        return vec![ack(MavMissionResult::MAV_MISSION_ACCEPTED)];
                    }
                    return Vec::new();
                };
                if usize::from(i.seq) != got.len() {
                    return Vec::new();
                }
                got.push(i.clone());
                *at = now;
                if got.len() == usize::from(*count) {
                    self.stored = std::mem::take(got);
                    self.upload = None;
                    return vec![ack(MavMissionResult::MAV_MISSION_ACCEPTED)];
                }
                vec![request(u16::try_from(got.len()).expect("small"))]
            }
            MavMessage::MISSION_REQUEST_LIST(_) => {
                vec![MavMessage::MISSION_COUNT(apm::MISSION_COUNT_DATA {
                    count: u16::try_from(self.stored.len()).expect("small"),
                    target_system: 255,
                    target_component: 190,
                    mission_type: MavMissionType::MAV_MISSION_TYPE_MISSION,
                    opaque_id: 0,
                })]
            }
            MavMessage::MISSION_REQUEST_INT(r) => self
                .stored
                .get(usize::from(r.seq))
                .map(|i| {
                    let mut i = i.clone();
                    (i.target_system, i.target_component) = (255, 190);
                    MavMessage::MISSION_ITEM_INT(i)
                })
                .into_iter()
                .collect(),
            MavMessage::MISSION_CLEAR_ALL(_) => {
                self.stored.clear();
                vec![ack(MavMissionResult::MAV_MISSION_ACCEPTED)]
            }
            _ => Vec::new(),
        }
    }

    fn deadline(&self) -> Option<Instant> {
        self.upload.as_ref().map(|(_, _, at)| *at + RE_REQUEST)
    }

    fn on_time(&mut self, now: Instant) -> Vec<MavMessage> {
        match &mut self.upload {
            Some((_, got, at)) if now >= *at + RE_REQUEST => {
                *at = now;
                vec![request(u16::try_from(got.len()).expect("small"))]
            }
            _ => Vec::new(),
        }
    }
}

/// Runs `m` against `v` with each frame lost with probability `loss` (seeded); returns the
/// result and the time it took.
fn run<M: Machine>(m: &mut M, v: &mut Vehicle, loss: f64, seed: u64) -> (M::Output, Duration) {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let t0 = Instant::now();
    let mut now = t0;
    let mut to_vehicle = m.start(now);
    for _ in 0..1_000_000 {
        now += HOP;
        let mut to_gcs = Vec::new();
        for msg in to_vehicle.drain(..) {
            if !rng.random_bool(loss) {
                to_gcs.extend(v.on(now, &msg));
            }
        }
        if !to_gcs.is_empty() {
            now += HOP;
        }
        for msg in to_gcs {
            if !rng.random_bool(loss) {
                let inb = Inbound {
                    sys: V.0,
                    comp: V.1,
                    msg,
                };
                to_vehicle.extend(m.on_message(now, &inb));
            }
        }
        if let Some(out) = m.result() {
            return (out, now - t0);
        }
        if to_vehicle.is_empty() {
            let next = v.deadline().map_or(m.deadline(), |d| d.min(m.deadline()));
            now = now.max(next);
            let from_vehicle = v.on_time(now);
            for msg in from_vehicle {
                if !rng.random_bool(loss) {
                    let inb = Inbound {
                        sys: V.0,
                        comp: V.1,
                        msg,
                    };
                    to_vehicle.extend(m.on_message(now, &inb));
                }
            }
            to_vehicle.extend(m.on_time(now));
        }
    }
    panic!("the exchange never ended");
}

fn mission(n: usize) -> Vec<Item> {
    (0..n)
        .map(|k| Item {
            frame: if k == 0 { 0 } else { 3 },
            command: 16,
            current: k == 0,
            autocontinue: true,
            #[allow(clippy::cast_precision_loss)]
            params: [k as f32, 0.5, 0.0, f32::NAN],
            x: -35.363_261_9 + k as f64 * 1e-4,
            y: 149.165_237_4,
            z: 30.0,
        })
        .collect()
}

fn upload(items: &[Item], v: &mut Vehicle, loss: f64, seed: u64) -> UploadOutcome {
    let wire = items
        .iter()
        .enumerate()
        .map(|(k, i)| to_wire(u16::try_from(k).expect("small"), i, V, Kind::Mission).expect("wire"))
        .collect();
    let mut m = UploadMachine::new(ME, V, Kind::Mission, wire, Duration::from_millis(20));
    run(&mut m, v, loss, seed).0
}

fn download(v: &mut Vehicle, loss: f64, seed: u64) -> Result<Vec<Item>, DownloadStalled> {
    let mut m = DownloadMachine::new(ME, V, Kind::Mission, Duration::from_millis(20));
    run(&mut m, v, loss, seed).0
}

fn same(a: &[Item], b: &[Item]) -> bool {
    a.len() == b.len() && a.iter().zip(b).all(|(x, y)| x.same_as(y))
}

#[test]
fn items_survive_the_wire_bit_for_bit() {
    for i in mission(3) {
        let w = to_wire(2, &i, V, Kind::Mission).expect("wire");
        assert!(from_wire(&w).same_as(&i));
        assert_eq!(from_wire(&w).wire_xy(), i.wire_xy());
    }
}

#[test]
fn a_clean_link_uploads_and_downloads_the_same_list() {
    let items = mission(6);
    let mut v = Vehicle::default();
    assert_eq!(
        upload(&items, &mut v, 0.0, 1),
        UploadOutcome::Acked {
            result: MavMissionResult::MAV_MISSION_ACCEPTED,
            reason: None
        }
    );
    assert_eq!(v.items_received, 6, "each item sent once");
    let back = download(&mut v, 0.0, 1).expect("downloads");
    assert!(same(&items, &back));
}

#[test]
fn lost_requests_items_and_acks_are_asked_again_at_30_percent_loss() {
    let items = mission(12);
    let mut no_ack = 0;
    for seed in 0..20 {
        let mut v = Vehicle::default();
        let out = upload(&items, &mut v, 0.3, seed);
        // The vehicle took the list: a lost ACK is told apart by the download that follows.
        match out {
            UploadOutcome::Acked { result, .. } => {
                assert_eq!(
                    result,
                    MavMissionResult::MAV_MISSION_ACCEPTED,
                    "seed {seed}"
                )
            }
            UploadOutcome::NoAck { .. } => no_ack += 1,
        }
        let stored: Vec<Item> = v.stored.iter().map(from_wire).collect();
        assert!(same(&items, &stored), "seed {seed}: stored as sent");
        let back = download(&mut v, 0.3, seed + 100).expect("downloads");
        assert!(same(&items, &back), "seed {seed}");
    }
    assert!(no_ack <= 2, "{no_ack} of 20 uploads without an ACK");
}

#[test]
fn a_silent_vehicle_ends_each_transfer_with_what_was_done() {
    let t0 = Instant::now();
    let mut m = DownloadMachine::new(ME, V, Kind::Mission, Duration::from_millis(20));
    let mut sends = m.start(t0).len();
    while m.result_pending() {
        let d = m.deadline();
        sends += m.on_time(d).len();
    }
    assert!(sends >= usize::from(MISSION_TRIES));
    let mut u = UploadMachine::new(ME, V, Kind::Mission, Vec::new(), Duration::from_millis(20));
    u.start(t0);
    let mut out = None;
    while out.is_none() {
        let d = u.deadline();
        u.on_time(d);
        out = u.result();
    }
    assert_eq!(
        out,
        Some(UploadOutcome::NoAck {
            requested: 0,
            total: 0
        })
    );
}

#[test]
fn a_refusal_carries_the_vehicle_reason() {
    let items = mission(2);
    let wire = items
        .iter()
        .enumerate()
        .map(|(k, i)| to_wire(u16::try_from(k).expect("small"), i, V, Kind::Mission).expect("wire"))
        .collect();
    let t0 = Instant::now();
    let mut m = UploadMachine::new(ME, V, Kind::Mission, wire, Duration::from_millis(20));
    m.start(t0);
    let from = |msg| Inbound {
        sys: V.0,
        comp: V.1,
        msg,
    };
    let sent = m.on_message(t0, &from(request(0)));
    assert!(matches!(sent[..], [MavMessage::MISSION_ITEM_INT(ref i)] if i.seq == 0));
    m.on_message(
        t0,
        &from(MavMessage::STATUSTEXT(apm::STATUSTEXT_DATA {
            severity: apm::MavSeverity::MAV_SEVERITY_WARNING,
            text: "Mission item 0: frame 3 is not supported".into(),
            id: 0,
            chunk_seq: 0,
        })),
    );
    m.on_message(
        t0,
        &from(ack(MavMissionResult::MAV_MISSION_UNSUPPORTED_FRAME)),
    );
    assert_eq!(
        m.result(),
        Some(UploadOutcome::Acked {
            result: MavMissionResult::MAV_MISSION_UNSUPPORTED_FRAME,
            reason: Some("Mission item 0: frame 3 is not supported".into())
        })
    );
    let mut other = UploadMachine::new(
        (SystemId(255), ComponentId(42)),
        V,
        Kind::Mission,
        Vec::new(),
        Duration::from_millis(20),
    );
    other.start(t0);
    assert!(
        other
            .on_message(t0, &from(ack(MavMissionResult::MAV_MISSION_ACCEPTED)))
            .is_empty()
    );
    assert_eq!(other.result(), None, "an ACK for another ground station");
    assert_eq!(
        result_words(MavMissionResult::MAV_MISSION_UNSUPPORTED_FRAME),
        "MAV_MISSION_UNSUPPORTED_FRAME (coordinate frame not supported)"
    );
}

#[test]
fn clear_is_asked_again_until_acked() {
    let mut v = Vehicle {
        stored: vec![to_wire(0, &mission(1)[0], V, Kind::Mission).expect("wire")],
        ..Vehicle::default()
    };
    let mut m = ClearMachine::new(V, Kind::Mission, Duration::from_millis(20));
    let (out, _) = run(&mut m, &mut v, 0.3, 7);
    assert_eq!(out, Some(MavMissionResult::MAV_MISSION_ACCEPTED));
    assert!(v.stored.is_empty());
}

impl DownloadMachine {
    fn result_pending(&mut self) -> bool {
        match self.result() {
            Some(r) => {
                assert!(r.is_err());
                false
            }
            None => true,
        }
    }
}
