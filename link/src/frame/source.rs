//! One sender's stream of frames: the sequence number each frame takes in turn.

use super::Frame;
use crate::dialect::MavMessage;
use crate::ids::{ComponentId, SystemId};

/// A sender (system and component) and the sequence number of its next frame; each frame it
/// builds takes the next number, wrapping after 255, as MAVLink's per-sender counter does.
#[derive(Debug, Clone)]
pub struct FrameSource {
    system_id: SystemId,
    component_id: ComponentId,
    next_seq: u8,
}

impl FrameSource {
    /// A sender whose first frame has sequence number 0.
    #[must_use]
    pub fn new(system_id: SystemId, component_id: ComponentId) -> Self {
        Self {
            system_id,
            component_id,
            next_seq: 0,
        }
    }

    /// The next frame of this sender: `msg` in MAVLink 2, unsigned (see [`Frame::encode_v2`]).
    pub fn encode_v2(&mut self, msg: &MavMessage) -> Frame {
        let seq = self.next_seq;
        self.next_seq = seq.wrapping_add(1);
        Frame::encode_v2(self.system_id, self.component_id, seq, msg)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn each_frame_takes_the_next_sequence_number_and_it_wraps() {
        let mut source = FrameSource::new(SystemId(7), ComponentId(1));
        let msg = crate::frame::gcs_heartbeat();
        let seqs: Vec<u8> = (0..258).map(|_| source.encode_v2(&msg).seq()).collect();
        assert_eq!(&seqs[..3], [0, 1, 2]);
        assert_eq!(&seqs[255..], [255, 0, 1]);
        let f = source.encode_v2(&msg);
        assert_eq!((f.system_id(), f.component_id()), (7, 1));
    }
}
