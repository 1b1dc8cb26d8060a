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
//! process, still reads as one gap: nothing tells it from a loss until more frames come; the
//! first process's next frames then read as late ones and take that gap back.)
//!
//! A link that reorders or repeats datagrams (a radio's retries, a network path with jitter)
//! delivers frames behind the newest one. Each sequence remembers which of its last
//! [`MAX_STEP`] numbers arrived and which it counted lost: a frame counted lost that arrives
//! after all is late, and takes its loss back ([`Seen::Late`]); a number that already arrived,
//! with the same checksum and less than [`REPEAT_WINDOW_US`] before, is a repeat
//! ([`Seen::Repeat`]), neither received again nor lost. (The checksum tells a repeated datagram
//! from another process's frame under the same number; the time, from a restarted sender's
//! identical first frames.)

/// A sender heard again after this much silence starts a new session: gaps across a silence
/// (a restart, a link that came back) say nothing about frames lost.
pub const SESSION_GAP_US: u64 = 2_000_000;
/// The largest forward step that still continues a sequence (`MAX_STEP - 1` frames lost).
pub const MAX_STEP: u8 = 128;
/// A jump to 0 this short continues the sequence across its wrap rather than starting a new
/// session: frames around the wrap may come reordered or be lost.
const WRAP_SLACK: u8 = 4;
/// A frame identical to one that arrived less than this long before is a repeated datagram.
pub const REPEAT_WINDOW_US: u64 = 500_000;
/// Sequences kept per sender (processes sharing one identity).
const STREAMS: usize = 4;

/// What a frame was to its sender's sequence.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Seen {
    /// The newest frame of a sequence (or the first of a new session), with the frames lost
    /// just before it.
    Next {
        /// Frames missing between the previous one and it.
        lost: u32,
    },
    /// A frame counted lost that arrived after all: one loss taken back.
    Late,
    /// A number that already arrived: a repeated datagram.
    Repeat,
}

/// One sequence: its newest number, when heard (µs), and for the [`MAX_STEP`] numbers up to
/// the newest (bit `k` is `last - k`) which arrived and which were counted lost, and the
/// checksums and arrival times (µs) of those that arrived (by number modulo [`MAX_STEP`]).
#[derive(Debug, Clone, PartialEq, Eq)]
struct Stream {
    last: u8,
    heard: u64,
    arrived: u128,
    lost: u128,
    arrivals: Box<[(u16, u64); MAX_STEP as usize]>,
}

impl Stream {
    fn new(seq: u8, crc: Option<u16>, at_us: u64) -> Self {
        let mut s = Self {
            last: seq,
            heard: at_us,
            arrived: 1,
            lost: 0,
            arrivals: Box::new([(0, 0); MAX_STEP as usize]),
        };
        s.keep(seq, crc, at_us);
        s
    }

    fn keep(&mut self, seq: u8, crc: Option<u16>, at_us: u64) {
        self.arrivals[usize::from(seq % MAX_STEP)] = (crc.unwrap_or(0), at_us);
    }

    /// Moves on to `seq`, `step` ahead: the numbers skipped are counted lost.
    fn advance(&mut self, seq: u8, crc: Option<u16>, step: u8, at_us: u64) {
        self.keep(seq, crc, at_us);
        let shift = u32::from(step);
        self.arrived = self.arrived.checked_shl(shift).unwrap_or(0) | 1;
        // Bits 1..step: the numbers between the previous newest and `seq`.
        let skipped = 1u128.checked_shl(shift).map_or(u128::MAX, |b| b - 1) & !1;
        self.lost = self.lost.checked_shl(shift).unwrap_or(0) | skipped;
        self.last = seq;
        self.heard = at_us;
    }

    /// Whether the frame numbered `seq`, `back` behind the newest, was counted lost, or arrived
    /// already, recently (with the same checksum, when one is given).
    fn knows(&self, seq: u8, crc: Option<u16>, back: u8, at_us: u64) -> bool {
        let bit = 1u128 << back;
        let (was, when) = self.arrivals[usize::from(seq % MAX_STEP)];
        self.lost & bit != 0
            || (self.arrived & bit != 0
                && crc.is_none_or(|c| was == c)
                && at_us.saturating_sub(when) < REPEAT_WINDOW_US)
    }

    /// The frame numbered `seq`, `back` behind the newest, which [`Stream::knows`]: late or a
    /// repeat.
    fn behind(&mut self, seq: u8, crc: Option<u16>, back: u8, at_us: u64) -> Seen {
        let bit = 1u128 << back;
        self.heard = at_us;
        if self.arrived & bit != 0 {
            Seen::Repeat
        } else {
            self.lost &= !bit;
            self.arrived |= bit;
            self.keep(seq, crc, at_us);
            Seen::Late
        }
    }
}

/// One sender's sequences.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct SenderSeq {
    streams: Vec<Stream>,
}

impl SenderSeq {
    /// Takes a frame numbered `seq` heard at `at_us` (any clock in µs that does not go back);
    /// returns the frames lost just before it (0 for a late or repeated frame).
    pub fn observe(&mut self, seq: u8, at_us: u64) -> u32 {
        match self.see(seq, None, at_us) {
            Seen::Next { lost } => lost,
            Seen::Late | Seen::Repeat => 0,
        }
    }

    /// Takes a frame numbered `seq` with checksum `crc` heard at `at_us`: what it was to its
    /// sequence. A frame belongs to the sequence it lies nearest to: a few numbers ahead of one
    /// (its next frame), or behind one that counted it lost or saw it arrive (late or
    /// repeated). Without a checksum, any frame under a number that arrived is a repeat.
    pub fn see(&mut self, seq: u8, crc: Option<u16>, at_us: u64) -> Seen {
        self.streams
            .retain(|s| at_us.saturating_sub(s.heard) < SESSION_GAP_US);
        let ahead = self
            .streams
            .iter()
            .enumerate()
            .filter_map(|(i, s)| {
                let step = seq.wrapping_sub(s.last);
                // A restart numbers from 0: a jump to 0 is a new session, not a loss (unless
                // it is a wrap with a frame or two reordered or lost around it).
                let continues =
                    step == 1 || (step > 1 && step <= MAX_STEP && (seq != 0 || step <= WRAP_SLACK));
                continues.then_some((step, i))
            })
            .min();
        let behind = self
            .streams
            .iter()
            .enumerate()
            .filter_map(|(i, s)| {
                let back = s.last.wrapping_sub(seq);
                (back < MAX_STEP && s.knows(seq, crc, back, at_us)).then_some((back, i))
            })
            .min();
        match (ahead, behind) {
            (_, Some((back, i))) if ahead.is_none_or(|(step, _)| back < step) => {
                self.streams[i].behind(seq, crc, back, at_us)
            }
            (Some((step, i)), _) => {
                self.streams[i].advance(seq, crc, step, at_us);
                Seen::Next {
                    lost: u32::from(step - 1),
                }
            }
            _ => {
                if self.streams.len() == STREAMS
                    && let Some(oldest) = (0..STREAMS).min_by_key(|&i| self.streams[i].heard)
                {
                    self.streams.swap_remove(oldest);
                }
                self.streams.push(Stream::new(seq, crc, at_us));
                Seen::Next { lost: 0 }
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

    fn seen(frames: &[(u8, u64)]) -> Vec<Seen> {
        let mut s = SenderSeq::default();
        frames
            .iter()
            .map(|&(seq, at)| s.see(seq, None, at))
            .collect()
    }

    #[test]
    fn a_late_frame_takes_its_loss_back_and_a_repeat_counts_nothing() {
        use Seen::{Late, Next, Repeat};
        assert_eq!(
            seen(&[(10, 0), (12, 1), (11, 2), (13, 3), (13, 4), (11, 5)]),
            [
                Next { lost: 0 },
                Next { lost: 1 },
                Late,
                Next { lost: 0 },
                Repeat,
                Repeat
            ]
        );
        // Across the wrap, and far behind (127 numbers) but still remembered.
        assert_eq!(
            seen(&[(254, 0), (1, 1), (255, 2), (0, 3)]),
            [Next { lost: 0 }, Next { lost: 2 }, Late, Late]
        );
        let mut far = vec![(0u8, 0u64), (1, 1)];
        far.extend((3..=128u8).map(|q| (q, u64::from(q))));
        far.push((2, 200));
        let got = seen(&far);
        assert_eq!(got[2], Next { lost: 1 });
        assert_eq!(got.last(), Some(&Late));
    }

    /// Every frame of a sequence that a link reorders by a few places and repeats now and then
    /// is either counted once or its loss taken back: the net loss is what the link dropped.
    #[test]
    fn reordered_and_repeated_frames_net_to_the_real_loss() {
        let mut sent: Vec<u32> = (0..2000).filter(|i| i % 10 != 3).collect();
        // Swap neighbours every 7 frames, and repeat every 20th.
        for i in (0..sent.len() - 1).step_by(7) {
            sent.swap(i, i + 1);
        }
        let mut frames = Vec::new();
        for (k, &i) in sent.iter().enumerate() {
            let (seq, crc) = (u8::try_from(i % 256).unwrap(), Some(i as u16 ^ 0x5a5a));
            frames.push((seq, crc, u64::from(i) * 1000));
            if k % 20 == 0 {
                frames.push((seq, crc, u64::from(i) * 1000 + 1));
            }
        }
        let mut s = SenderSeq::default();
        let (mut lost, mut late, mut received, mut repeats) = (0i64, 0i64, 0i64, 0);
        for &(seq, crc, at) in &frames {
            match s.see(seq, crc, at) {
                Seen::Next { lost: l } => {
                    lost += i64::from(l);
                    received += 1;
                }
                Seen::Late => {
                    late += 1;
                    received += 1;
                }
                Seen::Repeat => repeats += 1,
            }
        }
        assert_eq!(received, sent.len() as i64);
        assert_eq!(lost - late, 200, "{lost} counted lost, {late} late");
        assert_eq!(repeats, sent.len().div_ceil(20));
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
        // With their checksums, no frame of either reads as a repeat of the other's.
        let mut s = SenderSeq::default();
        let repeats = frames
            .iter()
            .enumerate()
            .filter(|&(k, &(seq, at))| s.see(seq, Some(k as u16), at) == Seen::Repeat)
            .count();
        assert_eq!(repeats, 0);
    }
}
