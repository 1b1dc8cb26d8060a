//! The links as the rest of the daemon sees them: which side a link is on, the live links as
//! the status line and the UI show them, the system ids two vehicle links claim, the router's
//! counters ([`RouterHandle`]), and the routing rules themselves ([`table`], pure).
//!
//! The router (crate-private, driven only by [`crate::daemon`]) writes these; the tracker, the
//! client, the status line, the UI and the binary read them. Nothing outside the daemon can
//! name the router (`tests/layers.rs`).

pub mod table;

use std::sync::Arc;
use std::sync::atomic::AtomicU64;

use tokio::sync::watch;
use vtol_link::{LinkId, LinkStats, SystemId};

use crate::trust::policy::{EndpointPolicy, PolicyCounters};
use crate::trust::signing::SigningCounters;

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

/// Router-wide counters (per-link ones live in each link's [`LinkStats`]).
#[derive(Debug, Default)]
pub struct RouterStats {
    /// Frames received from all links.
    pub frames_in: AtomicU64,
    /// Frame copies queued to egress links.
    pub frames_out: AtomicU64,
    /// Targeted frames whose target system was never seen.
    pub unroutable: AtomicU64,
    /// SETUP_SIGNING frames not forwarded (they carry a key).
    pub withheld_signing: AtomicU64,
    /// Copies lost because the link went down between routing and queueing.
    pub dropped_link_closed: AtomicU64,
    /// Frames the tracker tap could not take (it was behind).
    pub dropped_tap: AtomicU64,
    /// Frames from read-only links, not routed (all links).
    pub refused_read_only: AtomicU64,
    /// Copies not sent because of a link's rate limit (all links).
    pub dropped_rate: AtomicU64,
    /// Frames from `sign` links that could not be signed (MAVLink 1), not routed.
    pub unsignable: AtomicU64,
    /// Vehicle frames whose system id another vehicle link owns: logged, not routed or tracked.
    pub sysid_conflicts: AtomicU64,
}

/// What the router publishes for others: its counters, the live links, the signing counters
/// and the disputed system ids.
#[derive(Debug, Clone)]
pub struct RouterHandle {
    /// Counters.
    pub stats: Arc<RouterStats>,
    /// The live links.
    pub links: watch::Receiver<Vec<LinkInfo>>,
    /// Signing counters, when the daemon has a key.
    pub signing: Option<Arc<SigningCounters>>,
    /// System ids that two vehicle links claim, while both are up.
    pub conflicts: watch::Receiver<Vec<SysidConflict>>,
}
