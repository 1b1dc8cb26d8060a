//! The phases: saturation and paced load, in turns or one forwarder at a time.

use std::net::{SocketAddr, UdpSocket};
use std::time::{Duration, Instant};

use super::*;

/// `None`: as fast as possible.
#[derive(Clone, Copy)]
pub(crate) struct Load {
    pub(crate) rate: Option<u32>,
    pub(crate) count: u32,
}

#[derive(Clone, Copy, Default)]
pub(crate) struct PhaseResult {
    pub(crate) sent: u64,
    pub(crate) delivered: u64,
    /// Delivered copies per second over first send → last receive.
    pub(crate) delivered_per_s: f64,
    /// Generator's achieved send rate.
    pub(crate) offered_per_s: f64,
    pub(crate) loss: f64,
    pub(crate) p50_us: f64,
    pub(crate) p99_us: f64,
    pub(crate) max_us: f64,
    pub(crate) cpu_pct: f64,
    /// ns of the forwarder's CPU per frame forwarded (delivered copies / clients).
    pub(crate) cpu_ns_per_frame: f64,
    /// The forwarder's voluntary context switches per frame forwarded.
    pub(crate) vcsw_per_frame: f64,
    /// The forwarder's non-voluntary context switches per frame forwarded.
    pub(crate) ivcsw_per_frame: f64,
    /// Datagrams dropped by the kernel at the forwarder's ingress socket (buffer full).
    pub(crate) ingress_drops: u64,
    /// Datagrams dropped by the kernel at the sinks' sockets (should stay 0).
    pub(crate) sink_drops: u64,
    /// Time the hypervisor kept the machine's CPUs from running while the phase ran, % of
    /// the CPUs' time (`steal` in /proc/stat). A stall of a CPU delays every frame waiting
    /// on it, whichever forwarder runs: the p99 latencies are only comparable when this is
    /// near 0.
    pub(crate) steal_pct: f64,
    /// Interrupts between the machine's CPUs (rescheduling, function call and TLB shootdown
    /// IPIs, from /proc/interrupts) per frame forwarded: on a virtual machine, each one to a
    /// halted CPU waits for the host to run that CPU again.
    pub(crate) ipi_per_frame: f64,
}

pub(crate) fn generate(sock: &UdpSocket, phase: u32, load: Load) -> (u64, u64, u64) {
    let mut frame = [0u8; FRAME_LEN];
    let start = Instant::now();
    let period_ns = load.rate.map(|r| 1e9 / f64::from(r));
    let first = now_ns();
    for seq in 0..load.count {
        if let Some(p) = period_ns {
            let due = start + Duration::from_nanos((f64::from(seq) * p) as u64);
            let now = Instant::now();
            if due > now {
                std::thread::sleep(due - now);
            }
        }
        fill_frame(&mut frame, seq, phase, now_ns());
        // A send error (ENOBUFS…) is a frame not sent: it is not counted.
        let _ = sock.send(&frame);
    }
    (u64::from(load.count), first, now_ns())
}

/// What the sinks and the kernel saw of one forwarder over one or more slices of a phase.
#[derive(Clone, Default)]
pub(crate) struct Tally {
    pub(crate) sent: u64,
    pub(crate) delivered: u64,
    /// Σ over slices of (last receive − first send), ns.
    pub(crate) rx_span_ns: u64,
    /// Σ over slices of (last send − first send), ns.
    pub(crate) tx_span_ns: u64,
    /// Σ over slices of the wall time (generate, then settle), s.
    pub(crate) wall_s: f64,
    pub(crate) lat_ns: Vec<u32>,
    pub(crate) ingress_drops: u64,
    pub(crate) sink_drops: u64,
    /// Σ over slices of the machine's steal jiffies.
    pub(crate) steal_jiffies: u64,
    /// Σ over slices of the machine's interrupts between CPUs.
    pub(crate) ipis: u64,
}

/// Sends `load` through `fwd` as phase `phase` and adds what arrived to `tally`.
pub(crate) fn run_slice(
    fwd: &Forwarder,
    gen_sock: &UdpSocket,
    sinks: &Sinks,
    phase: u32,
    load: Load,
    tally: &mut Tally,
) {
    let n = sinks.sinks.len() as u64;
    sinks.begin(phase);
    let drops = |fwd: &Forwarder| {
        (
            udp_drops(fwd.ingress.port()),
            sinks
                .sinks
                .iter()
                .map(|s| udp_drops(s.addr.port()))
                .sum::<u64>(),
        )
    };
    let (in0, sink0) = drops(fwd);
    let steal0 = steal_jiffies();
    let ipi0 = ipis();
    let t0 = Instant::now();
    let (sent, first_send, last_send) = generate(gen_sock, phase, load);
    let accs = sinks.settle(sent * n, Duration::from_millis(300));
    tally.wall_s += t0.elapsed().as_secs_f64();
    tally.steal_jiffies += steal_jiffies().saturating_sub(steal0);
    tally.ipis += ipis().saturating_sub(ipi0);
    let (in1, sink1) = drops(fwd);
    let delivered: u64 = accs.iter().map(|a| a.count).sum();
    let last_rx = accs.iter().map(|a| a.last_ns).max().unwrap_or(first_send);
    if let (Some(dir), Some(rate)) = (latency_dump(), load.rate) {
        use std::fmt::Write as _;
        let mut text = String::new();
        for a in &accs {
            for (t, l) in a.rx_ns.iter().zip(&a.lat_ns) {
                let _ = writeln!(text, "{t} {l}");
            }
        }
        let _ = std::fs::write(dir.join(format!("phase{phase}-{rate}.txt")), text);
    }
    tally.sent += sent;
    tally.delivered += delivered;
    tally.rx_span_ns += last_rx.max(first_send + 1) - first_send;
    tally.tx_span_ns += last_send.max(first_send + 1) - first_send;
    tally
        .lat_ns
        .extend(accs.iter().flat_map(|a| a.lat_ns.iter().copied()));
    tally.ingress_drops += in1 - in0;
    tally.sink_drops += sink1 - sink0;
}

/// A phase's figures from its tally and the forwarder's use of the CPU over it.
pub(crate) fn phase_result(mut t: Tally, used: Used, clients: usize) -> PhaseResult {
    let n = clients as u64;
    // Frames forwarded to every client (on average): the unit of work of a forwarder.
    let frames = (t.delivered as f64 / n as f64).max(1.0);
    t.lat_ns.sort_unstable();
    let lat = &t.lat_ns;
    let pct = |q: f64| {
        if lat.is_empty() {
            f64::NAN
        } else {
            f64::from(lat[((lat.len() - 1) as f64 * q).round() as usize]) / 1e3
        }
    };
    PhaseResult {
        sent: t.sent,
        delivered: t.delivered,
        delivered_per_s: t.delivered as f64 / (t.rx_span_ns.max(1) as f64 / 1e9),
        offered_per_s: t.sent as f64 / (t.tx_span_ns.max(1) as f64 / 1e9),
        loss: 1.0 - t.delivered as f64 / (t.sent * n).max(1) as f64,
        p50_us: pct(0.50),
        p99_us: pct(0.99),
        max_us: pct(1.0),
        // The settle wait is part of the window: a forwarder still draining its backlog then
        // is charged for it; an idle one costs (almost) nothing.
        cpu_pct: 100.0 * used.cpu_s / t.wall_s.max(1e-9),
        cpu_ns_per_frame: used.cpu_s * 1e9 / frames,
        vcsw_per_frame: used.voluntary as f64 / frames,
        ivcsw_per_frame: used.involuntary as f64 / frames,
        ingress_drops: t.ingress_drops,
        sink_drops: t.sink_drops,
        steal_pct: 100.0 * t.steal_jiffies as f64 / (t.wall_s.max(1e-9) * JIFFIES_PER_S * cpus()),
        ipi_per_frame: t.ipis as f64 / frames,
    }
}

/// One forwarder alone: a warm-up or the saturation phase.
pub(crate) fn run_phase(
    fwd: &Forwarder,
    gen_sock: &UdpSocket,
    sinks: &Sinks,
    phase: u32,
    load: Load,
) -> PhaseResult {
    let cpu0 = fwd.cpu();
    let mut tally = Tally::default();
    run_slice(fwd, gen_sock, sinks, phase, load, &mut tally);
    phase_result(tally, fwd.cpu().since(&cpu0), sinks.sinks.len())
}

/// Length of one forwarder's turn in an interleaved paced phase (`FORWARDING_INTERLEAVE=1`), s.
pub(crate) const TURN_S: f64 = 1.0;

/// Traffic a forwarder gets before each of its turns in an interleaved phase, not counted, s:
/// the turn then meets a forwarder already woken up and running, as in a plain phase.
pub(crate) const WARM_S: f64 = 0.1;

/// A paced phase for every forwarder of `fwds`: turns of `turn_s` each, taken in alternating
/// order (A B, B A, A B…), until each forwarder has had `paced_s` of traffic. With one
/// forwarder and `turn_s` = `paced_s`, one plain phase. In turns, each turn follows
/// [`WARM_S`] of uncounted traffic to the same forwarder, and a forwarder's CPU and context
/// switches are counted over its counted turns only.
pub(crate) fn run_paced(
    fwds: &[(&Forwarder, &UdpSocket)],
    sinks: &Sinks,
    next_phase: &mut impl FnMut() -> u32,
    rate: u32,
    paced_s: f64,
    turn_s: f64,
) -> Vec<PhaseResult> {
    let turns = (paced_s / turn_s).round().max(1.0) as u32;
    let per_turn = (f64::from(rate) * paced_s / f64::from(turns)).round() as u32;
    let warm = (turns > 1).then(|| Load {
        rate: Some(rate),
        count: ((f64::from(rate) * WARM_S).round() as u32).max(10),
    });
    let mut used = vec![Used::default(); fwds.len()];
    let mut tallies = vec![Tally::default(); fwds.len()];
    for turn in 0..turns {
        let mut order: Vec<usize> = (0..fwds.len()).collect();
        if turn % 2 == 1 {
            order.reverse();
        }
        for k in order {
            let (fwd, gen_sock) = fwds[k];
            if let Some(warm) = warm {
                let mut ignored = Tally::default();
                run_slice(fwd, gen_sock, sinks, next_phase(), warm, &mut ignored);
            }
            let load = Load {
                rate: Some(rate),
                count: per_turn,
            };
            let cpu0 = fwd.cpu();
            run_slice(fwd, gen_sock, sinks, next_phase(), load, &mut tallies[k]);
            used[k].add(fwd.cpu().since(&cpu0));
        }
    }
    tallies
        .into_iter()
        .zip(used)
        .map(|(t, u)| phase_result(t, u, sinks.sinks.len()))
        .collect()
}

pub(crate) struct Scenario {
    pub(crate) kind: Kind,
    pub(crate) clients: usize,
    pub(crate) sat: PhaseResult,
    pub(crate) paced: Vec<(u32, PhaseResult)>,
    pub(crate) threads: usize,
    /// Peak resident set size of the forwarder process, bytes.
    pub(crate) peak_rss: u64,
    pub(crate) tlog_bytes: Option<u64>,
    pub(crate) last_status: String,
}

/// Every forwarder of `kinds` with the same sinks: each warmed up and saturated in turn, then
/// the paced phases in turns of `turn_s` ([`run_paced`]).
pub(crate) fn run_scenarios(
    kinds: &[Kind],
    sinks: &Sinks,
    cfg: &Cfg,
    next_phase: &mut u32,
    turn_s: f64,
) -> Vec<Scenario> {
    let addrs: Vec<SocketAddr> = sinks.sinks.iter().map(|s| s.addr).collect();
    let mut phase = || {
        *next_phase += 1;
        *next_phase
    };
    let fwds: Vec<(Forwarder, UdpSocket)> = kinds
        .iter()
        .map(|&kind| {
            let fwd = Forwarder::start(kind, &addrs);
            let gen_sock = UdpSocket::bind("127.0.0.1:0").unwrap();
            gen_sock.connect(fwd.ingress).unwrap();
            (fwd, gen_sock)
        })
        .collect();
    let mut sats = Vec::new();
    for (fwd, gen_sock) in &fwds {
        eprintln!("  {}: saturation…", fwd.kind.name());
        // Warm-up: the daemon's udpin creates the vehicle link on the first datagram. Repeat
        // until a frame gets through (the link comes up within milliseconds).
        for _ in 0..50 {
            let r = run_phase(
                fwd,
                gen_sock,
                sinks,
                phase(),
                Load {
                    rate: Some(1000),
                    count: 20,
                },
            );
            if r.delivered > 0 {
                break;
            }
        }
        sats.push(run_phase(
            fwd,
            gen_sock,
            sinks,
            phase(),
            Load {
                rate: None,
                count: cfg.sat_count,
            },
        ));
    }
    let pairs: Vec<(&Forwarder, &UdpSocket)> = fwds.iter().map(|(f, g)| (f, g)).collect();
    let mut paced: Vec<Vec<(u32, PhaseResult)>> = vec![Vec::new(); fwds.len()];
    for &rate in &cfg.rates {
        eprintln!("  paced {}/s…", kmsg(f64::from(rate)));
        let rs = run_paced(&pairs, sinks, &mut phase, rate, cfg.paced_s, turn_s);
        for (k, r) in rs.into_iter().enumerate() {
            paced[k].push((rate, r));
        }
    }
    fwds.into_iter()
        .zip(sats.into_iter().zip(paced))
        .map(|((fwd, _), (sat, paced))| {
            let threads = fwd.threads();
            let peak_rss = fwd.peak_rss();
            let last_status = fwd.last_status.lock().unwrap().clone();
            let kind = fwd.kind;
            let tlog_bytes = fwd.stop();
            Scenario {
                kind,
                clients: addrs.len(),
                sat,
                paced,
                threads,
                peak_rss,
                tlog_bytes,
                last_status,
            }
        })
        .collect()
}
