//! What the frame path hands its consumers: a frame as the taps see it, the daemon's clock, and
//! the tracker's tap ([`queue`]) through which the router hands frames over. (Which side a link
//! is on, the live links and the router's counters are in [`crate::links`].)
//!
//! The router writes these; the tracker reads them. Nothing outside the daemon can name the
//! router (`tests/layers.rs`).

pub mod queue;

use std::time::Instant;

use vtol_link::{Frame, LinkId};

use crate::links::Side;

pub use queue::{Drain, Handed, TapApplier, TapReceiver, TapSender, Waiting, tap};

/// A frame as the taps see it.
#[derive(Debug, Clone)]
pub struct Tapped {
    /// Ingress link.
    pub link: LinkId,
    /// Its side.
    pub side: Side,
    /// The frame.
    pub frame: Frame,
    /// When the router took it (its run's time, on the router's [`clock`]).
    pub at: Instant,
}

/// The daemon's clock as a `std` instant, read by the router once per run: tokio's, which
/// the tracker reads too ([`crate::tracker::now`]), so a test that pauses tokio's clock moves
/// rate limits, system id ownership and the tracker together. (While nothing pauses it, it is
/// `std`'s `Instant::now`.)
#[must_use]
pub fn clock() -> Instant {
    tokio::time::Instant::now().into_std()
}
