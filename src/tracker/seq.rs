//! Sequence accounting per sender that tells loss from a new session.
//!
//! A MAVLink sender numbers its frames 0..=255 and wraps. Counting `seq - last - 1` as lost
//! frames turns every new session into a phantom loss of up to 255 frames: a restarted vehicle
//! or client starting again at 0, two frames both numbered 0, or two processes sending under
//! one (system, component) identity, whose sequences interleave. Here each sender keeps a few
//! sequences at once; a frame continues the one it follows most closely, and a frame that
//! follows none (a step back, a repeat, a jump of more than [`MAX_STEP`], a jump to 0, or the
//! first after [`SESSION_GAP_US`] of silence) starts a new session and counts no loss. (A
//! second process's very first frame, when it lies less than [`MAX_STEP`] ahead of the first
//! process, still reads as one gap: nothing tells it from a loss until more frames come.)

/// A sender heard again after this much silence starts a new session: gaps across a silence
/// (a restart, a link that came back) say nothing about frames lost.
pub const SESSION_GAP_US: u64 = 2_000_000;
/// The largest forward step that still continues a sequence (`MAX_STEP - 1` frames lost).
pub const MAX_STEP: u8 = 128;
/// Sequences kept per sender (processes sharing one identity).
const STREAMS: usize = 4;

/// One sender's sequences: (last sequence number, when heard in µs).
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct SenderSeq {
    streams: Vec<(u8, u64)>,
}

impl SenderSeq {
    /// Takes a frame numbered `seq` heard at `at_us` (any clock in µs that does not go back);
    /// returns the frames lost just before it.
    pub fn observe(&mut self, seq: u8, at_us: u64) -> u32 {
        self.streams
            .retain(|&(_, heard)| at_us.saturating_sub(heard) < SESSION_GAP_US);
        let best = self
            .streams
            .iter()
            .enumerate()
            .filter_map(|(i, &(last, _))| {
                let step = seq.wrapping_sub(last);
                // A restart numbers from 0: a jump to 0 is a new session, not a loss.
                let continues = step == 1 || (step > 1 && step <= MAX_STEP && seq != 0);
                continues.then_some((step, i))
            })
            .min();
        match best {
            Some((step, i)) => {
                self.streams[i] = (seq, at_us);
                u32::from(step - 1)
            }
            None => {
                if self.streams.len() == STREAMS
                    && let Some(oldest) = (0..STREAMS).min_by_key(|&i| self.streams[i].1)
                {
                    self.streams.swap_remove(oldest);
                }
                self.streams.push((seq, at_us));
                0
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn lost(frames: &[(u8, u64)]) -> u32 {
        let mut s = SenderSeq::default();
        frames.iter().map(|&(seq, at)| s.observe(seq, at)).sum()
    }

    #[test]
    fn real_gaps_and_wraps_are_counted() {
        assert_eq!(lost(&[(10, 0), (11, 1), (15, 2)]), 3);
        assert_eq!(lost(&[(254, 0), (255, 1), (1, 2)]), 1);
    }

    #[test]
    fn a_restart_counts_nothing() {
        // Numbered from 0 again, right away or after a silence.
        assert_eq!(lost(&[(200, 0), (201, 1), (0, 2), (1, 3)]), 0);
        assert_eq!(lost(&[(100, 0), (101, 1), (0, 500_000), (1, 500_001)]), 0);
        assert_eq!(lost(&[(50, 0), (60, 3_000_000)]), 0);
    }

    #[test]
    fn first_two_frames_both_zero_count_nothing() {
        assert_eq!(lost(&[(0, 0), (0, 1), (1, 2), (2, 3)]), 0);
    }

    /// The second process's first frame looks like a jump forward (it cannot be told from a
    /// loss until more come); after it, the two sequences are counted apart. Counted as one
    /// sequence, every frame of either would count as a gap: 300 × 96 and 300 × 158.
    #[test]
    fn two_processes_sharing_an_identity_cost_at_most_their_first_step() {
        let mut frames = Vec::new();
        for i in 0..600u64 {
            let seq = u8::try_from(i / 2 % 256).unwrap();
            let other = seq.wrapping_add(97);
            frames.push((if i % 2 == 0 { seq } else { other }, i * 1000));
        }
        assert!(lost(&frames) <= 96, "{}", lost(&frames));
    }
}
