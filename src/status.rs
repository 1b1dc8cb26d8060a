//! The one-line live status the daemon prints when it runs without the terminal UI:
//! mode, armed state, attitude, altitude, PWM outputs, link health, reboots seen, the daemon's
//! parameter downloads and the log's counters, or its write error while it fails.

use std::fmt::Write;
use std::sync::atomic::Ordering;
use std::time::Instant;

use crate::links::{LinkInfo, Side};
use crate::tracker::VehicleState;
use crate::trust::policy::EndpointPolicy;
use crate::trust::signing::SigningSnapshot;
use crate::vitals::{Severity, Vitals, vitals};

/// Formats the status line for the first vehicle (or says none is heard yet).
// Long: the status line's segments appended in the order the line shows them (vehicle, reboots,
// parameters, vehicle links, clients, tlog); one pass over one string.
#[must_use]
pub fn line(
    state: &VehicleState,
    links: &[LinkInfo],
    tlog: Option<&crate::tlog::TlogStats>,
    params: &crate::reboot::FetchStatus,
    unroutable: u64,
    now: Instant,
) -> String {
    let mut s = String::new();
    match state.vehicles.values().next() {
        None => s.push_str("no vehicle heard yet"),
        Some(v) if state.vehicle_lost(now) => {
            let _ = write!(
                s,
                "sys {} LINK LOST (silent {:.0} s)",
                v.system_id,
                now.duration_since(v.last_heartbeat).as_secs_f64()
            );
        }
        Some(v) => {
            let _ = write!(
                s,
                "sys {} {} {}",
                v.system_id,
                v.mode_name(),
                crate::words::armed(v.armed)
            );
            if let Some(a) = v.attitude {
                let [r, p, y] = a.rpy_rad.map(|x| f64::from(x).to_degrees());
                let _ = write!(s, " | roll {r:+6.1}° pitch {p:+6.1}° yaw {y:+6.1}°");
            }
            if let Some(p) = v.position {
                let _ = write!(s, " | alt {:+5.2} m", -p.pos_ned_m[2]);
            }
            let _ = write!(
                s,
                " | pwm {} {} {} {} {}",
                v.servo_us[0], v.servo_us[1], v.servo_us[2], v.servo_us[3], v.servo_us[4]
            );
            s.push_str(&vitals_part(&vitals(state, v), v.system_status));
        }
    }
    if let Some(v) = state.vehicles.values().next()
        && v.reboots > 0
    {
        let _ = write!(s, " | rebooted {}x", v.reboots);
    }
    if params.completed > 0 || params.error.is_some() {
        let _ = write!(s, " | params {}", params.values);
        if params.after_reboots > 0 {
            let _ = write!(
                s,
                " (fetched again after {} reboot(s))",
                params.after_reboots
            );
        }
        if let Some(e) = &params.error {
            let _ = write!(s, " (download failed: {e})");
        }
    }
    for (id, h) in state.links.iter().filter(|(_, h)| h.side == Side::Vehicle) {
        let health = crate::words::link_health(h.is_lost(now));
        let _ = write!(
            s,
            " | vehicle {id} {health} {:.0} Hz loss {:.1}%",
            h.window.rate_hz(now),
            h.window.loss_pct(now)
        );
    }
    // The daemon's own-traffic link is not a client.
    let clients = links
        .iter()
        .filter(|l| l.side == Side::Client && l.peer != crate::daemon::OWN_TRAFFIC_PEER)
        .count();
    let dropped: u64 = links
        .iter()
        .map(|l| l.stats.snapshot().tx_dropped_queue_full)
        .sum();
    let _ = write!(
        s,
        " | links {clients} client(s), {dropped} dropped, {unroutable} unroutable"
    );
    if let Some(t) = tlog {
        let records = t.records.load(Ordering::Relaxed);
        let lost = t.write_errors.load(Ordering::Relaxed);
        match t.failing() {
            Some(why) => {
                let _ = write!(s, " | tlog ERROR {why}: {lost} rec lost, routing goes on");
            }
            None if lost > 0 => {
                let _ = write!(s, " | tlog {records} rec ({lost} lost to write errors)");
            }
            None => {
                let _ = write!(s, " | tlog {records} rec");
            }
        }
    }
    s
}

/// The status line's health part, as the UI's header shows it: the state with its reason, a
/// failsafe, battery, GPS, home and unhealthy sensors.
#[must_use]
pub fn vitals_part(v: &Vitals, state: vtol_link::dialect::MavState) -> String {
    use vtol_link::dialect::MavState as S;
    let mut s = String::new();
    match (state, &v.reason) {
        (S::MAV_STATE_CRITICAL | S::MAV_STATE_EMERGENCY, Some(r)) => {
            let _ = write!(s, " | {}: {r}", crate::words::mav_state(state));
        }
        (S::MAV_STATE_CRITICAL | S::MAV_STATE_EMERGENCY, None) => {
            let _ = write!(s, " | {}", crate::words::mav_state(state));
        }
        _ => {}
    }
    if let Some(fs) = &v.failsafe {
        let _ = write!(s, " | FAILSAFE {fs}");
    }
    if let Some(b) = &v.battery {
        let flag = match b.severity {
            Severity::Ok => "",
            Severity::Warn => " LOW",
            Severity::Bad => " CRITICAL",
        };
        let _ = write!(s, " | bat {}{flag}", b.summary());
    }
    if let Some((fix, sats, _)) = v.gps {
        let _ = write!(s, " | gps {fix} {sats} sats");
    }
    if let Some((d, b)) = v.home {
        let _ = write!(s, " | home {d:.1} m {b:03.0}°");
    }
    if !v.unhealthy.is_empty() {
        let _ = write!(s, " | unhealthy {}", v.unhealthy.join(", "));
    }
    s
}

/// The vehicle link as the stream fit measured it: its capacity in frame bytes per second
/// once it was full, whether the streams run at fitted rates, and the radio's free transmit
/// buffer when the link reports RADIO_STATUS. Empty when there is nothing to say.
#[must_use]
pub fn fit_part(fit: Option<&crate::stream_fit::LinkFit>) -> String {
    let mut s = String::new();
    let Some(f) = fit else { return s };
    if let Some(c) = f.capacity {
        let _ = write!(
            s,
            " | link {} capacity {:.1} kB/s{}",
            f.link,
            c / 1000.0,
            if f.fitted { ", streams fitted" } else { "" }
        );
    }
    if let Some(t) = f.radio_txbuf {
        let _ = write!(s, " | radio txbuf {t}%");
    }
    s
}

/// The status line's signing and policy part: with a key, what the daemon signed and what it
/// refused from the vehicle; per client link with a policy, its trust, its rate-limit drops and
/// refused frames. Empty when there is nothing to say.
#[must_use]
pub fn policy_part(links: &[LinkInfo], signing: Option<&SigningSnapshot>) -> String {
    let mut s = String::new();
    if let Some(c) = signing {
        let _ = write!(
            s,
            " | signing {} signed, {} verified, refused {} unsigned {} bad {} replayed",
            c.signed, c.verified, c.refused_unsigned, c.refused_bad_signature, c.refused_replayed
        );
    }
    for l in links
        .iter()
        .filter(|l| l.side == Side::Client && l.peer != crate::daemon::OWN_TRAFFIC_PEER)
        .filter(|l| l.policy != EndpointPolicy::default())
    {
        let c = l.policy_counters.snapshot();
        let _ = write!(s, " | {} {}", l.id, l.policy.trust);
        if l.policy.rate.is_some() {
            let _ = write!(s, " rate-dropped {}", c.dropped_rate);
        }
        if c.refused_read_only > 0 {
            let _ = write!(s, " refused {}", c.refused_read_only);
        }
        if c.signed > 0 || c.unsignable > 0 {
            let _ = write!(s, " signed {} unsignable {}", c.signed, c.unsignable);
        }
    }
    s
}

/// The status line's fleet part: with more than one vehicle, each one's system id, mode, armed
/// state and health; and every system id two vehicle links claim. Empty for one vehicle and no
/// conflict.
#[must_use]
pub fn fleet_part(
    state: &VehicleState,
    conflicts: &[crate::links::SysidConflict],
    now: Instant,
) -> String {
    let mut s = String::new();
    if state.vehicles.len() > 1 {
        let _ = write!(s, " | fleet");
        for v in state.vehicles.values() {
            if v.is_lost(now) {
                let _ = write!(s, " [{} LOST]", v.system_id);
            } else {
                let _ = write!(s, " [{}]", v.summary(now));
            }
        }
    }
    for c in conflicts {
        let _ = write!(
            s,
            " | CONFLICT sys {} on {} and {} (kept {})",
            c.system, c.owner, c.claimant, c.owner
        );
    }
    s
}

#[cfg(test)]
mod tests {
    use std::time::Duration;

    use vtol_link::dialect::{self, MavAutopilot, MavMessage, MavModeFlag, MavState, MavType};
    use vtol_link::{Frame, LinkId, SystemId};

    use super::*;
    use crate::links::SysidConflict;

    fn heartbeat(armed: bool) -> MavMessage {
        let mut base_mode = MavModeFlag::MAV_MODE_FLAG_CUSTOM_MODE_ENABLED;
        if armed {
            base_mode |= MavModeFlag::MAV_MODE_FLAG_SAFETY_ARMED;
        }
        MavMessage::HEARTBEAT(dialect::HEARTBEAT_DATA {
            custom_mode: 18,
            mavtype: MavType::MAV_TYPE_VTOL_TAILSITTER_DUOROTOR,
            autopilot: MavAutopilot::MAV_AUTOPILOT_GENERIC,
            base_mode,
            system_status: MavState::MAV_STATE_ACTIVE,
            mavlink_version: 3,
        })
    }

    /// Applies a heartbeat of system `sys` on vehicle link 1 at `at`.
    fn apply_heartbeat(s: &mut VehicleState, sys: u8, armed: bool, at: Instant) {
        let f = Frame::encode_v2(
            SystemId(sys),
            vtol_link::ComponentId(1),
            0,
            &heartbeat(armed),
        );
        s.apply(LinkId(1), Side::Vehicle, &f, at);
    }

    #[test]
    fn fleet_part_lists_vehicles_and_conflicts() {
        let t0 = Instant::now();
        let mut s = VehicleState::new(t0);
        apply_heartbeat(&mut s, 1, false, t0);
        assert_eq!(fleet_part(&s, &[], t0), "", "one vehicle: nothing to add");
        apply_heartbeat(&mut s, 2, true, t0 + Duration::from_secs(6));
        let conflict = SysidConflict {
            system: SystemId(2),
            owner: LinkId(1),
            claimant: LinkId(4),
        };
        let line = fleet_part(&s, &[conflict], t0 + Duration::from_secs(6));
        assert!(
            line.starts_with(" | fleet [1 LOST] [2 QHOVER ARMED"),
            "{line}"
        );
        assert!(
            line.ends_with(" | CONFLICT sys 2 on link#1 and link#4 (kept link#1)"),
            "{line}"
        );
    }
}
