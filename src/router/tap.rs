//! The tracker's tap: the router hands over each run's frames under one lock, and the tracker
//! takes everything waiting on its own tick, so neither side pays a channel operation or a
//! wake-up per frame. Bounded: what does not fit is dropped and counted by the router. A tap
//! holding `wake_at` frames wakes its reader before its tick ([`TapReceiver::filling`]): the
//! reader's work comes in short runs however slow its tick (a long run on a small machine
//! holds a CPU that forwarding needs, and shows in its latency), and a burst is not dropped.

use std::sync::{Arc, Mutex, MutexGuard, PoisonError};

use tokio::sync::Notify;

use super::Tapped;

#[derive(Debug, Default)]
struct Queue {
    frames: Vec<Tapped>,
    /// The sender is gone: nothing more will come.
    closed: bool,
}

#[derive(Debug)]
struct Shared {
    queue: Mutex<Queue>,
    capacity: usize,
    wake_at: usize,
    /// Signalled once the queue holds `wake_at` frames.
    filling: Notify,
}

impl Shared {
    fn lock(&self) -> MutexGuard<'_, Queue> {
        // Plain data: a panic elsewhere leaves it usable.
        self.queue.lock().unwrap_or_else(PoisonError::into_inner)
    }
}

/// A tap holding at most `capacity` frames, whose reader is woken when `wake_at` wait: the
/// router's end and the tracker's.
#[must_use]
pub fn tap(capacity: usize, wake_at: usize) -> (TapSender, TapReceiver) {
    let capacity = capacity.max(1);
    let shared = Arc::new(Shared {
        queue: Mutex::new(Queue::default()),
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
    /// Hands over `run` (emptied) in order, as much as the tap has room for: returns how many
    /// frames were dropped for want of room (the newest).
    pub fn send_run(&self, run: &mut Vec<Tapped>) -> usize {
        if run.is_empty() {
            return 0;
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
        let at = self.shared.wake_at;
        let wake = before < at && q.frames.len() >= at;
        drop(q);
        run.clear();
        if wake {
            self.shared.filling.notify_one();
        }
        dropped
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
        let mut q = self.shared.lock();
        if into.is_empty() {
            std::mem::swap(&mut q.frames, into);
        } else {
            into.append(&mut q.frames);
        }
        !(q.closed && into.is_empty())
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
    use crate::router::Side;
    use vtol_link::{Frame, LinkId};

    fn tapped(seq: u8) -> Tapped {
        Tapped {
            link: LinkId(1),
            side: Side::Vehicle,
            frame: Frame::encode_v2(1, 1, seq, &vtol_link::gcs_heartbeat()),
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
}
