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

/// How far back the history reaches (the charts' window can be set up to this).
pub const KEEP: Duration = Duration::from_secs(120);
/// Most raw frames kept per message id and sender (82 s of a 50 Hz message).
pub const MAX_FRAMES: usize = 4096;
/// Most typed samples kept per series (120 s at 50 Hz).
const MAX_SAMPLES: usize = 6000;

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

/// Everything the charts can draw.
#[derive(Debug, Clone)]
pub struct History {
    /// Sample times count from here.
    pub epoch: Instant,
    /// Typed series per vehicle (system, component).
    pub vehicles: BTreeMap<(vtol_link::SystemId, vtol_link::ComponentId), VehicleHistory>,
    /// Raw frames per (system, component, message id).
    pub frames: HashMap<(vtol_link::SystemId, vtol_link::ComponentId, u32), VecDeque<TimedFrame>>,
    next_index: u64,
    /// The last arrival time recorded and its [`History::t_s`]: a tick's frames share one.
    last_at: Option<(Instant, f64)>,
}

fn push<T>(q: &mut VecDeque<Sample<T>>, t_s: f64, v: T) {
    let oldest = t_s - KEEP.as_secs_f64();
    while q.len() >= MAX_SAMPLES || q.front().is_some_and(|(t, _)| *t < oldest) {
        q.pop_front();
    }
    q.push_back((t_s, v));
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
        let key = frame.sender();
        let ring = self
            .frames
            .entry((key.0, key.1, frame.message_id()))
            .or_default();
        let oldest = t_s - KEEP.as_secs_f64();
        while ring.len() >= MAX_FRAMES || ring.front().is_some_and(|f| f.t_s < oldest) {
            ring.pop_front();
        }
        ring.push_back(TimedFrame {
            index: self.next_index,
            t_s,
            frame: frame.clone(),
        });
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
                let v = [
                    s.servo1_raw,
                    s.servo2_raw,
                    s.servo3_raw,
                    s.servo4_raw,
                    s.servo5_raw,
                    s.servo6_raw,
                    s.servo7_raw,
                    s.servo8_raw,
                ];
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

    #[test]
    fn keeps_a_bounded_recent_past() {
        let t0 = Instant::now();
        let mut h = History::new(t0);
        // 200 s at 50 Hz: only the last 120 s stay, and no more than the caps.
        for i in 0..10_000u64 {
            let msg = attitude(i as f32);
            let f = Frame::encode_v2(1, 1, (i % 256) as u8, &msg);
            h.record(&f, Some(&msg), t0 + Duration::from_millis(i * 20));
        }
        let att = &h.vehicles[&(vtol_link::SystemId(1), vtol_link::ComponentId(1))].attitude;
        let span = att.back().unwrap().0 - att.front().unwrap().0;
        assert!(span <= KEEP.as_secs_f64() + 1e-9, "span {span}");
        assert!(span > 110.0, "span {span}");
        assert_eq!(att.back().unwrap().1[0], 9999.0);
        let frames = &h.frames[&(vtol_link::SystemId(1), vtol_link::ComponentId(1), 30)];
        assert_eq!(frames.len(), MAX_FRAMES);
        assert_eq!(frames.back().unwrap().index, 9999);
    }
}
