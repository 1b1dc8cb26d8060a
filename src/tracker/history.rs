//! The recent past the charts draw: attitude, PWM outputs and position per vehicle as typed
//! samples, and the raw frames of every message id, so any field of any message can be put on
//! a chart after the fact. Bounded in time and in count, so a flood cannot grow it without end.
//!
//! Shared with the UI behind a mutex ([`SharedHistory`]) instead of travelling in every
//! published snapshot: copying 30 s of samples 50 times a second would cost more than the UI.

use std::collections::{BTreeMap, VecDeque};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use foldhash::HashMap;
use vtol_link::Frame;
use vtol_link::dialect::MavMessage;

use super::state::servo_outputs;
use super::window::Stamp;

/// How far back the history reaches (the charts' window can be set up to this).
pub const KEEP: Duration = Duration::from_secs(120);
/// Most raw frames kept per message id and sender (82 s of a 50 Hz message).
pub const MAX_FRAMES: usize = 4096;
/// Most typed samples kept per series (120 s at 50 Hz).
const MAX_SAMPLES: usize = 6000;
/// Most bytes of raw frames kept per message id and sender: [`MAX_FRAMES`] of the longest.
const MAX_FRAME_BYTES: usize = MAX_FRAMES * vtol_link::frame::MAX_FRAME_LEN;
/// The smallest room a ring keeps.
const MIN_ROOM: usize = 16;

/// The history, shared by the tracker (writer) and the UI (reader).
pub type SharedHistory = Arc<Mutex<History>>;

/// One timed sample: seconds since the history's epoch, and the values.
pub type Sample<T> = (f64, T);

/// One vehicle's typed series.
#[derive(Debug, Clone, Default)]
pub struct VehicleHistory {
    /// Roll, pitch, yaw (rad) and their rates (rad/s).
    pub attitude: VecDeque<Sample<[f32; 6]>>,
    /// SERVO1..8 outputs, µs.
    pub servo: VecDeque<Sample<[u16; 8]>>,
    /// North, east, down position, m.
    pub position: VecDeque<Sample<[f32; 3]>>,
}

/// A raw frame with its arrival order (for incremental readers) and time.
#[derive(Debug, Clone)]
pub struct TimedFrame {
    /// Increases by one per recorded frame, across all message ids.
    pub index: u64,
    /// Seconds since the epoch.
    pub t_s: f64,
    /// The frame.
    pub frame: Frame,
}

/// Where one recorded frame's bytes are in its ring.
#[derive(Debug, Clone, Copy, Default)]
struct Slot {
    index: u64,
    t_s: f64,
    /// Position of the first byte, counted over every byte the ring ever took.
    start: u64,
    len: u32,
}

/// The recorded frames of one message id and sender, oldest first: their bytes back to back in
/// one ring, not the frames themselves.
///
/// A frame kept by reference would keep its allocation alive until it leaves the ring, 4 096
/// frames later: at 10 000 frames a second the tracker would then release, with an atomic
/// operation and a `free`, a frame that left every cache long ago, once per frame. Copied, a
/// frame's allocation is released as soon as routing, the tlog and the tracker are done with
/// it, and the ring's memory is written in order.
#[derive(Debug, Clone, Default)]
pub struct FrameRing {
    slots: VecDeque<Slot>,
    bytes: VecDeque<u8>,
    /// Position of `bytes[0]`, counted as [`Slot::start`] is.
    first_byte: u64,
}

impl FrameRing {
    /// Frames kept.
    #[must_use]
    pub fn len(&self) -> usize {
        self.slots.len()
    }

    /// Whether no frame is kept.
    #[must_use]
    pub fn is_empty(&self) -> bool {
        self.slots.is_empty()
    }

    /// Time of the oldest frame kept.
    #[must_use]
    pub fn oldest_t_s(&self) -> Option<f64> {
        self.slots.front().map(|s| s.t_s)
    }

    /// Index of the newest frame kept.
    #[must_use]
    pub fn newest_index(&self) -> Option<u64> {
        self.slots.back().map(|s| s.index)
    }

    /// The frames kept whose index is `index` or later, oldest first.
    pub fn since(&self, index: u64) -> impl Iterator<Item = TimedFrame> + '_ {
        let from = self.slots.partition_point(|s| s.index < index);
        self.slots.range(from..).filter_map(|s| {
            // Offsets of a slot kept are inside `bytes`: both rings drop from the front together.
            let at = usize::try_from(s.start - self.first_byte).ok()?;
            let bytes: Vec<u8> = self.bytes.range(at..at + s.len as usize).copied().collect();
            // The bytes were a whole frame when they were routed: this only wraps them again.
            let frame = Frame::from_bytes(bytes.into()).ok()?;
            Some(TimedFrame {
                index: s.index,
                t_s: s.t_s,
                frame,
            })
        })
    }

    /// Drops the frames older than `oldest` s and makes room for one more, then keeps `frame`.
    fn push(&mut self, index: u64, t_s: f64, oldest: f64, frame: &[u8]) {
        while self.slots.len() >= MAX_FRAMES || self.slots.front().is_some_and(|s| s.t_s < oldest) {
            let Some(gone) = self.slots.pop_front() else {
                break;
            };
            let n = gone.len as usize;
            self.bytes.drain(..n);
            self.first_byte += n as u64;
        }
        let len = u32::try_from(frame.len()).expect("a MAVLink frame is under 300 bytes");
        make_room(&mut self.slots, 1, MAX_FRAMES);
        make_room(&mut self.bytes, frame.len(), MAX_FRAME_BYTES);
        self.slots.push_back(Slot {
            index,
            t_s,
            start: self.first_byte + self.bytes.len() as u64,
            len,
        });
        self.bytes.extend(frame);
    }
}

/// Everything the charts can draw.
#[derive(Debug, Clone)]
pub struct History {
    /// Sample times count from here.
    pub epoch: Instant,
    /// Typed series per vehicle (system, component).
    pub vehicles: BTreeMap<(vtol_link::SystemId, vtol_link::ComponentId), VehicleHistory>,
    /// Raw frames per (system, component, message id).
    pub frames: HashMap<(vtol_link::SystemId, vtol_link::ComponentId, u32), FrameRing>,
    next_index: u64,
    /// The last arrival time recorded and its [`History::t_s`]: a tick's frames share one.
    last_at: Option<(Instant, f64)>,
}

fn push<T: Copy + Default>(q: &mut VecDeque<Sample<T>>, t_s: f64, v: T) {
    let oldest = t_s - KEEP.as_secs_f64();
    while q.len() >= MAX_SAMPLES || q.front().is_some_and(|(t, _)| *t < oldest) {
        q.pop_front();
    }
    make_room(q, 1, MAX_SAMPLES);
    q.push_back((t_s, v));
}

/// Gives a ring (already pruned) room for `more` items, sized by what it holds now, not by the
/// most it ever held, and never past `bound`; all of its room is written once when it is made.
///
/// A `VecDeque` doubles its buffer when full and never gives it back, and a ring that holds
/// fewer items than its buffer walks through the whole buffer as it goes round. With vehicles
/// coming and going, a vehicle's 120 s hold more or fewer samples from one minute to the next:
/// the buffers followed the most each had ever held, and the pages of their spare room became
/// resident one by one as the rings went round into them, so a daemon's resident memory rose
/// for minutes after its history held its full 120 s. Here a ring grows to half as much again as
/// it holds (and to its bound exactly), shrinks to that when it holds under half of its room, and
/// its room is resident from the start: resident memory follows what the history holds, and
/// is never more than twice it.
fn make_room<T: Copy + Default>(q: &mut VecDeque<T>, more: usize, bound: usize) {
    let (len, cap) = (q.len(), q.capacity());
    let need = len + more;
    let roomy = need + need / 2;
    let room = if need > cap {
        roomy.clamp(MIN_ROOM, bound.max(need))
    } else if cap > MIN_ROOM && need < cap / 2 {
        roomy.max(MIN_ROOM)
    } else {
        return;
    };
    if room > cap {
        q.reserve_exact(room - len);
    } else {
        q.shrink_to(room);
    }
    // Write the spare room once, so that its pages are resident now rather than when the ring
    // first goes round into them.
    let cap = q.capacity();
    q.resize(cap, T::default());
    q.truncate(len);
}

impl History {
    /// An empty history whose times count from `epoch`.
    #[must_use]
    pub fn new(epoch: Instant) -> Self {
        Self {
            epoch,
            vehicles: BTreeMap::new(),
            frames: HashMap::default(),
            next_index: 0,
            last_at: None,
        }
    }

    /// Seconds since the epoch.
    #[must_use]
    pub fn t_s(&self, at: Instant) -> f64 {
        at.saturating_duration_since(self.epoch).as_secs_f64()
    }

    /// Records a frame that arrived at `now`; `decoded` is the tracker's decode of it when it
    /// is a message of a known vehicle (attitude, outputs, position go to the typed series).
    pub fn record(&mut self, frame: &Frame, decoded: Option<&MavMessage>, now: Instant) {
        let t_s = match self.last_at {
            Some((at, t_s)) if at == now => t_s,
            _ => {
                let t_s = self.t_s(now);
                self.last_at = Some((now, t_s));
                t_s
            }
        };
        self.record_t(frame, decoded, t_s);
    }

    /// [`History::record`] at a time the tracker stamped already (one clock difference a frame
    /// for both).
    pub fn record_stamped(&mut self, frame: &Frame, decoded: Option<&MavMessage>, at: &Stamp) {
        if at.epoch() == self.epoch {
            self.record_t(frame, decoded, at.since_epoch_s());
        } else {
            self.record(frame, decoded, at.at());
        }
    }

    /// Bytes the history holds allocated (its rings' capacities).
    #[must_use]
    pub fn allocated_bytes(&self) -> usize {
        fn deque<T>(q: &VecDeque<T>) -> usize {
            q.capacity() * std::mem::size_of::<T>()
        }
        let typed: usize = self
            .vehicles
            .values()
            .map(|v| deque(&v.attitude) + deque(&v.servo) + deque(&v.position))
            .sum();
        let raw: usize = self
            .frames
            .values()
            .map(|r| deque(&r.slots) + deque(&r.bytes))
            .sum();
        typed + raw
    }

    fn record_t(&mut self, frame: &Frame, decoded: Option<&MavMessage>, t_s: f64) {
        let key = frame.sender();
        self.frames
            .entry((key.0, key.1, frame.message_id()))
            .or_default()
            .push(
                self.next_index,
                t_s,
                t_s - KEEP.as_secs_f64(),
                frame.as_bytes(),
            );
        self.next_index += 1;
        let Some(msg) = decoded else { return };
        match msg {
            MavMessage::ATTITUDE(a) => {
                let v = [
                    a.roll,
                    a.pitch,
                    a.yaw,
                    a.rollspeed,
                    a.pitchspeed,
                    a.yawspeed,
                ];
                push(&mut self.vehicles.entry(key).or_default().attitude, t_s, v);
            }
            MavMessage::SERVO_OUTPUT_RAW(s) => {
                let all = servo_outputs(s);
                let v: [u16; 8] = std::array::from_fn(|i| all[i]);
                push(&mut self.vehicles.entry(key).or_default().servo, t_s, v);
            }
            MavMessage::LOCAL_POSITION_NED(p) => {
                push(
                    &mut self.vehicles.entry(key).or_default().position,
                    t_s,
                    [p.x, p.y, p.z],
                );
            }
            _ => {}
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use vtol_link::dialect;

    fn attitude(roll: f32) -> MavMessage {
        MavMessage::ATTITUDE(dialect::ATTITUDE_DATA {
            time_boot_ms: 0,
            roll,
            pitch: 0.0,
            yaw: 0.0,
            rollspeed: 0.0,
            pitchspeed: 0.0,
            yawspeed: 0.0,
        })
    }

    /// Every ring's room against what it holds: at most twice as much, and its bound.
    fn assert_room_follows_content(h: &History) {
        let check = |what: &str, len: usize, cap: usize, bound: usize| {
            assert!(
                cap <= (2 * len).max(MIN_ROOM),
                "{what}: room {cap} for {len}"
            );
            assert!(cap <= bound, "{what}: room {cap} over its bound {bound}");
        };
        for v in h.vehicles.values() {
            check(
                "attitude",
                v.attitude.len(),
                v.attitude.capacity(),
                MAX_SAMPLES,
            );
            check("servo", v.servo.len(), v.servo.capacity(), MAX_SAMPLES);
        }
        for r in h.frames.values() {
            check("slots", r.slots.len(), r.slots.capacity(), MAX_FRAMES);
            check("bytes", r.bytes.len(), r.bytes.capacity(), MAX_FRAME_BYTES);
        }
    }

    #[test]
    fn memory_follows_what_is_held_as_a_vehicle_comes_and_goes() {
        let t0 = Instant::now();
        let mut h = History::new(t0);
        let servo = MavMessage::SERVO_OUTPUT_RAW(dialect::SERVO_OUTPUT_RAW_DATA {
            servo1_raw: 1500,
            ..Default::default()
        });
        let record = |h: &mut History, tick: u64| {
            let at = t0 + Duration::from_millis(tick * 20);
            let seq = (tick % 256) as u8;
            let id = (vtol_link::SystemId(1), vtol_link::ComponentId(1));
            let att = attitude(tick as f32);
            h.record(&Frame::encode_v2(id.0, id.1, seq, &att), Some(&att), at);
            if tick.is_multiple_of(5) {
                h.record(&Frame::encode_v2(id.0, id.1, seq, &servo), Some(&servo), at);
            }
        };
        // 150 s flying: 120 s of attitude (6 000 samples), outputs and their frames.
        for tick in 0..7500 {
            record(&mut h, tick);
        }
        assert_room_follows_content(&h);
        let full = h.allocated_bytes();
        // Then 240 s of coming and going: 1 s heard, 4 s away. Its 120 s hold a fifth as much,
        // and its memory follows (what a fleet's churn did: the rings kept the room of the most
        // they had ever held, 8 192 samples of attitude, while they held 1 200).
        for tick in 7500..19_500 {
            if tick % 250 < 50 {
                record(&mut h, tick);
            }
        }
        let att = &h.vehicles[&(vtol_link::SystemId(1), vtol_link::ComponentId(1))].attitude;
        assert!((1150..=1250).contains(&att.len()), "{}", att.len());
        assert_room_follows_content(&h);
        assert!(
            h.allocated_bytes() < full / 2,
            "{} of {full} bytes",
            h.allocated_bytes()
        );
    }

    #[test]
    fn keeps_a_bounded_recent_past() {
        let t0 = Instant::now();
        let mut h = History::new(t0);
        // 200 s at 50 Hz: only the last 120 s stay, and no more than the caps.
        for i in 0..10_000u64 {
            let msg = attitude(i as f32);
            let f = Frame::encode_v2(
                vtol_link::SystemId(1),
                vtol_link::ComponentId(1),
                (i % 256) as u8,
                &msg,
            );
            h.record(&f, Some(&msg), t0 + Duration::from_millis(i * 20));
        }
        let att = &h.vehicles[&(vtol_link::SystemId(1), vtol_link::ComponentId(1))].attitude;
        let span = att.back().unwrap().0 - att.front().unwrap().0;
        assert!(span <= KEEP.as_secs_f64() + 1e-9, "span {span}");
        assert!(span > 110.0, "span {span}");
        assert_eq!(att.back().unwrap().1[0], 9999.0);
        let frames = &h.frames[&(vtol_link::SystemId(1), vtol_link::ComponentId(1), 30)];
        assert_eq!(frames.len(), MAX_FRAMES);
        assert_eq!(frames.newest_index(), Some(9999));
        // The frames come back as they were recorded, and only from the index asked for.
        let back: Vec<TimedFrame> = frames.since(9998).collect();
        assert_eq!(back.len(), 2);
        assert_eq!(back[0].index, 9998);
        assert!((back[1].t_s - 199.98).abs() < 1e-9, "{}", back[1].t_s);
        let sent = Frame::encode_v2(
            vtol_link::SystemId(1),
            vtol_link::ComponentId(1),
            (9999 % 256) as u8,
            &attitude(9999.0),
        );
        assert_eq!(back[1].frame.as_bytes(), sent.as_bytes());
        assert_eq!(frames.since(0).count(), MAX_FRAMES);
    }

    #[test]
    fn frames_of_any_length_come_back_whole_after_the_oldest_left() {
        let t0 = Instant::now();
        let mut h = History::new(t0);
        let text = |i: usize| {
            let mut t = [0u8; 50];
            for (j, c) in t.iter_mut().take(i % 50).enumerate() {
                *c = b'a' + (j % 26) as u8;
            }
            MavMessage::STATUSTEXT(dialect::STATUSTEXT_DATA {
                severity: dialect::MavSeverity::MAV_SEVERITY_INFO,
                text: t.into(),
                ..Default::default()
            })
        };
        // One frame every 50 ms for 300 s: only the last 120 s stay (2 400 frames, under the
        // count cap), and their lengths differ frame to frame.
        let sent: Vec<Frame> = (0..6000)
            .map(|i| {
                Frame::encode_v2(
                    vtol_link::SystemId(1),
                    vtol_link::ComponentId(1),
                    (i % 256) as u8,
                    &text(i),
                )
            })
            .collect();
        for (i, f) in sent.iter().enumerate() {
            h.record(f, None, t0 + Duration::from_millis(i as u64 * 50));
        }
        let ring = &h.frames[&(vtol_link::SystemId(1), vtol_link::ComponentId(1), 253)];
        let kept: Vec<TimedFrame> = ring.since(0).collect();
        assert_eq!(kept.len(), ring.len());
        assert!((2399..=2401).contains(&kept.len()), "{}", kept.len());
        let first = 6000 - kept.len();
        for (k, f) in kept.iter().enumerate() {
            assert_eq!(f.index, (first + k) as u64);
            assert_eq!(
                f.frame.as_bytes(),
                sent[first + k].as_bytes(),
                "frame {}",
                first + k
            );
        }
        assert!(sent.iter().map(Frame::len).min() < sent.iter().map(Frame::len).max());
    }
}
