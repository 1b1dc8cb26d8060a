//! What every consumer of the frame path shares: which side a link is on, the live links as
//! the status line and the UI show them, a frame as the taps see it, the daemon's clock, and the
//! tracker's tap ([`queue`]) through which the router hands frames over.
//!
//! The router writes these; the tracker, the client, the status line and the UI read them. None
//! of them imports the router (`tests/layers.rs`).

pub mod queue;

use std::sync::Arc;
use std::time::Instant;

use vtol_link::{Frame, LinkId, LinkStats, SystemId};

use crate::trust::policy::{EndpointPolicy, PolicyCounters};

pub use queue::{Drain, Handed, TapApplier, TapReceiver, TapSender, tap};

/// Which side of the daemon a link is on.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Side {
    /// The vehicle link.
    Vehicle,
    /// A client: script, ground station, or the daemon itself.
    Client,
}

/// One live link, as the status line and the TUI show it.
#[derive(Debug, Clone)]
pub struct LinkInfo {
    /// The link.
    pub id: LinkId,
    /// Vehicle or client side.
    pub side: Side,
    /// Peer description.
    pub peer: String,
    /// Its counters (rx/tx frames and bytes, queue-full drops, decode errors).
    pub stats: Arc<LinkStats>,
    /// Its endpoint's policy.
    pub policy: EndpointPolicy,
    /// What the policy did to its traffic (rate-limit drops, read-only refusals, signed).
    pub policy_counters: Arc<PolicyCounters>,
}

/// A system id claimed by two vehicle links: the owner keeps it, the claimant's frames under
/// that id go nowhere while both are up.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord)]
pub struct SysidConflict {
    /// The disputed system id.
    pub system: SystemId,
    /// The vehicle link that had it first.
    pub owner: LinkId,
    /// The other vehicle link sending as that system.
    pub claimant: LinkId,
}

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
