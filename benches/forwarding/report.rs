//! Medians over runs, and the tables printed.

use super::*;

pub(crate) fn kmsg(x: f64) -> String {
    if x >= 1e4 {
        format!("{:.0}k", x / 1e3)
    } else {
        format!("{x:.0}")
    }
}

pub(crate) fn median(mut v: Vec<f64>) -> f64 {
    v.retain(|x| !x.is_nan());
    if v.is_empty() {
        return f64::NAN;
    }
    v.sort_by(f64::total_cmp);
    let m = v.len() / 2;
    if v.len().is_multiple_of(2) {
        (v[m - 1] + v[m]) / 2.0
    } else {
        v[m]
    }
}

/// Field-by-field median of the same phase over several runs.
pub(crate) fn median_phase(rs: &[PhaseResult]) -> PhaseResult {
    let m = |f: fn(&PhaseResult) -> f64| median(rs.iter().map(f).collect());
    let mu = |f: fn(&PhaseResult) -> u64| m_u64(rs.iter().map(f).collect());
    PhaseResult {
        sent: mu(|r| r.sent),
        delivered: mu(|r| r.delivered),
        delivered_per_s: m(|r| r.delivered_per_s),
        offered_per_s: m(|r| r.offered_per_s),
        loss: m(|r| r.loss),
        p50_us: m(|r| r.p50_us),
        p99_us: m(|r| r.p99_us),
        max_us: m(|r| r.max_us),
        cpu_pct: m(|r| r.cpu_pct),
        cpu_ns_per_frame: m(|r| r.cpu_ns_per_frame),
        vcsw_per_frame: m(|r| r.vcsw_per_frame),
        ivcsw_per_frame: m(|r| r.ivcsw_per_frame),
        ingress_drops: mu(|r| r.ingress_drops),
        sink_drops: mu(|r| r.sink_drops),
        steal_pct: m(|r| r.steal_pct),
        ipi_per_frame: m(|r| r.ipi_per_frame),
    }
}

pub(crate) fn m_u64(v: Vec<u64>) -> u64 {
    median(v.into_iter().map(|x| x as f64).collect()).round() as u64
}

/// The scenarios of one pass over every forwarder and client count.
pub(crate) struct Run {
    pub(crate) scenarios: Vec<Scenario>,
    /// CPU other processes used during the pass, % of the whole machine.
    pub(crate) background_pct: f64,
}

impl Run {
    pub(crate) fn find(&self, kind: Kind, clients: usize) -> Option<&Scenario> {
        self.scenarios
            .iter()
            .find(|s| s.kind == kind && s.clients == clients)
    }
}

impl Scenario {
    /// The paced phase at `rate` frames/s.
    pub(crate) fn at(&self, rate: u32) -> PhaseResult {
        self.paced
            .iter()
            .find(|(r, _)| *r == rate)
            .map(|(_, r)| *r)
            .unwrap_or_default()
    }
}

pub(crate) fn list(v: &[f64], digits: usize) -> String {
    let parts: Vec<String> = v.iter().map(|x| format!("{x:.digits$}")).collect();
    format!("[{}]", parts.join(", "))
}

pub(crate) fn print_report(cfg: &Cfg, runs: &[Run]) {
    let nproc = std::thread::available_parallelism().map_or(0, std::num::NonZero::get);
    println!();
    println!(
        "machine: {nproc} CPUs ({}), kernel {}; everything (generator, sinks, forwarder) shares them",
        cpu_model(),
        std::fs::read_to_string("/proc/sys/kernel/osrelease")
            .unwrap_or_default()
            .trim()
    );
    let bg: Vec<f64> = runs.iter().map(|r| r.background_pct).collect();
    println!(
        "background: other processes used {} % of the machine's CPU during each run (0 % = quiet machine)",
        list(&bg, 0)
    );
    println!(
        "mode: {}; {} run(s), figures are medians over the runs; saturation = {} frames as fast as possible; paced phases {:.1} s each{}; frame = 40-byte MAVLink 2 ATTITUDE",
        if cfg.quick {
            "QUICK (smoke run, numbers are not meaningful)"
        } else {
            "full"
        },
        runs.len(),
        cfg.sat_count,
        cfg.paced_s,
        if cfg.interleave {
            " per forwarder, both running, interleaved in 1 s turns, each after 0.1 s of uncounted traffic (FORWARDING_INTERLEAVE)"
        } else {
            ", one forwarder at a time"
        }
    );
    println!(
        "per frame = per frame forwarded (delivered copies / clients); csw = context switches of all the forwarder's threads (voluntary + non-voluntary)"
    );
    println!();
    println!(
        "| forwarder | clients | phase | sent | delivered/s (all clients) | per client/s | loss | p50 µs | p99 µs | max µs | CPU % | CPU ns/frame | csw/frame (vol + invol) | ingress drops | sink drops | host steal % | IPIs/frame |"
    );
    println!(
        "|---|---:|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|"
    );
    let Some(first) = runs.first() else { return };
    for s in &first.scenarios {
        let same: Vec<&Scenario> = runs
            .iter()
            .filter_map(|r| r.find(s.kind, s.clients))
            .collect();
        let row = |label: String, r: &PhaseResult| {
            println!(
                "| {} | {} | {} | {} | {} | {} | {:.2} % | {:.0} | {:.0} | {:.0} | {:.0} | {:.0} | {:.2} ({:.2} + {:.2}) | {} | {} | {:.2} | {:.2} |",
                s.kind.name(),
                s.clients,
                label,
                r.sent,
                kmsg(r.delivered_per_s),
                kmsg(r.delivered_per_s / s.clients as f64),
                100.0 * r.loss,
                r.p50_us,
                r.p99_us,
                r.max_us,
                r.cpu_pct,
                r.cpu_ns_per_frame,
                r.vcsw_per_frame + r.ivcsw_per_frame,
                r.vcsw_per_frame,
                r.ivcsw_per_frame,
                r.ingress_drops,
                r.sink_drops,
                r.steal_pct,
                r.ipi_per_frame
            );
        };
        let sat: Vec<PhaseResult> = same.iter().map(|x| x.sat).collect();
        let sat = median_phase(&sat);
        row(
            format!("saturation (offered {}/s)", kmsg(sat.offered_per_s)),
            &sat,
        );
        for (rate, _) in &s.paced {
            let at: Vec<PhaseResult> = same.iter().map(|x| x.at(*rate)).collect();
            row(
                format!("paced {}/s", kmsg(f64::from(*rate))),
                &median_phase(&at),
            );
        }
    }
    print_targets(runs);
}

/// The targets: the daemon (tlog on) against the bare forwarder of the same run; each
/// figure is the median over the runs, each ratio the median of the per-run ratios.
pub(crate) fn print_targets(runs: &[Run]) {
    let pass = |ok: bool| if ok { "ok" } else { "MISS" };
    println!();
    println!(
        "targets (vtol-gcs daemon with tlog vs bare forwarder, same run; median of {} run(s), per-run ratios in brackets):",
        runs.len()
    );
    for clients in [1usize, 4] {
        let pairs: Vec<(&Scenario, &Scenario)> = runs
            .iter()
            .filter_map(|r| Some((r.find(Kind::Daemon, clients)?, r.find(Kind::Bare, clients)?)))
            .collect();
        if pairs.is_empty() {
            continue;
        }
        let each = |f: &dyn Fn(&Scenario) -> f64| -> (f64, f64, f64, Vec<f64>) {
            let ratios: Vec<f64> = pairs.iter().map(|(d, b)| f(d) / f(b)).collect();
            (
                median(pairs.iter().map(|(d, _)| f(d)).collect()),
                median(pairs.iter().map(|(_, b)| f(b)).collect()),
                median(ratios.clone()),
                ratios,
            )
        };
        let c = if clients == 1 { "client" } else { "clients" };
        let (d, b, r, rs) = each(&|s| s.at(10_000).cpu_pct);
        let (dn, bn, rn, _) = each(&|s| s.at(10_000).cpu_ns_per_frame);
        println!(
            "  {clients} {c}: CPU at 10k/s: daemon {d:.1} % ({dn:.0} ns/frame), bare {b:.1} % ({bn:.0} ns/frame) = {r:.2}x {} (ns/frame {rn:.2}x; target <= 1.2x: {})",
            list(&rs, 2),
            pass(r <= 1.2)
        );
        let (dv, bv, _, _) = each(&|s| s.at(10_000).vcsw_per_frame);
        let (di, bi, _, _) = each(&|s| s.at(10_000).ivcsw_per_frame);
        println!(
            "  {clients} {c}: context switches per frame at 10k/s: daemon {:.2} ({dv:.2} + {di:.2}), bare {:.2} ({bv:.2} + {bi:.2})",
            dv + di,
            bv + bi
        );
        let want = if clients == 1 { 0.9 } else { 1.0 };
        let (d, b, r, rs) = each(&|s| s.sat.delivered_per_s / s.clients as f64);
        println!(
            "  {clients} {c}: delivered per client at saturation: daemon {}/s, bare {}/s = {r:.2}x {} (target >= {want:.1}x: {})",
            kmsg(d),
            kmsg(b),
            list(&rs, 2),
            pass(r >= want)
        );
        for rate in [1_000u32, 10_000] {
            let (d, b, r, rs) = each(&|s| s.at(rate).p99_us);
            let ds: Vec<f64> = pairs.iter().map(|(d, _)| d.at(rate).steal_pct).collect();
            let bs: Vec<f64> = pairs.iter().map(|(_, b)| b.at(rate).steal_pct).collect();
            println!(
                "  {clients} {c}: p99 at {}/s: daemon {d:.0} µs, bare {b:.0} µs = {r:.2}x {} (target <= 1.2x: {}); host steal in the phases, daemon {} %, bare {} %",
                kmsg(f64::from(rate)),
                list(&rs, 2),
                pass(r <= 1.2),
                list(&ds, 2),
                list(&bs, 2)
            );
        }
        let losses: Vec<f64> = pairs
            .iter()
            .map(|(d, _)| 100.0 * d.at(10_000).loss)
            .collect();
        let worst = losses.iter().copied().fold(0.0, f64::max);
        println!(
            "  {clients} {c}: loss at 10k/s: daemon {:.2} % {}{}",
            median(losses.clone()),
            list(&losses, 2),
            if clients == 4 {
                format!(" (target 0 % in every run: {})", pass(worst <= 0.0))
            } else {
                String::new()
            }
        );
        let rss: Vec<f64> = pairs.iter().map(|(d, _)| d.peak_rss as f64 / 1e6).collect();
        let worst = rss.iter().copied().fold(0.0, f64::max);
        println!(
            "  {clients} {c}: peak RSS of the daemon: {:.1} MB {} (bare {:.1} MB; target < 15 MB in every run: {})",
            median(rss.clone()),
            list(&rss, 1),
            median(pairs.iter().map(|(_, b)| b.peak_rss as f64 / 1e6).collect()),
            pass(worst < 15.0)
        );
    }
    for (i, run) in runs.iter().enumerate() {
        for s in run.scenarios.iter().filter(|s| s.kind == Kind::Daemon) {
            println!(
                "run {}: daemon, {} client(s): {} threads, tlog {} bytes; last status: {}",
                i + 1,
                s.clients,
                s.threads,
                s.tlog_bytes.unwrap_or(0),
                s.last_status
            );
        }
    }
}
