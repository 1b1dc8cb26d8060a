//! Forwarding load test: the `vtol-gcs` daemon against a bare UDP forwarder, side by side.
//!
//! ```text
//! cargo bench --bench forwarding                # one full run (~1.5 min), prints the tables
//! cargo bench --bench forwarding -- --runs 3     # three runs; every figure is the median
//! cargo bench --bench forwarding -- --quick      # smoke run, a few seconds
//! cargo test  --bench forwarding                 # the same smoke run, in the test profile
//! ```
//! (`FORWARDING_RUNS=N` sets the number of runs too; `FORWARDING_BARE_TOKIO=1` runs the bare
//! forwarder on a tokio runtime instead of blocking `std` calls; `FORWARDING_QUICK=1` also
//! selects the smoke run; so does running without cargo bench's `--bench` argument, which is
//! how `cargo test` runs a `harness = false` target; `FORWARDING_DAEMON=PATH` runs another build
//! of the daemon instead of this one's, to compare two builds on the same machine;
//! `FORWARDING_BARE_WORK_NS=N` gives the bare forwarder N ns of busy work after each datagram,
//! to see what a CPU cost per frame does to the latency on the machine.)
//!
//! Set-up, all on loopback UDP:
//! - a load generator (this process, one thread) sends MAVLink 2 ATTITUDE frames from sysid 1
//!   compid 1 with an increasing sequence number, a phase number and the send time (ns since a
//!   common `Instant`) in the payload;
//! - N sinks (this process, one thread each, 4 MiB receive buffers) bind UDP sockets, count
//!   the frames of the current phase and record one-way latency (receive − send time);
//! - the forwarder under test is a separate process, so its CPU time is exactly utime + stime
//!   from `/proc/<pid>/stat` over each phase:
//!   - **bare**: this same executable re-run as a plain blocking `std` UDP loop (`recv_from`,
//!     then `send_to` every client) — the ceiling on this machine;
//!   - **vtol-gcs**: the real daemon binary, `vtol-gcs run --vehicle udpin:127.0.0.1:P
//!     --serve udpout:127.0.0.1:SINK1 … --log-dir TMP --headless`, tlog on.
//!
//! Phases per forwarder and client count: saturation (a fixed count sent as fast as the
//! generator can; delivered/s = frames received by all sinks / (last receive − first send)),
//! then open-loop paced 1k, 10k and 50k msgs/s (sleep-paced on a fixed schedule, so a late
//! wake-up sends the frames that are due back to back). Loss = 1 − delivered/(sent × clients).
//! Latency percentiles are per phase. One forwarder runs at a time. `FORWARDING_INTERLEAVE=1`
//! (diagnostic) runs both at once instead, and the paced phases in turns of 1 s of traffic in
//! alternating order (bare, daemon, daemon, bare, …) until each has had the phase's time, so
//! both meet the same machine noise; each turn follows 0.1 s of uncounted traffic to the same
//! forwarder (so that it does not meet a forwarder idle for a second), and each one's CPU is
//! counted over its counted turns. Every phase also reports the host's steal time (`steal` in
//! /proc/stat): a busy hypervisor stalls CPUs for milliseconds, and the frames waiting on a
//! stalled CPU make the p99. CPU % is of one core (100 % = one core busy); CPU
//! ns/frame is the forwarder's CPU time over the phase divided by the frames it forwarded
//! (delivered copies / clients); context switches per frame are summed over all of the
//! forwarder's threads (`/proc/<pid>/task/*/status`, voluntary and non-voluntary); peak RSS is
//! the forwarder's `VmHWM` at the end of its scenario. With several runs, each figure is the
//! median over the runs and each daemon/bare ratio the median of the per-run ratios (the two
//! forwarders of a run share its machine load).

mod forwarder;
mod frames;
mod machine;
mod phases;
mod report;
mod sinks;

use std::sync::OnceLock;
use std::time::Instant;

use forwarder::*;
use frames::*;
use machine::*;
use phases::*;
use report::*;
use sinks::*;

/// MAVLink ATTITUDE: id 30, 28-byte payload, CRC_EXTRA 39.
pub(crate) const ATTITUDE_ID: u32 = vtol_link::protocol::id::ATTITUDE;
pub(crate) const PAYLOAD_LEN: usize = 28;
pub(crate) const FRAME_LEN: usize = 10 + PAYLOAD_LEN + 2;
pub(crate) const SINK_RCVBUF: usize = 4 << 20;

pub(crate) fn epoch() -> Instant {
    static EPOCH: OnceLock<Instant> = OnceLock::new();
    *EPOCH.get_or_init(Instant::now)
}

pub(crate) fn now_ns() -> u64 {
    u64::try_from(epoch().elapsed().as_nanos()).unwrap_or(u64::MAX)
}

pub(crate) struct Cfg {
    pub(crate) quick: bool,
    /// `FORWARDING_INTERLEAVE=1`: both forwarders at once, paced phases in 1 s turns.
    pub(crate) interleave: bool,
    pub(crate) sat_count: u32,
    pub(crate) paced_s: f64,
    /// Paced phases, frames/s.
    pub(crate) rates: Vec<u32>,
}

/// `--runs N` (after `--` with cargo bench) or `FORWARDING_RUNS=N`; default 1.
fn run_count(args: &[String]) -> usize {
    let from_args = args
        .iter()
        .position(|a| a == "--runs")
        .and_then(|i| args.get(i + 1))
        .and_then(|v| v.parse().ok());
    let from_env = std::env::var("FORWARDING_RUNS")
        .ok()
        .and_then(|v| v.parse().ok());
    from_args.or(from_env).unwrap_or(1usize).max(1)
}

fn main() {
    let args: Vec<String> = std::env::args().collect();
    if let Some(i) = args.iter().position(|a| a == "--bare-forwarder") {
        bare_forwarder(args.get(i + 1).map_or("", String::as_str));
    }
    let _ = epoch();
    // `cargo bench` passes --bench; `cargo test` runs a harness = false target without it.
    let quick = args.iter().any(|a| a == "--quick")
        || std::env::var_os("FORWARDING_QUICK").is_some_and(|v| v != "0")
        || !args.iter().any(|a| a == "--bench");
    // For profiling one phase: FORWARDING_RATES=10000 FORWARDING_PACED_S=20.
    let rates: Vec<u32> = std::env::var("FORWARDING_RATES")
        .ok()
        .map(|v| v.split(',').filter_map(|r| r.trim().parse().ok()).collect())
        .filter(|r: &Vec<u32>| !r.is_empty())
        .unwrap_or_else(|| vec![1_000, 10_000, 50_000]);
    let interleave = std::env::var_os("FORWARDING_INTERLEAVE").is_some_and(|v| v != "0");
    let cfg = if quick {
        Cfg {
            quick,
            interleave,
            sat_count: 5_000,
            paced_s: 0.2,
            rates: rates.clone(),
        }
    } else {
        Cfg {
            quick,
            interleave,
            sat_count: 100_000,
            // 10 s a phase: a p99 at 10k/s then comes from 1 000 frames, not 250 (at 2.5 s the
            // bare loop's own p99 ranged over 87–257 µs from run to run).
            paced_s: std::env::var("FORWARDING_PACED_S")
                .ok()
                .and_then(|v| v.parse().ok())
                .unwrap_or(10.0),
            rates,
        }
    };
    let n_runs = run_count(&args);
    let mut runs = Vec::new();
    let mut phase = 0;
    // For profiling one case: FORWARDING_ONLY=bare|daemon, FORWARDING_CLIENTS=1|4 (with the
    // rates above).
    let only = std::env::var("FORWARDING_ONLY").unwrap_or_default();
    let only_clients: Option<usize> = std::env::var("FORWARDING_CLIENTS")
        .ok()
        .and_then(|v| v.parse().ok());
    for run in 0..n_runs {
        let (busy0, total0) = machine_jiffies();
        let own0 = own_jiffies();
        let mut scenarios = Vec::new();
        for clients in [1usize, 4]
            .into_iter()
            .filter(|c| only_clients.is_none_or(|o| o == *c))
        {
            let sinks = Sinks::start(clients);
            let kinds: Vec<Kind> = [Kind::Bare, Kind::Daemon]
                .into_iter()
                .filter(|k| only.is_empty() || only == k.tag())
                .collect();
            eprintln!("run {}/{n_runs}: {clients} client(s)…", run + 1);
            if cfg.interleave {
                scenarios.extend(run_scenarios(&kinds, &sinks, &cfg, &mut phase, TURN_S));
            } else {
                // One forwarder at a time, each alone on the machine.
                for kind in kinds {
                    let one = run_scenarios(&[kind], &sinks, &cfg, &mut phase, cfg.paced_s);
                    scenarios.extend(one);
                }
            }
        }
        let (busy1, total1) = machine_jiffies();
        let other = (busy1 - busy0).saturating_sub(own_jiffies() - own0);
        runs.push(Run {
            scenarios,
            background_pct: 100.0 * other as f64 / (total1 - total0).max(1) as f64,
        });
    }
    print_report(&cfg, &runs);
    // Smoke check: both forwarders move traffic to every client at a modest rate.
    for s in runs.iter().flat_map(|r| &r.scenarios) {
        let (_, r) = s.paced[0];
        assert!(
            r.delivered * 2 >= r.sent * s.clients as u64,
            "{} with {} client(s) delivered {} of {} copies at 1k/s",
            s.kind.name(),
            s.clients,
            r.delivered,
            r.sent * s.clients as u64
        );
    }
}
