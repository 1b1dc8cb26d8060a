//! Fleet telemetry over Zenoh into one ground daemon, or a fleet of a thousand into four; the
//! same over UDP side by side; and the soak.
//!
//! ```text
//! cargo bench --bench zenoh_fleet                # 100 vehicles, 10 s measured, prints a table
//! cargo bench --bench zenoh_fleet -- --runs 3    # three runs; every figure is the median
//! cargo test  --bench zenoh_fleet                # smoke run: 8 vehicles over 2 daemons, 2 s
//! ZENOH_FLEET_VEHICLES=1000 ZENOH_FLEET_DAEMONS=4 ZENOH_FLEET_SECONDS=60 \
//!     cargo bench --bench zenoh_fleet            # a thousand vehicles over four daemons
//! ZENOH_FLEET_TRANSPORT=udp cargo bench --bench zenoh_fleet   # the same vehicles over UDP
//! ZENOH_FLEET_VEHICLES=1000 ZENOH_FLEET_DAEMONS=4 ZENOH_FLEET_SECONDS=3600 \
//!     cargo bench --bench zenoh_fleet -- --soak  # the hour-long soak (docs/fleet.md)
//! cargo test  --bench zenoh_fleet -- --soak      # the soak tests/run.sh runs: 60 s measured
//! ```
//! Environment: `ZENOH_FLEET_VEHICLES=N`, `ZENOH_FLEET_DAEMONS=D` (at most 250 vehicles each),
//! `ZENOH_FLEET_SECONDS=S` (the measured window), `ZENOH_FLEET_CHURN=P` (the chance that a
//! vehicle leaves in a given second; default 0.01, 0 for UDP), `ZENOH_FLEET_SEED=N` (default 38),
//! `ZENOH_FLEET_TRANSPORT=udp`, `ZENOH_FLEET_ALIGNED=1` (every vehicle's 10 Hz and 1 Hz frames
//! in the same tick, the worst case), `ZENOH_FLEET_DAEMON_RUNTIME=R` (the daemons' `ZENOH_RUNTIME`,
//! e.g. `(rx: (worker_threads: 1))`), `ZENOH_FLEET_DAEMON_WRAP='CMD ARGS'` (the daemons run as
//! `CMD ARGS vtol-gcs run ...`, e.g. `env LD_PRELOAD=... DUMP_HEAPTRACK_OUTPUT=FIFO` for a heap
//! profile: `env` keeps the daemon's process id, so its footprint is still the daemon's).
//!
//! MAVLink system ids stop at 255, so a fleet larger than that is served by several daemons,
//! each selecting its part by key expression: daemon K runs `--vehicle 'zenoh:bench-dK/*'`
//! (the key expression `vtol/bench-dK/*`) and its vehicles are `bench-dK/v1` … `bench-dK/v250`,
//! system ids 1 to 250 within each part, all on the one router (docs/fleet.md plans the
//! system-id space of a large fleet).
//!
//! Set-up, all on loopback TCP:
//! - a Zenoh router: this executable re-run as `--router ENDPOINT`, its own process (a session
//!   in router mode, what `zenohd` runs);
//! - each ground daemon, the real binary: `vtol-gcs run --vehicle 'zenoh:bench-dK/*'
//!   --zenoh-mode client --zenoh-connect ROUTER --serve udpout:127.0.0.1:CLIENT --log-dir TMP
//!   --headless` (tlog on);
//! - the vehicles, in this process, synthetic (no physics: a thousand twins would take far more
//!   than this machine's two cores): one client session of the router per daemon's part with,
//!   per vehicle, a liveliness token on `vtol/bench-dK/vN` and a publisher on
//!   `vtol/bench-dK/vN/from_vehicle` (what `vtol-gcs run --serve zenoh:bench-dK/vN` declares).
//!   Each vehicle (system id N) publishes ATTITUDE at 50 Hz, SERVO_OUTPUT_RAW at 10 Hz and
//!   HEARTBEAT at 1 Hz, one frame per publication, on a fixed schedule with the vehicles spread
//!   over each 20 ms tick and each vehicle's SERVO_OUTPUT_RAW and HEARTBEAT at a phase of its
//!   own (fleet index N sends them in the ticks where tick + N is a multiple of 5 and of 50), as
//!   vehicles started at different times do. During the window, each second each vehicle leaves with the churn's
//!   chance (its last publication, then its token dropped 20 ms later) and comes back 1 to 5 s
//!   later (a new token, then its publications from the next tick), from a seeded generator;
//! - the clients: one UDP socket per daemon in this process (its own MAVLink client), where that
//!   daemon sends everything.
//!
//! After a warm-up (every vehicle heard at its client, then 1 s), a measured window: per daemon,
//! loss = 1 − received / published for the telemetry (ATTITUDE and SERVO_OUTPUT_RAW) published
//! in the window, the client socket's kernel drops counted apart (the client not keeping up is
//! not the daemon's loss); latency = receive time − publication time per frame (both in this
//! process, matched by system id and sequence number); CPU = the daemon's CPU time over the
//! window (`/proc/<pid>/task/*/schedstat`, all threads) per second (100 % = one core) and per
//! delivered frame; resident memory and descriptors at the window's start and end; the
//! router's CPU and Zenoh sessions (its established TCP connections).
//!
//! `--soak` first runs 130 s of traffic (`ZENOH_FLEET_FILL`; vehicles already leaving and
//! joining) so that the daemons' chart history, which keeps 120 s, is full; then it samples every
//! daemon's footprint and the router's sessions through the window and fails unless descriptors
//! and sessions end where they were, resident memory grew no more than 10 % + 2 MB over the
//! window, and no frame that reached a daemon was lost.

mod measure;
mod procs;
mod run;

use run::{RunResult, Setup};

fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}

fn setup(args: &[String]) -> (Setup, usize, bool) {
    let env = |k: &str| std::env::var(k).ok().and_then(|v| v.parse::<f64>().ok());
    // `cargo bench` passes --bench; `cargo test` runs a harness = false target without it.
    let quick = !args.iter().any(|a| a == "--bench");
    let soak = args.iter().any(|a| a == "--soak");
    let udp = std::env::var("ZENOH_FLEET_TRANSPORT").is_ok_and(|t| t == "udp");
    // The soak under `cargo test` (tests/run.sh): 60 vehicles over 4 daemons for 60 s, what
    // two shared cores carry in the test profile beside the rest of the suite.
    let (v0, d0, s0) = match (quick, soak) {
        (true, true) => (60.0, 4.0, 60.0),
        (true, false) => (8.0, 2.0, 2.0),
        (false, _) => (100.0, 1.0, 10.0),
    };
    let vehicles = env("ZENOH_FLEET_VEHICLES").unwrap_or(v0) as usize;
    let daemons = env("ZENOH_FLEET_DAEMONS").unwrap_or(d0) as usize;
    let seconds = env("ZENOH_FLEET_SECONDS").unwrap_or(s0);
    let churn = if udp {
        0.0
    } else {
        env("ZENOH_FLEET_CHURN").unwrap_or(0.01)
    };
    let runs = args
        .iter()
        .position(|a| a == "--runs")
        .and_then(|i| args.get(i + 1)?.parse::<usize>().ok())
        .unwrap_or(1)
        .max(1);
    assert!(daemons >= 1, "ZENOH_FLEET_DAEMONS: at least 1");
    assert!(
        vehicles >= 1 && vehicles.div_ceil(daemons) <= 250,
        "1 to 250 vehicles per daemon (MAVLink system ids stop at 255)"
    );
    let s = Setup {
        vehicles,
        daemons,
        seconds,
        churn,
        seed: env("ZENOH_FLEET_SEED").map_or(38, |s| s as u64),
        udp,
        sample_every: (seconds / 12.0).max(1.0),
        // The daemons' chart history keeps 120 s (src/tracker/history.rs): a soak measures
        // from 10 s after it is full.
        fill: env("ZENOH_FLEET_FILL").unwrap_or(if soak { 130.0 } else { 0.0 }),
        aligned: std::env::var("ZENOH_FLEET_ALIGNED").is_ok_and(|a| a == "1"),
    };
    (s, runs, soak)
}

fn main() {
    let args: Vec<String> = std::env::args().collect();
    if let Some(i) = args.iter().position(|a| a == "--router") {
        procs::router(args.get(i + 1).map_or("", String::as_str));
    }
    let _ = measure::now_ns();
    let (s, runs, soak) = setup(&args);
    let mut results = Vec::new();
    for r in 0..runs {
        eprintln!(
            "run {}/{runs}: {} vehicles over {} daemon(s) by {} for {} s (churn {}/s, seed {})…",
            r + 1,
            s.vehicles,
            s.daemons,
            if s.udp { "UDP" } else { "Zenoh" },
            s.seconds,
            s.churn,
            s.seed
        );
        let res = run::one_run(&s);
        for (d, x) in res.daemons.iter().enumerate() {
            eprintln!(
                "  daemon {d}: published {} received {} client drops {} p99 {:.2} ms CPU {:.1} %",
                x.published,
                x.received,
                x.client_drops,
                x.p99_ms,
                100.0 * x.cpu_ns as f64 / (res.window_s * 1e9)
            );
        }
        results.push(res);
    }
    report(&s, &results);
    for r in &results {
        check(r, soak);
    }
}

/// Prints the run's tables (Markdown, as docs/benchmarks/zenoh_fleet.md keeps them).
// Over 80 lines: a one-pass formatter, one statement per row of the tables.
fn report(s: &Setup, results: &[RunResult]) {
    let m = |f: &dyn Fn(&RunResult) -> f64| median(results.iter().map(f).collect());
    let sum =
        |r: &RunResult, f: fn(&run::DaemonResult) -> u64| r.daemons.iter().map(f).sum::<u64>();
    let expected = s.vehicles as f64 * 60.0;
    let how = if s.udp { "UDP (udpin)" } else { "Zenoh" };
    println!(
        "\n## Fleet over {how}: {} vehicles × (50 Hz ATTITUDE + 10 Hz SERVO_OUTPUT_RAW + 1 Hz \
         HEARTBEAT) over {} ground daemon(s), {} s measured, churn {}/s, seed {}, {} run(s), \
         medians\n",
        s.vehicles,
        s.daemons,
        s.seconds,
        s.churn,
        s.seed,
        results.len()
    );
    println!("| figure | value | target |");
    println!("|---|---|---|");
    println!(
        "| published telemetry | {:.0} frames/s (schedule: {expected:.0} while all fly) | |",
        m(&|r| sum(r, |d| d.published) as f64 / r.window_s)
    );
    println!(
        "| delivered to the clients | {:.0} frames/s | |",
        m(&|r| sum(r, |d| d.received) as f64 / r.window_s)
    );
    println!(
        "| loss (all daemons) | {:.3} % ({:.0} frames; client sockets' kernel drops {:.0}) | 0 % |",
        m(&|r| 100.0
            * (1.0 - sum(r, |d| d.received) as f64 / sum(r, |d| d.published).max(1) as f64)),
        m(&|r| sum(r, |d| d.published).saturating_sub(sum(r, |d| d.received)) as f64),
        m(&|r| sum(r, |d| d.client_drops) as f64)
    );
    let worst = |f: fn(&run::DaemonResult) -> f64| {
        move |r: &RunResult| r.daemons.iter().map(f).fold(f64::NAN, f64::max)
    };
    println!(
        "| latency p50 (worst daemon) | {:.2} ms | |",
        m(&worst(|d| d.p50_ms))
    );
    println!(
        "| latency p99 (worst daemon) | {:.2} ms | < 10 ms |",
        m(&worst(|d| d.p99_ms))
    );
    println!("| latency max | {:.2} ms | |", m(&worst(|d| d.max_ms)));
    println!(
        "| ground daemons' CPU | {:.1} % of a core in all, {:.1} µs per delivered frame | |",
        m(&|r| 100.0 * sum(r, |d| d.cpu_ns) as f64 / (r.window_s * 1e9)),
        m(&|r| sum(r, |d| d.cpu_ns) as f64 / sum(r, |d| d.received).max(1) as f64 / 1e3)
    );
    println!(
        "| busiest ground daemon | {:.1} % of a core | < 50 % |",
        m(
            &|r| 100.0 * r.daemons.iter().map(|d| d.cpu_ns).max().unwrap_or(0) as f64
                / (r.window_s * 1e9)
        )
    );
    println!(
        "| Zenoh router CPU | {:.1} % of a core | |",
        m(&|r| 100.0 * r.router_cpu_ns as f64 / (r.window_s * 1e9))
    );
    let last = results.last().expect("a run");
    println!(
        "| vehicles left / came back (last run) | {} / {} | |",
        last.left, last.joined
    );
    if let (Some(a), Some(b)) = (last.samples.first(), last.samples.last()) {
        println!(
            "| Zenoh sessions at the router, window start → end | {} → {} | flat |",
            a.sessions, b.sessions
        );
    }
    println!("\nPer daemon (last run):\n");
    println!(
        "| daemon | vehicles | published | received | loss | p50 | p99 | CPU | per frame | RSS start → end | fds |"
    );
    println!("|---|---|---|---|---|---|---|---|---|---|---|");
    for (i, d) in last.daemons.iter().enumerate() {
        println!(
            "| {i} | {} | {} | {} | {:.3} % | {:.2} ms | {:.2} ms | {:.1} % | {:.1} µs | {:.1} → {:.1} MB | {} → {} |",
            d.served,
            d.published,
            d.received,
            100.0 * (1.0 - d.received as f64 / d.published.max(1) as f64),
            d.p50_ms,
            d.p99_ms,
            100.0 * d.cpu_ns as f64 / (last.window_s * 1e9),
            d.cpu_ns as f64 / d.received.max(1) as f64 / 1e3,
            d.rss_kb.0 as f64 / 1024.0,
            d.rss_kb.1 as f64 / 1024.0,
            d.fds.0,
            d.fds.1
        );
    }
    // The footprint samples (a soak's): whether memory levels off or keeps rising.
    if last.samples.len() > 2 {
        println!("\nResident memory through the window (MB):\n");
        for d in 0..last.daemons.len() {
            let mb: Vec<String> = last
                .samples
                .iter()
                .map(|s| format!("{:.0} s {:.1}", s.t_s, s.rss_kb[d] as f64 / 1024.0))
                .collect();
            println!("- daemon {d}: {}", mb.join(", "));
        }
    }
}

/// Every run: the telemetry arrives. A soak: descriptors, sessions and memory flat and no frame
/// lost that reached a daemon.
fn check(r: &RunResult, soak: bool) {
    for (i, d) in r.daemons.iter().enumerate() {
        assert!(
            d.received * 2 >= d.published && d.published > 0,
            "daemon {i}: received {} of {} published frames",
            d.received,
            d.published
        );
        if soak {
            assert_eq!(
                d.received + d.client_drops,
                d.published,
                "daemon {i}: {} published, {} received, {} dropped at the client's socket",
                d.published,
                d.received,
                d.client_drops
            );
        }
    }
    if !soak {
        return;
    }
    let (first, last) = (r.samples.first().unwrap(), r.samples.last().unwrap());
    assert_eq!(
        first.sessions, last.sessions,
        "Zenoh sessions at the router"
    );
    for d in 0..r.daemons.len() {
        assert!(
            last.fds[d] <= first.fds[d],
            "daemon {d}: descriptors {} → {}",
            first.fds[d],
            last.fds[d]
        );
        let (a, b) = (first.rss_kb[d], last.rss_kb[d]);
        assert!(
            b <= a + a / 10 + 2048,
            "daemon {d}: resident memory {a} kB at {:.0} s → {b} kB at {:.0} s",
            first.t_s,
            last.t_s
        );
    }
    eprintln!(
        "soak: descriptors, sessions and memory flat over {} samples, no frame lost",
        r.samples.len()
    );
}
