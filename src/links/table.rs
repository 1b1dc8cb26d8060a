//! The routing table: which (system, component) ids sit behind which link, and where a frame
//! goes. Pure and synchronous, so its invariants are property-tested without sockets.
//!
//! Rules (MAVLink routing, as mavlink-router applies them):
//! - every frame teaches the table that its sender sits behind its ingress link;
//! - a frame without a target, or with target system 0, is a broadcast: every other link;
//! - a frame targeted at (s, c) goes only to links where (s, c) was seen; with c = 0, or when
//!   component c was never seen, to links where any component of system s was seen;
//! - a targeted frame whose system was never seen goes nowhere (counted as unroutable);
//! - never back to the ingress link.
//!
//! Vehicles are kept apart by system id: the first vehicle-side link a system id is heard on
//! owns it while that link lives and keeps sending as it ([`RoutingTable::claim`]); the same id
//! from another vehicle link is a conflict, and the router never merges it (its frames are
//! logged, go nowhere else and are counted). An owner silent for [`CLAIM_TIMEOUT`] under that
//! id hands it to the next link that sends as it. (A vehicle restarted on a new UDP port of a
//! `udpin` endpoint is followed by the endpoint itself, at once once the old address has been
//! silent half a second: the old peer's link goes down and the new one claims the id.)
//!
//! One refinement for shared ground stations: pymavlink scripts all speak as (255, 0), so a
//! COMMAND_ACK for (255, 0) would reach every script. The table remembers which link last sent
//! each command id from each sender and delivers the ACK to that link only, so each script
//! gets its own ACK and no other.

use foldhash::HashMap;
use std::time::{Duration, Instant};

use vtol_link::{ComponentId, Frame, LinkId, RawCommandAck, SystemId};

/// How long a vehicle link keeps a system id it stopped sending as (the tracker's link
/// timeout): after that another vehicle link may take it.
pub const CLAIM_TIMEOUT: Duration = Duration::from_secs(5);

/// Where a frame goes, as decided by [`RoutingTable::route`].
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Route {
    /// To every link but the ingress one.
    Broadcast,
    /// To the links where the target was seen.
    Targeted,
    /// Targeted at a system no link has shown: dropped.
    Unroutable,
}

/// A frame's addressing, as far as routing needs it.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct Addressing {
    /// `target_system`/`target_component`, if the message has them.
    pub target: Option<(SystemId, ComponentId)>,
    /// For COMMAND_ACK: the command it answers.
    pub ack_of_command: Option<u16>,
    /// For COMMAND_LONG/COMMAND_INT: the command it carries.
    pub command: Option<u16>,
}

/// The table.
#[derive(Debug, Default, Clone)]
pub struct RoutingTable {
    /// (system, component) → links it was seen on (almost always one).
    components: HashMap<(SystemId, ComponentId), Vec<LinkId>>,
    /// system → links any of its components was seen on.
    systems: HashMap<SystemId, Vec<LinkId>>,
    /// (sender system, sender component, command) → the link that sent it last.
    pending_commands: HashMap<(SystemId, ComponentId, u16), LinkId>,
    /// Vehicle system → the vehicle-side link that owns it, and when it last sent as it.
    claims: HashMap<SystemId, (LinkId, Instant)>,
}

fn add_unique(v: &mut Vec<LinkId>, link: LinkId) {
    if !v.contains(&link) {
        v.push(link);
    }
}

impl RoutingTable {
    /// An empty table.
    #[must_use]
    pub fn new() -> Self {
        Self::default()
    }

    /// Learns that `(system, component)` sits behind `link`.
    pub fn learn(&mut self, link: LinkId, system: SystemId, component: ComponentId) {
        let known = self.components.entry((system, component)).or_default();
        if known.contains(&link) {
            return;
        }
        known.push(link);
        add_unique(self.systems.entry(system).or_default(), link);
    }

    /// Remembers that `link` sent `command` as (system, component), so the ACK goes back there.
    pub fn note_command(
        &mut self,
        link: LinkId,
        system: SystemId,
        component: ComponentId,
        command: u16,
    ) {
        self.pending_commands
            .insert((system, component, command), link);
    }

    /// Forgets everything learnt about a link that went down.
    pub fn forget_link(&mut self, link: LinkId) {
        self.components.retain(|_, v| {
            v.retain(|l| *l != link);
            !v.is_empty()
        });
        self.systems.retain(|_, v| {
            v.retain(|l| *l != link);
            !v.is_empty()
        });
        self.pending_commands.retain(|_, l| *l != link);
        self.claims.retain(|_, (l, _)| *l != link);
    }

    /// A vehicle-side `link` sends as `system` at `now`: `Ok(None)` when the link owns the id
    /// (claimed now if nobody did), `Ok(Some(previous))` when it takes the id from a link
    /// silent under it for [`CLAIM_TIMEOUT`], `Err(owner)` when another vehicle link owns it.
    /// A claim lasts until the owner goes down ([`RoutingTable::forget_link`]) or falls silent.
    ///
    /// # Errors
    /// The owning link, for a conflict.
    pub fn claim(
        &mut self,
        link: LinkId,
        system: SystemId,
        now: Instant,
    ) -> Result<Option<LinkId>, LinkId> {
        match self.claims.get_mut(&system) {
            Some((owner, last)) if *owner == link => {
                *last = now;
                Ok(None)
            }
            Some((owner, last)) if now.saturating_duration_since(*last) < CLAIM_TIMEOUT => {
                Err(*owner)
            }
            Some(entry) => {
                let previous = entry.0;
                *entry = (link, now);
                Ok(Some(previous))
            }
            None => {
                self.claims.insert(system, (link, now));
                Ok(None)
            }
        }
    }

    /// The vehicle link that owns `system`, if any.
    #[must_use]
    pub fn owner_of(&self, system: SystemId) -> Option<LinkId> {
        self.claims.get(&system).map(|(l, _)| *l)
    }

    /// Links where `(system, component)` was seen.
    #[must_use]
    pub fn links_of(&self, system: SystemId, component: ComponentId) -> &[LinkId] {
        self.components
            .get(&(system, component))
            .map_or(&[], Vec::as_slice)
    }

    /// Whether any component of `system` was seen on `link`.
    #[must_use]
    pub fn system_seen_on(&self, system: SystemId, link: LinkId) -> bool {
        self.systems.get(&system).is_some_and(|v| v.contains(&link))
    }

    /// Decides where a frame from `ingress` goes. `links` lists every live link; the chosen
    /// ones are appended to `out` (cleared first), never including `ingress`.
    pub fn route(
        &mut self,
        ingress: LinkId,
        addressing: &Addressing,
        links: &[LinkId],
        out: &mut Vec<LinkId>,
    ) -> Route {
        out.clear();
        let Some((system, component)) = addressing.target.filter(|(s, _)| !s.is_broadcast()) else {
            out.extend(links.iter().copied().filter(|l| *l != ingress));
            return Route::Broadcast;
        };
        if let Some(command) = addressing.ack_of_command
            && let Some(&link) = self.pending_commands.get(&(system, component, command))
            && link != ingress
            && links.contains(&link)
        {
            self.pending_commands.remove(&(system, component, command));
            out.push(link);
            return Route::Targeted;
        }
        let exact = self.links_of(system, component);
        let candidates = if component != ComponentId::ALL && !exact.is_empty() {
            exact
        } else {
            self.systems.get(&system).map_or(&[][..], Vec::as_slice)
        };
        out.extend(
            candidates
                .iter()
                .copied()
                .filter(|l| *l != ingress && links.contains(l)),
        );
        if candidates.is_empty() {
            Route::Unroutable
        } else {
            Route::Targeted
        }
    }
}

/// Reads what routing needs from a frame without decoding it.
#[must_use]
pub fn addressing(frame: &Frame) -> Addressing {
    let mut a = Addressing {
        target: frame.target_ids(),
        ..Addressing::default()
    };
    if let Some(cmd) = frame.raw_command() {
        a.command = Some(cmd.command);
    } else if let Some(ack) = RawCommandAck::from_frame(frame) {
        a.ack_of_command = Some(ack.command);
    }
    a
}

#[cfg(test)]
mod tests {
    use super::*;

    fn ids(s: u8, c: u8) -> (SystemId, ComponentId) {
        (SystemId(s), ComponentId(c))
    }
    use proptest::prelude::*;

    const VEHICLE: LinkId = LinkId(1);
    const SCRIPT_A: LinkId = LinkId(2);
    const SCRIPT_B: LinkId = LinkId(3);

    fn table() -> RoutingTable {
        let mut t = RoutingTable::new();
        t.learn(VEHICLE, SystemId(1), ComponentId(1));
        t.learn(SCRIPT_A, SystemId(255), ComponentId(0));
        t.learn(SCRIPT_B, SystemId(255), ComponentId(0));
        t
    }

    #[test]
    fn broadcast_goes_everywhere_but_ingress() {
        let mut t = table();
        let mut out = Vec::new();
        let r = t.route(
            VEHICLE,
            &Addressing::default(),
            &[VEHICLE, SCRIPT_A, SCRIPT_B],
            &mut out,
        );
        assert_eq!(r, Route::Broadcast);
        assert_eq!(out, vec![SCRIPT_A, SCRIPT_B]);
    }

    #[test]
    fn targeted_to_vehicle_and_unknown_component_falls_back_to_system() {
        let mut t = table();
        let mut out = Vec::new();
        let a = Addressing {
            target: Some(ids(1, 0)),
            ..Default::default()
        };
        assert_eq!(
            t.route(SCRIPT_A, &a, &[VEHICLE, SCRIPT_A, SCRIPT_B], &mut out),
            Route::Targeted
        );
        assert_eq!(out, vec![VEHICLE]);
        let a = Addressing {
            target: Some(ids(1, 100)),
            ..Default::default()
        };
        t.route(SCRIPT_A, &a, &[VEHICLE, SCRIPT_A, SCRIPT_B], &mut out);
        assert_eq!(out, vec![VEHICLE]);
        let a = Addressing {
            target: Some(ids(9, 1)),
            ..Default::default()
        };
        assert_eq!(
            t.route(SCRIPT_A, &a, &[VEHICLE, SCRIPT_A], &mut out),
            Route::Unroutable
        );
        assert!(out.is_empty());
    }

    #[test]
    fn command_ack_goes_to_the_link_that_sent_the_command() {
        let mut t = table();
        let links = [VEHICLE, SCRIPT_A, SCRIPT_B];
        t.note_command(SCRIPT_B, SystemId(255), ComponentId(0), 400);
        let mut out = Vec::new();
        let ack = Addressing {
            target: Some(ids(255, 0)),
            ack_of_command: Some(400),
            command: None,
        };
        t.route(VEHICLE, &ack, &links, &mut out);
        assert_eq!(out, vec![SCRIPT_B]);
        // The pending entry is used once; a second ACK falls back to plain routing.
        t.route(VEHICLE, &ack, &links, &mut out);
        assert_eq!(out, vec![SCRIPT_A, SCRIPT_B]);
    }

    #[test]
    fn forgetting_a_link_removes_its_routes() {
        let mut t = table();
        t.forget_link(SCRIPT_A);
        assert_eq!(t.links_of(SystemId(255), ComponentId(0)), &[SCRIPT_B]);
        t.forget_link(VEHICLE);
        let mut out = Vec::new();
        let a = Addressing {
            target: Some(ids(1, 1)),
            ..Default::default()
        };
        assert_eq!(
            t.route(SCRIPT_B, &a, &[SCRIPT_B], &mut out),
            Route::Unroutable
        );
    }

    #[test]
    fn a_system_id_belongs_to_the_first_vehicle_link_until_it_goes_or_falls_silent() {
        let mut t = RoutingTable::new();
        let (a, b) = (LinkId(7), LinkId(8));
        let t0 = Instant::now();
        let at = |ms| t0 + Duration::from_millis(ms);
        assert_eq!(t.claim(a, SystemId(1), at(0)), Ok(None));
        assert_eq!(t.claim(b, SystemId(2), at(0)), Ok(None));
        assert_eq!(t.claim(a, SystemId(1), at(1000)), Ok(None));
        assert_eq!(t.claim(b, SystemId(1), at(5999)), Err(a), "a spoke 5 s ago");
        assert_eq!(t.owner_of(SystemId(1)), Some(a));
        t.forget_link(a);
        assert_eq!(t.claim(b, SystemId(1), at(6000)), Ok(None), "a went down");
        assert_eq!(t.owner_of(SystemId(1)), Some(b));
        // b falls silent as system 1 (still up as system 2): after 5 s a may take it.
        assert_eq!(t.claim(a, SystemId(1), at(10_999)), Err(b));
        assert_eq!(t.claim(a, SystemId(1), at(11_000)), Ok(Some(b)));
        assert_eq!(t.owner_of(SystemId(1)), Some(a));
    }

    proptest! {
        /// No frame goes back to its ingress link, and a targeted frame reaches only links
        /// where its target system was seen.
        #[test]
        fn routing_invariants(
            learned in proptest::collection::vec((1u32..6, 0u8..4, 0u8..3), 0..20),
            frames in proptest::collection::vec(
                (1u32..6, proptest::option::of((0u8..4, 0u8..3)), proptest::option::of(0u16..3)),
                1..40),
        ) {
            let links: Vec<LinkId> = (1..6).map(LinkId).collect();
            let mut t = RoutingTable::new();
            for (l, s, c) in learned {
                t.learn(LinkId(l), SystemId(s), ComponentId(c));
            }
            let mut out = Vec::new();
            for (ingress, target, ack) in frames {
                let ingress = LinkId(ingress);
                if let Some(cmd) = ack {
                    // The router learns a sender before it notes its command.
                    t.learn(ingress, SystemId(255), ComponentId(0));
                    t.note_command(ingress, SystemId(255), ComponentId(0), cmd);
                }
                let a = Addressing { target: target.map(|(s, c)| ids(s, c)), ack_of_command: ack, command: None };
                let route = t.route(ingress, &a, &links, &mut out);
                prop_assert!(!out.contains(&ingress));
                let mut dedup = out.clone();
                dedup.sort();
                dedup.dedup();
                prop_assert_eq!(dedup.len(), out.len(), "a link got the frame twice");
                match target {
                    Some((s, _)) if s != 0 => {
                        for l in &out {
                            prop_assert!(t.system_seen_on(SystemId(s), *l), "{l} never showed system {s}");
                        }
                        prop_assert_ne!(route, Route::Broadcast);
                    }
                    _ => prop_assert_eq!(out.len(), links.len() - 1),
                }
            }
        }
    }
}
