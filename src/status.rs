//! The one-line live status the daemon prints when it runs without the terminal UI:
//! mode, armed state, attitude, altitude, PWM outputs, link health and log counters.

use std::fmt::Write;
use std::time::Instant;

use crate::router::policy::EndpointPolicy;
use crate::router::signing::SigningSnapshot;
use crate::router::{LinkInfo, Side};
use crate::vehicle::VehicleState;

/// Formats the status line for the first vehicle (or says none is heard yet).
#[must_use]
pub fn line(
    state: &VehicleState,
    links: &[LinkInfo],
    tlog_records: Option<u64>,
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
                if v.armed { "ARMED" } else { "disarmed" }
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
        }
    }
    for (id, h) in state.links.iter().filter(|(_, h)| h.side == Side::Vehicle) {
        let health = if h.is_lost(now) { "LOST" } else { "ok" };
        let _ = write!(
            s,
            " | vehicle {id} {health} {:.0} Hz loss {:.1}%",
            h.rate_hz(now),
            h.loss_pct(now)
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
    if let Some(n) = tlog_records {
        let _ = write!(s, " | tlog {n} rec");
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
