//! The egress side of a link: its bounded queue, what the router hands it, and the batches its
//! writer takes.

use std::fmt;
use std::sync::Arc;
use std::sync::atomic::Ordering;

use tokio::sync::mpsc;

use super::{DirectUdp, LinkStats};
use crate::frame::Frame;

/// Why [`LinkSender::try_send`] refused a frame.
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
pub enum SendError {
    /// The queue is full: the frame was dropped and counted.
    #[error("egress queue full, frame dropped")]
    Full,
    /// The link is down.
    #[error("link is down")]
    Closed,
}

/// What became of the frames handed to [`LinkSender::try_send_many`].
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct SendSummary {
    /// Sent, or queued for the link's writer.
    pub taken: usize,
    /// Dropped because the queue was full (also counted in the link's `tx_dropped_queue_full`).
    pub full: usize,
    /// Lost because the link is down.
    pub closed: usize,
    /// Not wanted by the link ([`LinkOptions::accept`]).
    pub filtered: usize,
}

impl std::ops::AddAssign for SendSummary {
    fn add_assign(&mut self, o: Self) {
        self.taken += o.taken;
        self.full += o.full;
        self.closed += o.closed;
        self.filtered += o.filtered;
    }
}

/// Which frames a link takes, for an in-process consumer that reads only a few message types
/// (the daemon's own client): the others are never copied to it.
#[derive(Clone)]
pub struct EgressFilter(Arc<dyn Fn(&Frame) -> bool + Send + Sync>);

impl EgressFilter {
    /// A filter that takes the frames for which `accepts` is true.
    pub fn new(accepts: impl Fn(&Frame) -> bool + Send + Sync + 'static) -> Self {
        EgressFilter(Arc::new(accepts))
    }

    /// Whether the link takes `frame`.
    pub fn accepts(&self, frame: &Frame) -> bool {
        (self.0)(frame)
    }
}

impl fmt::Debug for EgressFilter {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str("EgressFilter")
    }
}

/// The egress side of one link: a bounded queue plus the link's counters.
///
/// `try_send` never waits, so one slow peer cannot stall the router; a full queue drops the
/// frame and counts it in `tx_dropped_queue_full`. A UDP peer whose writer has nothing queued
/// gets its datagrams from the caller's task at once, without a task hop.
#[derive(Debug, Clone)]
pub struct LinkSender {
    tx: mpsc::Sender<Frame>,
    stats: Arc<LinkStats>,
    direct: Option<Arc<DirectUdp>>,
    accept: Option<EgressFilter>,
}

impl LinkSender {
    pub(crate) fn new(
        tx: mpsc::Sender<Frame>,
        stats: Arc<LinkStats>,
        accept: Option<EgressFilter>,
    ) -> Self {
        LinkSender {
            tx,
            stats,
            direct: None,
            accept,
        }
    }

    pub(crate) fn with_direct_udp(
        tx: mpsc::Sender<Frame>,
        stats: Arc<LinkStats>,
        accept: Option<EgressFilter>,
        direct: Arc<DirectUdp>,
    ) -> Self {
        LinkSender {
            tx,
            stats,
            direct: Some(direct),
            accept,
        }
    }

    /// Whether the link wants `frame` ([`LinkOptions::accept`]); what it does not want is
    /// dropped by the sending calls and counted as filtered.
    pub fn accepts(&self, frame: &Frame) -> bool {
        self.accept.as_ref().is_none_or(|a| a.accepts(frame))
    }

    /// The UDP peer to send to directly, when its writer has nothing queued (so order holds).
    fn direct_now(&self) -> Option<&DirectUdp> {
        self.direct
            .as_deref()
            .filter(|d| d.queued.load(Ordering::Acquire) == 0 && !self.tx.is_closed())
    }

    /// Queues a frame without waiting; a full queue drops it (counted). A UDP peer whose
    /// writer is idle gets the datagram at once, from the caller's task. A frame the link does
    /// not take ([`LinkOptions::accept`]) is dropped and reported as sent.
    pub fn try_send(&self, frame: Frame) -> Result<(), SendError> {
        if !self.accepts(&frame) {
            return Ok(());
        }
        if let Some(d) = self.direct_now()
            && d.try_send_now(&frame, &self.stats).is_some()
        {
            return Ok(());
        }
        self.try_send_queued(frame)
    }

    /// Sends a run of frames, in order, without waiting, and empties `frames`: to a UDP peer
    /// whose writer is idle in as few system calls as the kernel allows (`sendmmsg`), the rest
    /// (the socket buffer full, or another kind of link) through the queue.
    pub fn try_send_many(&self, frames: &mut Vec<Frame>) -> SendSummary {
        let mut summary = SendSummary::default();
        if self.accept.is_some() {
            let before = frames.len();
            frames.retain(|f| self.accepts(f));
            summary.filtered = before - frames.len();
        }
        let mut start = 0;
        if let Some(d) = self.direct_now() {
            start = d.try_send_now_many(frames, &self.stats);
            summary.taken += start;
        }
        for frame in frames.drain(start..) {
            match self.try_send_queued(frame) {
                Ok(()) => summary.taken += 1,
                Err(SendError::Full) => summary.full += 1,
                Err(SendError::Closed) => summary.closed += 1,
            }
        }
        frames.clear();
        summary
    }

    /// Like [`LinkSender::try_send`] but always through the queue, so the link's own writer
    /// task does the I/O.
    pub fn try_send_queued(&self, frame: Frame) -> Result<(), SendError> {
        self.note_queued(1);
        match self.tx.try_send(frame) {
            Ok(()) => Ok(()),
            Err(mpsc::error::TrySendError::Full(_)) => {
                self.note_queued(-1);
                self.stats.add_tx_dropped_queue_full();
                Err(SendError::Full)
            }
            Err(mpsc::error::TrySendError::Closed(_)) => {
                self.note_queued(-1);
                Err(SendError::Closed)
            }
        }
    }

    fn note_queued(&self, delta: isize) {
        if let Some(d) = &self.direct {
            if delta > 0 {
                d.queued.fetch_add(1, Ordering::AcqRel);
            } else {
                d.queued.fetch_sub(1, Ordering::AcqRel);
            }
        }
    }

    /// Queues a frame, waiting for room (for traffic that must not be dropped, e.g. a
    /// vehicle's replies on an in-memory link). Errors only if the link is down.
    pub async fn send(&self, frame: Frame) -> Result<(), SendError> {
        if !self.accepts(&frame) {
            return Ok(());
        }
        if let Some(d) = self.direct_now()
            && d.try_send_now(&frame, &self.stats).is_some()
        {
            return Ok(());
        }
        self.note_queued(1);
        let r = self.tx.send(frame).await.map_err(|_| SendError::Closed);
        if r.is_err() {
            self.note_queued(-1);
        }
        r
    }

    /// Free places in the egress queue now: a producer with traffic of two priorities sheds
    /// the lower one before the queue is full.
    pub fn room(&self) -> usize {
        self.tx.capacity()
    }

    /// True once the link is down.
    pub fn is_closed(&self) -> bool {
        self.tx.is_closed()
    }

    /// Completes when the link is down (its queue's receiver is gone).
    pub async fn closed(&self) {
        self.tx.closed().await
    }

    /// The link's counters.
    pub fn stats(&self) -> &Arc<LinkStats> {
        &self.stats
    }
}

/// Starts `batch` with `first` and appends the frames already queued behind it, up to
/// `max_bytes` (one write of a stream, one publication): returns how many frames it holds.
pub(crate) fn take_batch(
    first: &Frame,
    rx: &mut mpsc::Receiver<Frame>,
    batch: &mut Vec<u8>,
    max_bytes: usize,
) -> usize {
    batch.clear();
    batch.extend_from_slice(first.as_bytes());
    let mut frames = 1;
    while batch.len() < max_bytes {
        match rx.try_recv() {
            Ok(f) => {
                batch.extend_from_slice(f.as_bytes());
                frames += 1;
            }
            Err(_) => break,
        }
    }
    frames
}
