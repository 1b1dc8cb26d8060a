//! Per-link counters.

use std::sync::atomic::{AtomicU64, Ordering};

use crate::decoder::DecodeStats;

/// Per-link counters, shared between the link task and its owner.
#[derive(Debug, Default)]
pub struct LinkStats {
    rx_frames: AtomicU64,
    rx_bytes: AtomicU64,
    tx_frames: AtomicU64,
    tx_bytes: AtomicU64,
    tx_dropped_queue_full: AtomicU64,
    tx_errors: AtomicU64,
    bad_crc: AtomicU64,
    garbage_bytes: AtomicU64,
    unknown_id: AtomicU64,
    bad_incompat: AtomicU64,
}

/// A copy of [`LinkStats`] at one instant.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct LinkStatsSnapshot {
    /// Frames received (verified and unverified).
    pub rx_frames: u64,
    /// Bytes received, garbage included.
    pub rx_bytes: u64,
    /// Frames written to the transport.
    pub tx_frames: u64,
    /// Bytes written to the transport.
    pub tx_bytes: u64,
    /// Frames refused because the egress queue was full (slow peer).
    pub tx_dropped_queue_full: u64,
    /// Frames lost to send errors (UDP only; stream errors end the link).
    pub tx_errors: u64,
    /// Received candidates with a bad CRC.
    pub bad_crc: u64,
    /// Received bytes skipped while resyncing.
    pub garbage_bytes: u64,
    /// Received frames with message ids the dialect does not know.
    pub unknown_id: u64,
    /// Received frames dropped for unknown incompat flags.
    pub bad_incompat: u64,
}

impl LinkStats {
    /// Reads every counter.
    pub fn snapshot(&self) -> LinkStatsSnapshot {
        let g = |a: &AtomicU64| a.load(Ordering::Relaxed);
        LinkStatsSnapshot {
            rx_frames: g(&self.rx_frames),
            rx_bytes: g(&self.rx_bytes),
            tx_frames: g(&self.tx_frames),
            tx_bytes: g(&self.tx_bytes),
            tx_dropped_queue_full: g(&self.tx_dropped_queue_full),
            tx_errors: g(&self.tx_errors),
            bad_crc: g(&self.bad_crc),
            garbage_bytes: g(&self.garbage_bytes),
            unknown_id: g(&self.unknown_id),
            bad_incompat: g(&self.bad_incompat),
        }
    }

    pub(crate) fn add_decode(&self, d: &DecodeStats) {
        let add = |a: &AtomicU64, v: u64| {
            if v != 0 {
                a.fetch_add(v, Ordering::Relaxed);
            }
        };
        add(&self.rx_frames, d.frames);
        add(&self.bad_crc, d.bad_crc);
        add(&self.garbage_bytes, d.garbage_bytes);
        add(&self.unknown_id, d.unknown_id);
        add(&self.bad_incompat, d.bad_incompat);
    }

    pub(crate) fn add_rx_bytes(&self, n: usize) {
        self.rx_bytes.fetch_add(n as u64, Ordering::Relaxed);
    }

    pub(crate) fn add_tx(&self, frames: usize, bytes: usize) {
        self.tx_frames.fetch_add(frames as u64, Ordering::Relaxed);
        self.tx_bytes.fetch_add(bytes as u64, Ordering::Relaxed);
    }

    pub(crate) fn add_tx_dropped_queue_full(&self) {
        self.tx_dropped_queue_full.fetch_add(1, Ordering::Relaxed);
    }

    pub(crate) fn add_tx_error(&self) {
        self.tx_errors.fetch_add(1, Ordering::Relaxed);
    }
}
