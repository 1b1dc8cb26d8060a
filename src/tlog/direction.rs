//! Which way a tlog record travelled, in logs of every ground station.
//!
//! MAVProxy and this daemon mark the direction in a record's timestamp: the low two bits are 3
//! for a frame sent towards the vehicle and 0 for one received from it. Mission Planner and
//! QGroundControl stamp plain microseconds, whose low two bits are arbitrary. A log follows
//! the link-bit convention when, over its first [`DETECT_RECORDS`] records, every record's
//! bits are 0 or 3 and 3 is never on a vehicle's frame (plain microseconds put 1 and 2 on half
//! the records and 3 on a quarter of the vehicle's). A 0 on a ground station's frame agrees
//! with the convention: MAVProxy stamps 0 on whatever its vehicle link brings, another ground
//! station's heartbeat routed to it included. Otherwise a record's direction is its sender's side: a ground station
//! (a heartbeat of MAV_TYPE_GCS; before any heartbeat, component 190 or system 255) sends
//! towards the vehicle, everything else comes from the vehicle's side.

use std::collections::HashMap;

use vtol_link::Frame;

/// Records read from the start of a log to decide its convention.
pub const DETECT_RECORDS: usize = 4096;

/// MAV_TYPE_GCS.
const MAV_TYPE_GCS: u8 = 6;
/// MAV_COMP_ID_MISSIONPLANNER: the component ground stations use.
const GCS_COMPONENT: u8 = 190;
/// The system id ground stations use.
const GCS_SYSTEM: u8 = 255;

/// How a log tells a record's direction.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Convention {
    /// The timestamp's low two bits (MAVProxy's and this daemon's logs).
    LinkBits,
    /// The sender (Mission Planner's, QGroundControl's, and any log whose bits disagree).
    Sender,
}

/// Reads each record's direction; feed it every record in order.
#[derive(Debug, Clone)]
pub struct Directions {
    convention: Convention,
    /// Whether each (system, component) that sent a heartbeat is a ground station.
    ground: HashMap<(u8, u8), bool>,
}

impl Directions {
    /// Decides the convention from the first records of a log (at most [`DETECT_RECORDS`]
    /// are read from `records`).
    pub fn detect(records: impl IntoIterator<Item = (u64, Frame)>) -> Self {
        let mut probe = Self {
            convention: Convention::Sender,
            ground: HashMap::new(),
        };
        let mut consistent = true;
        for (stamp, frame) in records.into_iter().take(DETECT_RECORDS) {
            let ground = probe.is_ground(&frame);
            consistent &= match stamp & 3 {
                0 => true,
                3 => ground || probe.is_vehicle_side_unknown(&frame),
                _ => false,
            };
            if !consistent {
                break;
            }
        }
        Self {
            convention: if consistent {
                Convention::LinkBits
            } else {
                Convention::Sender
            },
            ground: HashMap::new(),
        }
    }

    /// A reader of a log known to follow `convention`.
    #[must_use]
    pub fn with(convention: Convention) -> Self {
        Self {
            convention,
            ground: HashMap::new(),
        }
    }

    /// The log's convention.
    #[must_use]
    pub fn convention(&self) -> Convention {
        self.convention
    }

    /// Whether the record was sent towards the vehicle.
    pub fn to_vehicle(&mut self, stamp: u64, frame: &Frame) -> bool {
        match self.convention {
            Convention::LinkBits => stamp & 3 == 3,
            Convention::Sender => self.is_ground(frame),
        }
    }

    /// Whether the frame's sender is a ground station, learning from its heartbeat.
    fn is_ground(&mut self, frame: &Frame) -> bool {
        let key = (frame.system_id(), frame.component_id());
        if let Some((mav_type, _)) = frame.heartbeat_kind() {
            self.ground.insert(key, mav_type == MAV_TYPE_GCS);
        }
        self.ground
            .get(&key)
            .copied()
            .unwrap_or(key.1 == GCS_COMPONENT || key.0 == GCS_SYSTEM)
    }

    /// A sender marked 3 that is not known as a ground station passes the check only while
    /// it has sent no heartbeat (a client of a non-standard identity, whose heartbeat comes
    /// later); one that said it is a vehicle fails it.
    fn is_vehicle_side_unknown(&self, frame: &Frame) -> bool {
        !self
            .ground
            .contains_key(&(frame.system_id(), frame.component_id()))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use vtol_link::dialect::{self as apm, MavMessage};
    use vtol_link::{ComponentId, SystemId};

    fn beat(sys: u8, comp: u8, mavtype: apm::MavType) -> Frame {
        let msg = MavMessage::HEARTBEAT(apm::HEARTBEAT_DATA {
            mavtype,
            ..Default::default()
        });
        Frame::encode_v2(SystemId(sys), ComponentId(comp), 0, &msg)
    }

    fn attitude(sys: u8, comp: u8) -> Frame {
        let msg = MavMessage::ATTITUDE(apm::ATTITUDE_DATA::default());
        Frame::encode_v2(SystemId(sys), ComponentId(comp), 0, &msg)
    }

    /// A flight of a vehicle (1:1) and a ground station (255:190), stamped by `stamp(t, gcs)`.
    fn flight(stamp: impl Fn(u64, bool) -> u64) -> Vec<(u64, Frame)> {
        let mut out = Vec::new();
        for i in 0..200u64 {
            let t = 1_700_000_000_000_000 + i * 10_007;
            out.push((stamp(t, false), attitude(1, 1)));
            if i % 10 == 0 {
                out.push((
                    stamp(t + 1, false),
                    beat(1, 1, apm::MavType::MAV_TYPE_QUADROTOR),
                ));
                out.push((
                    stamp(t + 2, true),
                    beat(255, 190, apm::MavType::MAV_TYPE_GCS),
                ));
            }
        }
        out
    }

    fn count_to_vehicle(log: &[(u64, Frame)]) -> (Convention, usize) {
        let mut d = Directions::detect(log.iter().cloned());
        let n = log.iter().filter(|(s, f)| d.to_vehicle(*s, f)).count();
        (d.convention(), n)
    }

    #[test]
    fn mavproxy_link_bits_are_read() {
        let log = flight(|t, gcs| if gcs { t | 3 } else { t & !3 });
        assert_eq!(count_to_vehicle(&log), (Convention::LinkBits, 20));
    }

    /// QGroundControl's plain microseconds: a quarter of the vehicle's frames end in 3, and none
    /// of them is taken as sent towards the vehicle.
    #[test]
    fn plain_microseconds_fall_back_to_the_sender() {
        let log = flight(|t, _| t);
        assert!(log.iter().filter(|(s, _)| s & 3 == 3).count() > 40);
        assert_eq!(count_to_vehicle(&log), (Convention::Sender, 20));
    }

    /// MAVProxy's log: another ground station's frames, routed to it over the vehicle link,
    /// carry 0; its own carry 3. Still the convention.
    #[test]
    fn another_ground_stations_frames_from_the_vehicle_link_keep_the_convention() {
        let mut log = flight(|t, gcs| if gcs { t | 3 } else { t & !3 });
        log.push((
            1_700_000_100_000_000,
            beat(255, 0, apm::MavType::MAV_TYPE_GCS),
        ));
        assert_eq!(count_to_vehicle(&log), (Convention::LinkBits, 20));
    }

    /// Bits of 0 and 3 only, but on the wrong senders: not the convention.
    #[test]
    fn bits_that_disagree_with_the_sender_are_not_the_convention() {
        let log = flight(|t, gcs| if gcs { t & !3 } else { t | 3 });
        assert_eq!(count_to_vehicle(&log), (Convention::Sender, 20));
    }

    /// A ground station of another identity is known by its heartbeat.
    #[test]
    fn a_heartbeat_of_type_gcs_names_a_ground_station() {
        let log = vec![
            (0, beat(200, 42, apm::MavType::MAV_TYPE_GCS)),
            (5, attitude(200, 42)),
            (9, attitude(1, 1)),
        ];
        let (conv, n) = count_to_vehicle(&log);
        assert_eq!((conv, n), (Convention::Sender, 2));
    }
}
