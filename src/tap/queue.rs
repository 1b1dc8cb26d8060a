//! The tracker's tap: the router hands over each run's frames under one lock, so neither side
//! pays a channel operation or a wake-up per frame. Bounded: what does not fit is dropped and
//! counted by the router.
//!
//! Where the frames are applied:
//! - **By the router's thread, inline** ([`TapReceiver::drain_inline`]): once a hand-off
//!   leaves the drain's run of frames waiting (32 for the tracker), the sender has them applied
//!   itself if the reader's state is free at that instant ([`Drain::try_apply`] never waits).
//!   This is the common case under traffic: the frames are applied on the CPU that just routed
//!   them, in the thread that allocated them, a run at a time (the state's maps stay warm from
//!   one frame to the next), and the reader is not woken.
//! - **By the reader, on its tick**: what was not applied inline (fewer than a run waited, or
//!   the reader's state was busy: being published, or read by the terminal UI) waits in the
//!   tap for the reader's next tick or for the sender's next run. A tap holding `wake_at`
//!   frames wakes its reader before its tick ([`TapReceiver::filling`]): the reader's work
//!   comes in short runs however slow its tick (a long run on a small machine holds a CPU that
//!   forwarding needs, and shows in its latency), and a burst is not dropped.
//!
//! Lock order: the reader's state (the tracker's core, then its history), then the tap. The
//! tap's lock is the innermost and is held only to move frames in or out (the router's run in
//! under the router's lock, every waiting frame out with one swap); nothing is decoded under
//! it. Whoever applies frames, the reader on its tick or a sender through the [`Drain`], first
//! holds the reader's state and only then swaps the waiting frames out of the tap
//! ([`Waiting::take`], [`TapReceiver::take`]), and decodes them after the tap's lock is
//! released: frames are applied in the order they were handed over, and a sender handing a
//! run over never waits on a decode. A drain takes the reader's state without waiting
//! (`try_lock`) so that a link's thread never waits for the tracker; with the order above,
//! waiting would be safe too.

use std::sync::{Arc, Mutex, MutexGuard, OnceLock, PoisonError};

use tokio::sync::Notify;

use super::Tapped;

/// Work on tapped frames that the sender may do itself, after handing a run over.
pub trait Drain: Send + Sync {
    /// Applies the frames `waiting` in the tap and returns `true` if that needs no waiting:
    /// when the state it applies them to is busy it returns `false` at once and leaves them.
    /// It takes them ([`Waiting::take`]) only while it holds that state, and applies them
    /// after the take (the tap's lock released).
    fn try_apply(&self, waiting: &Waiting<'_>) -> bool;
}

/// The frames waiting in a tap, as a [`Drain`] reaches them.
#[derive(Debug)]
pub struct Waiting<'a> {
    shared: &'a Shared,
}

impl Waiting<'_> {
    /// Moves every waiting frame, in order, into `into` under the tap's lock, released on
    /// return ([`TapReceiver::take`]).
    pub fn take(&self, into: &mut Vec<Tapped>) {
        self.shared.take(into);
    }
}

#[derive(Debug, Default)]
struct Queue {
    frames: Vec<Tapped>,
    /// The sender is gone: nothing more will come.
    closed: bool,
}

struct Shared {
    queue: Mutex<Queue>,
    /// Set by the reader: the sender applies the frames itself when it can and at least so
    /// many wait.
    drain: OnceLock<(Arc<dyn Drain>, usize)>,
    capacity: usize,
    wake_at: usize,
    /// Signalled once the queue holds `wake_at` frames.
    filling: Notify,
}

impl std::fmt::Debug for Shared {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Shared")
            .field("capacity", &self.capacity)
            .field("wake_at", &self.wake_at)
            .field("inline", &self.drain.get().is_some())
            .finish_non_exhaustive()
    }
}

impl Shared {
    fn lock(&self) -> MutexGuard<'_, Queue> {
        // Plain data: a panic elsewhere leaves it usable.
        self.queue.lock().unwrap_or_else(PoisonError::into_inner)
    }

    /// Moves every waiting frame, in order, into `into` (which should be empty: its buffer is
    /// given to the sender in exchange). `false` once the sender is gone and nothing is left.
    fn take(&self, into: &mut Vec<Tapped>) -> bool {
        let mut q = self.lock();
        if into.is_empty() {
            std::mem::swap(&mut q.frames, into);
        } else {
            into.append(&mut q.frames);
        }
        !(q.closed && into.is_empty())
    }
}

/// A tap holding at most `capacity` frames, whose reader is woken when `wake_at` wait: the
/// router's end and the tracker's.
#[must_use]
pub fn tap(capacity: usize, wake_at: usize) -> (TapSender, TapReceiver) {
    let capacity = capacity.max(1);
    let shared = Arc::new(Shared {
        queue: Mutex::new(Queue::default()),
        drain: OnceLock::new(),
        capacity,
        wake_at: wake_at.clamp(1, capacity),
        filling: Notify::new(),
    });
    (
        TapSender {
            shared: Arc::clone(&shared),
        },
        TapReceiver { shared },
    )
}

/// The router's end. Dropping it closes the tap.
#[derive(Debug)]
pub struct TapSender {
    shared: Arc<Shared>,
}

impl TapSender {
    /// Hands over `run` (emptied) in order, as much as the tap has room for, then applies
    /// everything waiting if it is enough for the reader's [`Drain`] and the drain can take it
    /// without waiting: returns how many frames were dropped for want of room (the newest).
    pub fn send_run(&self, run: &mut Vec<Tapped>) -> usize {
        let handed = self.hand_over(run);
        self.applier().apply_waiting(handed);
        handed.dropped
    }

    /// Hands over `run` (emptied) in order, as much as the tap has room for, and applies
    /// nothing: the router calls it under its lock, so frames enter the tap in the order they
    /// were routed, and applies them ([`TapApplier::apply_waiting`]) once its lock is released.
    /// When a run waits for the drain, waking the reader is left to that call too: the frames
    /// the sender applies itself wake nobody.
    pub fn hand_over(&self, run: &mut Vec<Tapped>) -> Handed {
        if run.is_empty() {
            return Handed::default();
        }
        let mut q = self.shared.lock();
        let before = q.frames.len();
        let room = self.shared.capacity.saturating_sub(before);
        let dropped = run.len().saturating_sub(room);
        run.truncate(run.len() - dropped);
        if q.frames.is_empty() {
            // Hand the buffer over whole; the tracker's empty one comes back on its next take.
            std::mem::swap(&mut q.frames, run);
        } else {
            q.frames.append(run);
        }
        let apply = self
            .shared
            .drain
            .get()
            .is_some_and(|(_, at_least)| q.frames.len() >= *at_least);
        let at = self.shared.wake_at;
        let wake = before < at && q.frames.len() >= at;
        drop(q);
        run.clear();
        if wake && !apply {
            self.shared.filling.notify_one();
        }
        Handed {
            dropped,
            apply,
            wake,
        }
    }

    /// What applies the waiting frames on the sender's side, outside the sender's own locks.
    #[must_use]
    pub fn applier(&self) -> TapApplier {
        TapApplier {
            shared: Arc::clone(&self.shared),
        }
    }
}

/// What became of a run handed to the tap ([`TapSender::hand_over`]).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct Handed {
    /// Frames dropped for want of room (the newest of the run).
    pub dropped: usize,
    /// A run waits for the reader's [`Drain`]: the sender should apply it
    /// ([`TapApplier::apply_waiting`]).
    pub apply: bool,
    /// The hand-over filled the tap to the reader's wake-up mark: the reader is woken unless
    /// the sender applies what waits.
    wake: bool,
}

/// Applies waiting frames through the reader's [`Drain`] from the sender's thread. Unlike the
/// [`TapSender`], holding one does not keep the tap open.
#[derive(Debug, Clone)]
pub struct TapApplier {
    shared: Arc<Shared>,
}

impl TapApplier {
    /// After `handed` ([`TapSender::hand_over`]): has the reader's [`Drain`] apply everything
    /// waiting if a run of it waited and the drain can take it without waiting; otherwise
    /// leaves it for a later run or the reader, waking the reader if the hand-over filled the
    /// tap. Called with no lock held: the drain takes the reader's state first and the tap's
    /// lock only to swap the frames out, so the decoding holds no lock a sender takes.
    pub fn apply_waiting(&self, handed: Handed) {
        if !handed.apply {
            return;
        }
        let Some((drain, _)) = self.shared.drain.get() else {
            return;
        };
        drain.try_apply(&Waiting {
            shared: &self.shared,
        });
        if handed.wake && self.shared.lock().frames.len() >= self.shared.wake_at {
            self.shared.filling.notify_one();
        }
    }
}

impl Drop for TapSender {
    fn drop(&mut self) {
        self.shared.lock().closed = true;
    }
}

/// The tracker's end.
#[derive(Debug)]
pub struct TapReceiver {
    shared: Arc<Shared>,
}

impl TapReceiver {
    /// Moves every waiting frame, in order, into `into` (which should be empty: its buffer is
    /// given to the sender in exchange). `false` once the sender is gone and nothing is left.
    pub fn take(&self, into: &mut Vec<Tapped>) -> bool {
        self.shared.take(into)
    }

    /// Lets the sender apply frames itself through `drain` when it can ([`Drain::try_apply`])
    /// and at least `at_least` of them wait: fewer wait for a later run or for the reader. The
    /// reader must then take the tap only while it holds the state `drain` applies to, so that
    /// frames are applied in order. A tap has one drain: a second is ignored.
    pub fn drain_inline(&self, drain: Arc<dyn Drain>, at_least: usize) {
        let _ = self.shared.drain.set((drain, at_least.max(1)));
    }

    /// Waits until the tap holds `wake_at` frames (at once if it got there since the last
    /// wait).
    pub async fn filling(&self) {
        self.shared.filling.notified().await;
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::links::Side;
    use vtol_link::{Frame, LinkId};

    fn tapped(seq: u8) -> Tapped {
        Tapped {
            link: LinkId(1),
            side: Side::Vehicle,
            frame: Frame::encode_v2(
                vtol_link::SystemId(1),
                vtol_link::ComponentId(1),
                seq,
                &vtol_link::gcs_heartbeat(),
            ),
            at: std::time::Instant::now(),
        }
    }

    fn seqs(v: &[Tapped]) -> Vec<u8> {
        v.iter().map(|t| t.frame.seq()).collect()
    }

    #[test]
    fn runs_arrive_in_order_and_the_overflow_is_counted() {
        let (tx, rx) = tap(5, 5);
        let mut run: Vec<_> = (0..3).map(tapped).collect();
        assert_eq!(tx.send_run(&mut run), 0);
        assert!(run.is_empty());
        let mut run: Vec<_> = (3..7).map(tapped).collect();
        // Room for two of the four: the two newest are dropped.
        assert_eq!(tx.send_run(&mut run), 2);
        let mut got = Vec::new();
        assert!(rx.take(&mut got));
        assert_eq!(seqs(&got), vec![0, 1, 2, 3, 4]);
        // Taken: room again.
        got.clear();
        let mut run = vec![tapped(9)];
        assert_eq!(tx.send_run(&mut run), 0);
        assert!(rx.take(&mut got));
        assert_eq!(seqs(&got), vec![9]);
    }

    #[tokio::test]
    async fn a_filling_tap_wakes_its_reader() {
        let (tx, rx) = tap(8, 4);
        tx.send_run(&mut (0..3).map(tapped).collect());
        let early = tokio::time::timeout(std::time::Duration::from_millis(50), rx.filling());
        assert!(early.await.is_err(), "three of eight frames wake nobody");
        tx.send_run(&mut vec![tapped(3)]);
        tokio::time::timeout(std::time::Duration::from_secs(5), rx.filling())
            .await
            .expect("the fourth frame wakes the reader");
        let mut got = Vec::new();
        rx.take(&mut got);
        assert_eq!(seqs(&got), vec![0, 1, 2, 3]);
    }

    #[test]
    fn a_dropped_sender_closes_the_tap_after_what_it_sent() {
        let (tx, rx) = tap(8, 8);
        tx.send_run(&mut vec![tapped(1)]);
        drop(tx);
        let mut got = Vec::new();
        assert!(rx.take(&mut got), "what was sent is still taken");
        assert_eq!(seqs(&got), vec![1]);
        got.clear();
        assert!(!rx.take(&mut got));
    }

    /// A drain that takes frames only while `open`, recording what it took.
    #[derive(Default)]
    struct Gate {
        open: std::sync::atomic::AtomicBool,
        took: Mutex<Vec<u8>>,
    }

    impl Drain for Gate {
        fn try_apply(&self, waiting: &Waiting<'_>) -> bool {
            if !self.open.load(std::sync::atomic::Ordering::Relaxed) {
                return false;
            }
            let mut took = self.took.lock().unwrap();
            let mut frames = Vec::new();
            waiting.take(&mut frames);
            took.extend(seqs(&frames));
            true
        }
    }

    /// A drain that records whether the tap's lock was free while it applied what it took.
    #[derive(Default)]
    struct Checks {
        applied: Mutex<Vec<(u8, bool)>>,
    }

    impl Drain for Checks {
        fn try_apply(&self, waiting: &Waiting<'_>) -> bool {
            let mut applied = self.applied.lock().unwrap();
            let mut frames = Vec::new();
            waiting.take(&mut frames);
            let tap_free = waiting.shared.queue.try_lock().is_ok();
            applied.extend(frames.iter().map(|t| (t.frame.seq(), tap_free)));
            true
        }
    }

    #[test]
    fn the_sender_applies_frames_with_the_tap_unlocked() {
        let (tx, rx) = tap(8, 8);
        let checks = Arc::new(Checks::default());
        rx.drain_inline(Arc::clone(&checks) as Arc<dyn Drain>, 2);
        tx.send_run(&mut (0..3).map(tapped).collect());
        assert_eq!(
            *checks.applied.lock().unwrap(),
            vec![(0, true), (1, true), (2, true)],
            "the frames were applied under the tap's lock, or not at all"
        );
    }

    #[test]
    fn the_sender_applies_nothing_until_a_run_waits() {
        let (tx, rx) = tap(8, 8);
        let gate = Arc::new(Gate::default());
        gate.open.store(true, std::sync::atomic::Ordering::Relaxed);
        rx.drain_inline(Arc::clone(&gate) as Arc<dyn Drain>, 3);
        tx.send_run(&mut (0..2).map(tapped).collect());
        assert!(
            gate.took.lock().unwrap().is_empty(),
            "two of a run of three were applied"
        );
        // The third makes a run: everything waiting is applied, in order.
        tx.send_run(&mut vec![tapped(2)]);
        assert_eq!(*gate.took.lock().unwrap(), vec![0, 1, 2]);
        // Fewer than a run wait for the reader, who takes them.
        tx.send_run(&mut vec![tapped(3)]);
        let mut got = Vec::new();
        assert!(rx.take(&mut got));
        assert_eq!(seqs(&got), vec![3]);
    }

    #[test]
    fn the_sender_applies_what_waits_when_the_drain_is_free_and_leaves_it_otherwise() {
        let (tx, rx) = tap(8, 4);
        let gate = Arc::new(Gate::default());
        rx.drain_inline(Arc::clone(&gate) as Arc<dyn Drain>, 1);
        // Busy: the run waits in the tap.
        tx.send_run(&mut (0..2).map(tapped).collect());
        assert!(gate.took.lock().unwrap().is_empty());
        // Free: the next run takes what waited first, in order, and nothing is left.
        gate.open.store(true, std::sync::atomic::Ordering::Relaxed);
        tx.send_run(&mut vec![tapped(2)]);
        assert_eq!(*gate.took.lock().unwrap(), vec![0, 1, 2]);
        let mut got = Vec::new();
        assert!(rx.take(&mut got));
        assert!(got.is_empty(), "left in the tap: {:?}", seqs(&got));
    }
}
