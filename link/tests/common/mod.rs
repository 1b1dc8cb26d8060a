//! Helpers shared by the transport tests: frames to send and event waits with upper bounds.

#![allow(dead_code)]

use std::time::Duration;

use tokio::sync::mpsc;
use vtol_link::{Frame, LinkEvent, LinkId, LinkSender};

/// Upper bound for any single wait; tests never sleep to wait for state.
pub const WAIT: Duration = Duration::from_secs(5);

/// A GCS heartbeat from `sys` with sequence `seq`.
pub fn hb(sys: u8, seq: u8) -> Frame {
    Frame::encode_v2(
        vtol_link::SystemId(sys),
        vtol_link::ComponentId(190),
        seq,
        &vtol_link::gcs_heartbeat(),
    )
}

/// Waits for the first event matching `pred`, skipping others.
pub async fn wait_for(
    rx: &mut mpsc::Receiver<LinkEvent>,
    what: &str,
    mut pred: impl FnMut(&LinkEvent) -> bool,
) -> LinkEvent {
    let fut = async {
        loop {
            match rx.recv().await {
                Some(ev) if pred(&ev) => return ev,
                Some(_) => continue,
                None => panic!("event channel closed while waiting for {what}"),
            }
        }
    };
    tokio::time::timeout(WAIT, fut)
        .await
        .unwrap_or_else(|_| panic!("timed out waiting for {what}"))
}

/// Waits for the next `Up` and returns its id, peer and queue.
pub async fn wait_up(rx: &mut mpsc::Receiver<LinkEvent>) -> (LinkId, String, LinkSender) {
    match wait_for(rx, "Up", |e| matches!(e, LinkEvent::Up { .. })).await {
        LinkEvent::Up { id, peer, tx } => (id, peer, tx),
        _ => unreachable!(),
    }
}

/// Waits for a frame on link `id`.
pub async fn wait_frame(rx: &mut mpsc::Receiver<LinkEvent>, id: LinkId) -> Frame {
    match wait_for(
        rx,
        "Frame",
        |e| matches!(e, LinkEvent::Frame { id: i, .. } if *i == id),
    )
    .await
    {
        LinkEvent::Frame { frame, .. } => frame,
        _ => unreachable!(),
    }
}

/// Waits for link `id` to go down and returns the reason.
pub async fn wait_down(rx: &mut mpsc::Receiver<LinkEvent>, id: LinkId) -> String {
    match wait_for(
        rx,
        "Down",
        |e| matches!(e, LinkEvent::Down { id: i, .. } if *i == id),
    )
    .await
    {
        LinkEvent::Down { reason, .. } => reason,
        _ => unreachable!(),
    }
}
