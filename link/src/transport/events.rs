//! What links report to their owner (ids, events), and where: a queue read by an owner task, or
//! a handler the link tasks call inline.

use std::fmt;
use std::sync::Arc;
use std::sync::atomic::{AtomicU32, Ordering};

use tokio::sync::mpsc;
use tokio_util::sync::CancellationToken;

use super::LinkSender;
use crate::frame::Frame;

/// Identifies one link for the life of the process (unique across all endpoints).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub struct LinkId(pub u32);

impl LinkId {
    /// A fresh id from the process-wide counter (starts at 1).
    pub fn next() -> LinkId {
        static NEXT: AtomicU32 = AtomicU32::new(1);
        LinkId(NEXT.fetch_add(1, Ordering::Relaxed))
    }
}

impl fmt::Display for LinkId {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "link#{}", self.0)
    }
}

/// What links report to their owner.
#[derive(Debug)]
pub enum LinkEvent {
    /// A link is connected. `tx` is its egress queue; it closes when the link goes down.
    Up {
        /// The link.
        id: LinkId,
        /// Human-readable peer (`tcp 127.0.0.1:5760`, `udp 10.0.0.2:14550`, device path).
        peer: String,
        /// Bounded egress queue of this link (and its counters).
        tx: LinkSender,
    },
    /// A frame arrived on a link.
    Frame {
        /// The link it arrived on.
        id: LinkId,
        /// The frame, raw bytes as received.
        frame: Frame,
    },
    /// A link went away (EOF, I/O error, UDP silence, shutdown).
    Down {
        /// The link.
        id: LinkId,
        /// Why, for logs and the TUI.
        reason: String,
    },
}

/// Takes a link's events in the task that received them: no queue and no task hop between a
/// link and its owner. The owner (the daemon's router) routes each frame before the link task
/// reads its socket again.
///
/// Implementations must not block: they run inside the links' tasks.
pub trait LinkEventHandler: Send + Sync {
    /// Handles one event. False when the owner is gone: the link stops.
    fn event(&self, event: LinkEvent) -> bool;

    /// Handles the frames one wake-up of a link task received, in order, and empties `frames`.
    /// False when the owner is gone. The default hands them to [`LinkEventHandler::event`] one
    /// by one; an owner that can do better with a run (one lock, one batched send per egress
    /// link) overrides it.
    fn frames(&self, frames: &mut Vec<(LinkId, Frame)>) -> bool {
        for (id, frame) in frames.drain(..) {
            if !self.event(LinkEvent::Frame { id, frame }) {
                return false;
            }
        }
        true
    }

    /// True once the owner is gone for good (a reconnecting link then stops trying).
    fn is_closed(&self) -> bool {
        false
    }
}

/// Where links report their events: a bounded queue read by an owner task, or a handler called
/// inline by the link tasks. `From<mpsc::Sender<LinkEvent>>` makes a queue.
#[derive(Clone)]
pub enum Events {
    /// A bounded queue; a full queue makes the link wait (it is the owner's job to keep up).
    Queue(mpsc::Sender<LinkEvent>),
    /// A handler called from the link tasks.
    Inline(Arc<dyn LinkEventHandler>),
}

impl fmt::Debug for Events {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Events::Queue(tx) => f.debug_tuple("Queue").field(tx).finish(),
            Events::Inline(_) => f.write_str("Inline"),
        }
    }
}

impl From<mpsc::Sender<LinkEvent>> for Events {
    fn from(tx: mpsc::Sender<LinkEvent>) -> Self {
        Events::Queue(tx)
    }
}

impl From<Arc<dyn LinkEventHandler>> for Events {
    fn from(handler: Arc<dyn LinkEventHandler>) -> Self {
        Events::Inline(handler)
    }
}

impl Events {
    /// True once the owner is gone.
    pub fn is_closed(&self) -> bool {
        match self {
            Events::Queue(tx) => tx.is_closed(),
            Events::Inline(h) => h.is_closed(),
        }
    }
}

/// Sends an event unless shutting down; false if the link should stop.
pub(crate) async fn emit(events: &Events, event: LinkEvent, cancel: &CancellationToken) -> bool {
    let tx = match events {
        Events::Inline(h) => return h.event(event),
        Events::Queue(tx) => tx,
    };
    // The common case, room in the queue, needs no future and no select.
    let event = match tx.try_send(event) {
        Ok(()) => return true,
        Err(mpsc::error::TrySendError::Closed(_)) => return false,
        Err(mpsc::error::TrySendError::Full(event)) => event,
    };
    tokio::select! {
        biased;
        _ = cancel.cancelled() => false,
        r = tx.send(event) => r.is_ok(),
    }
}

/// Sends the frames of one wake-up, in order, and empties `frames`; false if the link should
/// stop.
pub(crate) async fn emit_frames(
    events: &Events,
    frames: &mut Vec<(LinkId, Frame)>,
    cancel: &CancellationToken,
) -> bool {
    if frames.is_empty() {
        return true;
    }
    if let Events::Inline(h) = events {
        return h.frames(frames);
    }
    for (id, frame) in frames.drain(..) {
        if !emit(events, LinkEvent::Frame { id, frame }, cancel).await {
            return false;
        }
    }
    true
}

/// Reports a link as down. During shutdown the owner may be gone or not reading, so do not
/// wait then.
pub(crate) async fn emit_down(
    events: &Events,
    id: LinkId,
    reason: String,
    cancel: &CancellationToken,
) {
    tracing::debug!(%id, %reason, "link down");
    let ev = LinkEvent::Down { id, reason };
    match events {
        Events::Inline(h) => {
            h.event(ev);
        }
        Events::Queue(tx) if cancel.is_cancelled() => {
            let _ = tx.try_send(ev);
        }
        Events::Queue(tx) => {
            let _ = tx.send(ev).await;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn link_ids_are_unique() {
        let a = LinkId::next();
        let b = LinkId::next();
        assert_ne!(a, b);
    }
}
