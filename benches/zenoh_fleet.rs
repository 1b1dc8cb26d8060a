//! Fleet telemetry over Zenoh into one ground daemon, or a larger fleet into several.
//!
//! ```text
//! cargo bench --bench zenoh_fleet                # 100 vehicles, 10 s measured, prints a table
//! cargo bench --bench zenoh_fleet -- --runs 3    # three runs; every figure is the median
//! cargo test  --bench zenoh_fleet                # smoke run: 5 vehicles, 1 s
//! ZENOH_FLEET_VEHICLES=1000 ZENOH_FLEET_DAEMONS=4 ZENOH_FLEET_SECONDS=60 \
//!     cargo bench --bench zenoh_fleet            # a thousand vehicles over four daemons
//! ```
//! (`ZENOH_FLEET_VEHICLES=N` and `ZENOH_FLEET_SECONDS=S` change the size and the length;
//! `ZENOH_FLEET_DAEMONS=D` splits the vehicles over D ground daemons, at most 250 each.)
//!
//! MAVLink system ids stop at 255, so a fleet larger than that is served by several daemons,
//! each selecting its part by key expression: daemon K runs `--vehicle 'zenoh:bench-dK/*'`
//! (the key expression `vtol/bench-dK/*`) and its vehicles are `bench-dK/v1` … `bench-dK/v250`,
//! system ids 1 to 250 within each part, all on the one router.
//!
//! Set-up, all on loopback TCP:
//! - a Zenoh router: this executable re-run as `--router ENDPOINT`, its own process (a session
//!   in router mode, what `zenohd` runs);
//! - each ground daemon, the real binary: `vtol-gcs run --vehicle 'zenoh:bench-dK/*'
//!   --zenoh-mode client --zenoh-connect ROUTER --serve udpout:127.0.0.1:SINK --log-dir TMP
//!   --headless` (tlog on);
//! - the vehicles' ends, in this process: one client session of the router with, per vehicle,
//!   a liveliness token on `vtol/bench-dK/vN` and a publisher on `vtol/bench-dK/vN/from_vehicle`
//!   (what `vtol-gcs run --serve zenoh:bench-dK/vN` declares). Each vehicle (system id N)
//!   publishes ATTITUDE at 50 Hz, SERVO_OUTPUT_RAW at 10 Hz and HEARTBEAT at 1 Hz, one frame per
//!   publication, on a fixed schedule with the vehicles spread over each 20 ms tick;
//! - the clients: a UDP socket per daemon in this process, where that daemon sends everything.
//!
//! After a warm-up (every vehicle heard at the client, then 1 s), a measured window: delivered
//! rate = telemetry frames (ATTITUDE and SERVO_OUTPUT_RAW) published in the window and received
//! by the client / window; loss = 1 − received / published; latency = receive time − publication
//! time per frame (both in this process, matched by system id, message and sequence number);
//! CPU = the ground daemons' CPU time over the window (`/proc/<pid>/task/*/schedstat`, all
//! threads) per second (100 % = one core) and per delivered frame, and the busiest daemon's;
//! the router's likewise.

use std::io::{BufRead, BufReader};
use std::net::UdpSocket;
use std::process::{Child, Command, Stdio};
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::{Arc, Mutex, OnceLock};
use std::time::{Duration, Instant};

use vtol_link::Frame;
use vtol_link::dialect::{self, MavMessage};

const ATTITUDE: u32 = 30;
const SERVO_OUTPUT_RAW: u32 = 36;

fn epoch() -> Instant {
    static EPOCH: OnceLock<Instant> = OnceLock::new();
    *EPOCH.get_or_init(Instant::now)
}

fn now_ns() -> u64 {
    u64::try_from(epoch().elapsed().as_nanos()).unwrap_or(u64::MAX)
}

fn free_tcp_port() -> u16 {
    std::net::TcpListener::bind("127.0.0.1:0")
        .unwrap()
        .local_addr()
        .unwrap()
        .port()
}

/// CPU time of every thread of a process, ns.
fn cpu_ns(pid: u32) -> u64 {
    let Ok(dir) = std::fs::read_dir(format!("/proc/{pid}/task")) else {
        return 0;
    };
    dir.flatten()
        .filter_map(|e| std::fs::read_to_string(e.path().join("schedstat")).ok())
        .filter_map(|s| s.split_whitespace().next()?.parse::<u64>().ok())
        .sum()
}

/// Resident memory (kB) and open descriptors of a process: what a soak watches stay flat.
fn footprint(pid: u32) -> (u64, u64) {
    let rss = std::fs::read_to_string(format!("/proc/{pid}/status"))
        .ok()
        .and_then(|s| {
            s.lines()
                .find_map(|l| l.strip_prefix("VmRSS:"))
                .and_then(|v| v.split_whitespace().next()?.parse().ok())
        })
        .unwrap_or(0);
    let fds = std::fs::read_dir(format!("/proc/{pid}/fd")).map_or(0, |d| d.count() as u64);
    (rss, fds)
}

/// Publication times (ns) by vehicle and sequence number (a vehicle's frames share one
/// sequence, as on a real link; it wraps every 4 s, far beyond any latency).
struct Sent(Vec<[AtomicU64; 256]>);

impl Sent {
    fn new(vehicles: usize) -> Self {
        Sent(
            (0..vehicles)
                .map(|_| std::array::from_fn(|_| AtomicU64::new(0)))
                .collect(),
        )
    }
    /// Vehicle `v` (0-based over the whole fleet).
    fn slot(&self, v: usize, seq: u8) -> &AtomicU64 {
        &self.0[v][usize::from(seq)]
    }
}

#[derive(Default)]
struct Received {
    window: Option<(u64, u64)>,
    frames: u64,
    latencies_ns: Vec<u64>,
    /// Vehicles (0-based over the whole fleet) heard at their daemon's client.
    vehicles_heard: std::collections::HashSet<usize>,
}

/// Which part of the fleet a client's daemon serves: vehicles `first ..= first + per - 1`
/// (0-based), system ids 1 to `per`.
#[derive(Clone, Copy)]
struct Part {
    first: usize,
    per: usize,
    vehicles: usize,
}

/// A client: receives its daemon's UDP copies and matches telemetry to its publication.
fn sink(sock: &UdpSocket, part: Part, sent: &Sent, acc: &Mutex<Received>, stop: &AtomicBool) {
    sock.set_read_timeout(Some(Duration::from_millis(50)))
        .unwrap();
    let mut buf = [0u8; 2048];
    while !stop.load(Ordering::Relaxed) {
        let Ok(n) = sock.recv(&mut buf) else { continue };
        let t = now_ns();
        let d = &buf[..n];
        // MAVLink 2 header: magic, len, incompat, compat, seq, sysid, compid, msgid (3 bytes).
        if n < 12 || d[0] != 0xFD {
            continue;
        }
        let (seq, sys) = (d[4], d[5]);
        let msgid = u32::from(d[7]) | u32::from(d[8]) << 8 | u32::from(d[9]) << 16;
        let v = part.first + usize::from(sys).wrapping_sub(1);
        if sys == 0 || usize::from(sys) > part.per || v >= part.vehicles {
            continue;
        }
        let mut a = acc.lock().unwrap();
        a.vehicles_heard.insert(v);
        if !matches!(msgid, ATTITUDE | SERVO_OUTPUT_RAW) {
            continue;
        }
        let t0 = sent.slot(v, seq).load(Ordering::Acquire);
        if let Some((start, end)) = a.window
            && t0 >= start
            && t0 < end
        {
            a.frames += 1;
            a.latencies_ns.push(t.saturating_sub(t0));
        }
    }
}

fn attitude(t_ms: u32) -> MavMessage {
    MavMessage::ATTITUDE(dialect::ATTITUDE_DATA {
        time_boot_ms: t_ms,
        roll: 0.01,
        pitch: -0.02,
        yaw: 1.5,
        ..Default::default()
    })
}

fn servo(t_ms: u32) -> MavMessage {
    MavMessage::SERVO_OUTPUT_RAW(dialect::SERVO_OUTPUT_RAW_DATA {
        time_usec: t_ms.wrapping_mul(1000),
        servo1_raw: 1500,
        servo2_raw: 1510,
        ..Default::default()
    })
}

fn heartbeat() -> MavMessage {
    MavMessage::HEARTBEAT(dialect::HEARTBEAT_DATA {
        mavtype: dialect::MavType::MAV_TYPE_VTOL_TAILSITTER_DUOROTOR,
        autopilot: dialect::MavAutopilot::MAV_AUTOPILOT_ARDUPILOTMEGA,
        base_mode: dialect::MavModeFlag::MAV_MODE_FLAG_CUSTOM_MODE_ENABLED,
        custom_mode: 17,
        system_status: dialect::MavState::MAV_STATE_STANDBY,
        mavlink_version: 3,
    })
}

struct Proc(Child);

impl Drop for Proc {
    fn drop(&mut self) {
        let _ = Command::new("kill")
            .args(["-TERM", &self.0.id().to_string()])
            .status();
        let deadline = Instant::now() + Duration::from_secs(5);
        while Instant::now() < deadline {
            if let Ok(Some(_)) = self.0.try_wait() {
                return;
            }
            std::thread::sleep(Duration::from_millis(10));
        }
        let _ = self.0.kill();
        let _ = self.0.wait();
    }
}

/// Starts a process and waits for a line starting with `ready` on its stdout.
fn spawn_ready(mut cmd: Command, ready: &'static str) -> Proc {
    let mut child = cmd
        .stdout(Stdio::piped())
        .stdin(Stdio::piped())
        .spawn()
        .expect("spawn");
    let out = child.stdout.take().unwrap();
    let (tx, rx) = std::sync::mpsc::channel();
    std::thread::spawn(move || {
        for line in BufReader::new(out).lines() {
            let Ok(line) = line else { break };
            if line.starts_with(ready) {
                let _ = tx.send(());
            }
        }
    });
    rx.recv_timeout(Duration::from_secs(30))
        .unwrap_or_else(|_| panic!("no '{ready}' line in 30 s"));
    Proc(child)
}

/// `--router ENDPOINT`: a Zenoh router until stdin closes.
fn router(endpoint: &str) -> ! {
    let rt = tokio::runtime::Runtime::new().unwrap();
    rt.block_on(async {
        let opts = vtol_link::ZenohOptions {
            mode: vtol_link::ZenohMode::Router,
            listen: vec![endpoint.to_string()],
            ..Default::default()
        };
        let _session = vtol_link::transport::zenoh::session(&opts)
            .await
            .expect("router session");
        println!("ready");
        let mut line = String::new();
        let _ = tokio::task::spawn_blocking(move || std::io::stdin().read_line(&mut line)).await;
    });
    std::process::exit(0)
}

struct RunResult {
    published: u64,
    received: u64,
    window_s: f64,
    p50_ms: f64,
    p99_ms: f64,
    max_ms: f64,
    daemon_cpu_pct: f64,
    busiest_daemon_cpu_pct: f64,
    daemon_ns_per_frame: f64,
    router_cpu_pct: f64,
    /// The daemons' resident memory (MB) and descriptors, summed, at the window's start and end.
    rss_mb: (f64, f64),
    fds: (u64, u64),
}

fn percentile(sorted: &[u64], p: f64) -> f64 {
    if sorted.is_empty() {
        return f64::NAN;
    }
    let i = ((sorted.len() - 1) as f64 * p).round() as usize;
    sorted[i] as f64 / 1e6
}

/// One measured run of `vehicles` over `daemons` ground daemons.
// Over 80 lines: one sequence of set-up, publication schedule and tear-down; split, its parts
// would pass half a dozen handles between them.
fn one_run(vehicles: usize, daemons: usize, seconds: f64) -> RunResult {
    let per = vehicles.div_ceil(daemons);
    let port = free_tcp_port();
    let endpoint = format!("tcp/127.0.0.1:{port}");
    let mut rcmd = Command::new(std::env::current_exe().unwrap());
    rcmd.args(["--router", &endpoint]);
    let router = spawn_ready(rcmd, "ready");

    let log_dir = tempfile::tempdir().unwrap();
    let sent = Arc::new(Sent::new(vehicles));
    let acc = Arc::new(Mutex::new(Received::default()));
    let stop = Arc::new(AtomicBool::new(false));
    let mut ground = Vec::new();
    let mut sink_threads = Vec::new();
    for d in 0..daemons {
        let sink_sock = UdpSocket::bind("127.0.0.1:0").unwrap();
        let sink_addr = sink_sock.local_addr().unwrap();
        let mut dcmd = Command::new(env!("CARGO_BIN_EXE_vtol-gcs"));
        dcmd.args([
            "run",
            "--vehicle",
            &format!("zenoh:bench-d{d}/*"),
            "--zenoh-mode",
            "client",
            "--zenoh-connect",
            &endpoint,
            "--serve",
            &format!("udpout:{sink_addr}"),
            "--headless",
            "--log-dir",
        ])
        .arg(log_dir.path().join(format!("d{d}")));
        ground.push(spawn_ready(dcmd, "logging "));
        let part = Part {
            first: d * per,
            per,
            vehicles,
        };
        let (sent, acc, stop) = (Arc::clone(&sent), Arc::clone(&acc), Arc::clone(&stop));
        sink_threads.push(std::thread::spawn(move || {
            sink(&sink_sock, part, &sent, &acc, &stop);
        }));
    }
    let ground_cpu =
        |ground: &[Proc]| -> Vec<u64> { ground.iter().map(|p| cpu_ns(p.0.id())).collect() };
    let ground_footprint = |ground: &[Proc]| -> (u64, u64) {
        ground
            .iter()
            .map(|p| footprint(p.0.id()))
            .fold((0, 0), |a, b| (a.0 + b.0, a.1 + b.1))
    };
    let mut foot0 = (0, 0);

    let rt = tokio::runtime::Runtime::new().unwrap();
    let result = rt.block_on(async {
        let opts = vtol_link::ZenohOptions {
            mode: vtol_link::ZenohMode::Client,
            connect: vec![endpoint.clone()],
            ..Default::default()
        };
        let session = vtol_link::transport::zenoh::session(&opts)
            .await
            .expect("vehicles' session");
        let mut publishers = Vec::new();
        let mut tokens = Vec::new();
        for v in 0..vehicles {
            let (fleet, name) = (format!("bench-d{}", v / per), format!("v{}", v % per + 1));
            tokens.push(
                session
                    .liveliness()
                    .declare_token(vtol_link::transport::zenoh::liveliness_key(&fleet, &name))
                    .await
                    .unwrap(),
            );
            publishers.push(
                session
                    .declare_publisher(vtol_link::transport::zenoh::from_vehicle_key(&fleet, &name))
                    .congestion_control(zenoh::qos::CongestionControl::Block)
                    .await
                    .unwrap(),
            );
        }
        let tick = Duration::from_millis(20);
        let start = tokio::time::Instant::now();
        let mut seq = vec![0u8; vehicles];
        let mut published = 0u64;
        let mut ticks = 0u64;
        let mut warm_until: Option<u64> = None;
        let mut window: Option<(u64, u64)> = None;
        let mut cpu0 = (Vec::new(), 0);
        loop {
            // Phase control at each tick start.
            let t = now_ns();
            if warm_until.is_none() && acc.lock().unwrap().vehicles_heard.len() == vehicles {
                warm_until = Some(t + 1_000_000_000);
            }
            if let Some(w) = warm_until
                && window.is_none()
                && t >= w
            {
                let end = t + (seconds * 1e9) as u64;
                window = Some((t, end));
                acc.lock().unwrap().window = window;
                cpu0 = (ground_cpu(&ground), cpu_ns(router.0.id()));
                foot0 = ground_footprint(&ground);
            }
            if let Some((_, end)) = window
                && t >= end
            {
                break;
            }
            if ticks > 3000 {
                panic!(
                    "warm-up: the client heard {} of {vehicles} vehicles in 60 s",
                    acc.lock().unwrap().vehicles_heard.len()
                );
            }
            let t_ms = u32::try_from(ticks * 20).unwrap_or(u32::MAX);
            for (i, p) in publishers.iter().enumerate() {
                // Spread the vehicles over the tick.
                let due = start + tick * ticks as u32 + tick * i as u32 / vehicles as u32;
                tokio::time::sleep_until(due).await;
                let sys = u8::try_from(i % per + 1).unwrap();
                let mut frames = vec![(0usize, attitude(t_ms))];
                if ticks.is_multiple_of(5) {
                    frames.push((1, servo(t_ms)));
                }
                if ticks.is_multiple_of(50) {
                    frames.push((2, heartbeat()));
                }
                for (kind, msg) in frames {
                    let s = seq[i];
                    seq[i] = s.wrapping_add(1);
                    let f = Frame::encode_v2(
                        vtol_link::SystemId(sys),
                        vtol_link::ComponentId(1),
                        s,
                        &msg,
                    );
                    let t_send = now_ns();
                    sent.slot(i, s).store(t_send, Ordering::Release);
                    if kind < 2 && window.is_some_and(|(a, b)| t_send >= a && t_send < b) {
                        published += 1;
                    }
                    p.put(f.as_bytes().to_vec()).await.unwrap();
                }
            }
            ticks += 1;
        }
        let (w0, w1) = window.unwrap();
        let cpu1 = (ground_cpu(&ground), cpu_ns(router.0.id()));
        let foot1 = ground_footprint(&ground);
        // Stragglers: wait up to 1 s for the window's last frames.
        let deadline = Instant::now() + Duration::from_secs(1);
        while Instant::now() < deadline && acc.lock().unwrap().frames < published {
            tokio::time::sleep(Duration::from_millis(10)).await;
        }
        drop(tokens);
        let daemon_cpu: Vec<u64> = cpu1.0.iter().zip(&cpu0.0).map(|(b, a)| b - a).collect();
        (published, w1 - w0, daemon_cpu, cpu1.1 - cpu0.1, foot1)
    });
    stop.store(true, Ordering::Relaxed);
    for t in sink_threads {
        t.join().unwrap();
    }
    drop(ground);
    drop(router);
    let (published, window_ns, daemon_cpus, router_cpu, foot1) = result;
    let daemon_cpu: u64 = daemon_cpus.iter().sum();
    let busiest = daemon_cpus.iter().copied().max().unwrap_or(0);
    let mut a = acc.lock().unwrap();
    a.latencies_ns.sort_unstable();
    let window_s = window_ns as f64 / 1e9;
    RunResult {
        published,
        received: a.frames,
        window_s,
        p50_ms: percentile(&a.latencies_ns, 0.5),
        p99_ms: percentile(&a.latencies_ns, 0.99),
        max_ms: percentile(&a.latencies_ns, 1.0),
        daemon_cpu_pct: 100.0 * daemon_cpu as f64 / window_ns as f64,
        busiest_daemon_cpu_pct: 100.0 * busiest as f64 / window_ns as f64,
        daemon_ns_per_frame: daemon_cpu as f64 / a.frames.max(1) as f64,
        router_cpu_pct: 100.0 * router_cpu as f64 / window_ns as f64,
        rss_mb: (foot0.0 as f64 / 1024.0, foot1.0 as f64 / 1024.0),
        fds: (foot0.1, foot1.1),
    }
}

fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}

fn main() {
    let args: Vec<String> = std::env::args().collect();
    if let Some(i) = args.iter().position(|a| a == "--router") {
        router(args.get(i + 1).map_or("", String::as_str));
    }
    let _ = epoch();
    let env = |k: &str| std::env::var(k).ok().and_then(|v| v.parse::<f64>().ok());
    // `cargo bench` passes --bench; `cargo test` runs a harness = false target without it.
    let quick = !args.iter().any(|a| a == "--bench");
    let vehicles = env("ZENOH_FLEET_VEHICLES").map_or(if quick { 5 } else { 100 }, |v| v as usize);
    let seconds = env("ZENOH_FLEET_SECONDS").unwrap_or(if quick { 1.0 } else { 10.0 });
    let daemons = env("ZENOH_FLEET_DAEMONS").map_or(1, |v| v as usize);
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
    let mut results = Vec::new();
    for r in 0..runs {
        eprintln!(
            "run {}/{runs}: {vehicles} vehicles over {daemons} daemon(s) for {seconds} s…",
            r + 1
        );
        let res = one_run(vehicles, daemons, seconds);
        eprintln!(
            "  published {} received {} p99 {:.2} ms daemons {:.1} % (busiest {:.1} %) router {:.1} %",
            res.published,
            res.received,
            res.p99_ms,
            res.daemon_cpu_pct,
            res.busiest_daemon_cpu_pct,
            res.router_cpu_pct
        );
        results.push(res);
    }
    let m = |f: fn(&RunResult) -> f64| median(results.iter().map(f).collect());
    let expected = vehicles as f64 * 60.0;
    println!(
        "\n## Zenoh fleet: {vehicles} vehicles × (50 Hz ATTITUDE + 10 Hz SERVO_OUTPUT_RAW) \
         over {daemons} ground daemon(s), {seconds} s measured, {runs} run(s), medians\n"
    );
    println!("| figure | value | target |");
    println!("|---|---|---|");
    println!(
        "| delivered rate | {:.0} frames/s (of {expected:.0} published) | {expected:.0} |",
        m(|r| r.received as f64 / r.window_s)
    );
    println!(
        "| loss | {:.3} % | 0 % |",
        m(|r| 100.0 * (1.0 - r.received as f64 / r.published.max(1) as f64))
    );
    println!("| latency p50 | {:.2} ms | |", m(|r| r.p50_ms));
    println!("| latency p99 | {:.2} ms | < 10 ms |", m(|r| r.p99_ms));
    println!("| latency max | {:.2} ms | |", m(|r| r.max_ms));
    println!(
        "| ground daemon CPU | {:.1} % of a core in all, {:.0} ns/frame | |",
        m(|r| r.daemon_cpu_pct),
        m(|r| r.daemon_ns_per_frame)
    );
    println!(
        "| busiest ground daemon | {:.1} % of a core | < 50 % |",
        m(|r| r.busiest_daemon_cpu_pct)
    );
    println!(
        "| Zenoh router CPU | {:.1} % of a core | |",
        m(|r| r.router_cpu_pct)
    );
    let last = results.last().expect("a run");
    println!(
        "| ground daemons' resident memory, window start → end (last run) | {:.1} → {:.1} MB | flat |",
        last.rss_mb.0, last.rss_mb.1
    );
    println!(
        "| ground daemons' open descriptors, window start → end (last run) | {} → {} | flat |",
        last.fds.0, last.fds.1
    );
    // Smoke check: the fleet's telemetry arrives.
    for r in &results {
        assert!(
            r.received * 2 >= r.published && r.published > 0,
            "received {} of {} published frames",
            r.received,
            r.published
        );
    }
}
