//! One measured run: the router, the ground daemons and their clients, the vehicles' schedule
//! with vehicles leaving and joining, and the figures read at the window's start and end.

use std::net::{SocketAddr, UdpSocket};
use std::process::Command;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use rand::{Rng, SeedableRng};
use vtol_link::Frame;
use vtol_link::transport::zenoh as vz;
use zenoh::liveliness::LivelinessToken;
use zenoh::pubsub::Publisher;

use crate::measure::{self, Part, Received, Sent, now_ns};
use crate::procs::{self, Proc};

/// What a run is.
#[derive(Clone, Copy)]
pub struct Setup {
    pub vehicles: usize,
    pub daemons: usize,
    pub seconds: f64,
    /// The chance that a flying vehicle leaves in a given second of the window; it comes back
    /// 1 to 5 s later. 0: nobody leaves.
    pub churn: f64,
    pub seed: u64,
    /// The vehicles send over UDP to `udpin` endpoints instead of over Zenoh (the side-by-side
    /// baseline; nobody leaves).
    pub udp: bool,
    /// Footprint samples this often during the window (the soak's), seconds.
    pub sample_every: f64,
    /// Seconds of traffic between the warm-up and the window: the soak's, long enough for the
    /// daemons' chart history (120 s, bounded) to fill, so that their memory is at its level.
    pub fill: f64,
    /// Every vehicle sends its 10 Hz and 1 Hz frames in the same 20 ms tick (the worst case)
    /// instead of at a phase of its own, as vehicles started at different times do.
    pub aligned: bool,
}

/// One ground daemon's figures over the window.
pub struct DaemonResult {
    pub served: usize,
    pub published: u64,
    pub received: u64,
    /// Datagrams the kernel dropped at its client's socket (the client did not keep up).
    pub client_drops: u64,
    pub p50_ms: f64,
    pub p99_ms: f64,
    pub max_ms: f64,
    pub cpu_ns: u64,
    pub rss_kb: (u64, u64),
    pub fds: (u64, u64),
}

/// A footprint sample: seconds into the window, each daemon's RSS (kB) and descriptors, and
/// the router's Zenoh sessions.
pub struct Sample {
    pub t_s: f64,
    pub rss_kb: Vec<u64>,
    pub fds: Vec<u64>,
    pub sessions: u64,
}

pub struct RunResult {
    pub window_s: f64,
    pub daemons: Vec<DaemonResult>,
    pub router_cpu_ns: u64,
    pub samples: Vec<Sample>,
    pub left: u64,
    pub joined: u64,
}

enum Out {
    Zenoh(Publisher<'static>),
    Udp(UdpSocket, SocketAddr),
}

#[derive(Clone, Copy, PartialEq)]
enum Next {
    /// Then back after this many ticks.
    DropToken(u64),
    Rejoin,
    Publish,
}

struct Vehicle {
    part: usize,
    sys: u8,
    out: Out,
    token: Option<LivelinessToken>,
    active: bool,
    next: Option<(u64, Next)>,
    seq: u8,
}

struct Ground {
    procs: Vec<Proc>,
    sinks: Vec<(u16, Arc<Mutex<Received>>, std::thread::JoinHandle<()>)>,
    /// Each daemon's `udpin` address (UDP runs).
    udp_in: Vec<SocketAddr>,
}

fn start_ground(
    setup: &Setup,
    endpoint: &str,
    log_dir: &std::path::Path,
    sent: &Arc<Sent>,
    stop: &Arc<AtomicBool>,
) -> Ground {
    let per = setup.vehicles.div_ceil(setup.daemons);
    let mut g = Ground {
        procs: Vec::new(),
        sinks: Vec::new(),
        udp_in: Vec::new(),
    };
    for d in 0..setup.daemons {
        let sink_sock = measure::client_socket();
        let sink_addr = sink_sock.local_addr().unwrap();
        let vehicle = if setup.udp {
            let port = UdpSocket::bind("127.0.0.1:0")
                .unwrap()
                .local_addr()
                .unwrap();
            g.udp_in.push(port);
            format!("udpin:{port}")
        } else {
            format!("zenoh:bench-d{d}/*")
        };
        // A command the daemons run under (a heap profiler's environment, for finding where
        // memory goes); one that execs the daemon (`env`) keeps its footprint the daemon's.
        let wrap = std::env::var("ZENOH_FLEET_DAEMON_WRAP").unwrap_or_default();
        let mut wrap = wrap.split_whitespace();
        let mut dcmd = match wrap.next() {
            Some(w) => {
                let mut c = Command::new(w);
                c.args(wrap).arg(env!("CARGO_BIN_EXE_vtol-gcs"));
                c
            }
            None => Command::new(env!("CARGO_BIN_EXE_vtol-gcs")),
        };
        dcmd.args(["run", "--vehicle", &vehicle]);
        if !setup.udp {
            dcmd.args(["--zenoh-mode", "client", "--zenoh-connect", endpoint]);
        }
        // Zenoh's runtime (its threads) in the daemons alone, for comparisons.
        if let Ok(r) = std::env::var("ZENOH_FLEET_DAEMON_RUNTIME") {
            dcmd.env("ZENOH_RUNTIME", r);
        }
        dcmd.args([
            "--serve",
            &format!("udpout:{sink_addr}"),
            "--headless",
            "--log-dir",
        ])
        .arg(log_dir.join(format!("d{d}")));
        g.procs.push(procs::spawn_ready(dcmd, "logging "));
        let part = Part {
            first: d * per,
            per,
            vehicles: setup.vehicles,
        };
        let acc = Arc::new(Mutex::new(Received::default()));
        let (sent, a, stop) = (Arc::clone(sent), Arc::clone(&acc), Arc::clone(stop));
        let t = std::thread::spawn(move || measure::sink(&sink_sock, part, &sent, &a, &stop));
        g.sinks.push((sink_addr.port(), acc, t));
    }
    g
}

async fn open_vehicles(
    setup: &Setup,
    endpoint: &str,
    ground: &Ground,
) -> (Vec<zenoh::Session>, Vec<Vehicle>) {
    let per = setup.vehicles.div_ceil(setup.daemons);
    let mut sessions = Vec::new();
    if !setup.udp {
        // One session per daemon's part: the vehicles of a part share one connection.
        for _ in 0..setup.daemons {
            let opts = vtol_link::ZenohOptions {
                mode: vtol_link::ZenohMode::Client,
                connect: vec![endpoint.to_string()],
                ..Default::default()
            };
            let c = vz::zenoh_config(&opts).unwrap();
            sessions.push(zenoh::open(c).await.expect("vehicles' session"));
        }
    }
    let mut out = Vec::new();
    for v in 0..setup.vehicles {
        let (part, sys) = (v / per, u8::try_from(v % per + 1).unwrap());
        let (fleet, name) = (format!("bench-d{part}"), format!("v{sys}"));
        let (o, token) = if setup.udp {
            let s = UdpSocket::bind("127.0.0.1:0").unwrap();
            (Out::Udp(s, ground.udp_in[part]), None)
        } else {
            let s = &sessions[part];
            let t = s
                .liveliness()
                .declare_token(vz::liveliness_key(&fleet, &name))
                .await
                .unwrap();
            let p = s
                .declare_publisher(vz::from_vehicle_key(&fleet, &name))
                .congestion_control(zenoh::qos::CongestionControl::Block)
                .await
                .unwrap();
            (Out::Zenoh(p), Some(t))
        };
        out.push(Vehicle {
            part,
            sys,
            out: o,
            token,
            active: true,
            next: None,
            seq: 0,
        });
    }
    (sessions, out)
}

/// Who leaves this second, and what each pending leave or return does at this tick. Leaving:
/// the last publication, its liveliness token dropped one tick (20 ms) later; back 1 to 5 s
/// later: a new token, then publications from the next tick.
async fn churn(
    vs: &mut [Vehicle],
    sessions: &[zenoh::Session],
    ticks: u64,
    leave: Option<(f64, &mut rand_chacha::ChaCha8Rng)>,
    counts: &mut (u64, u64),
) {
    let (p_leave, mut rng) = match leave {
        Some((p, rng)) => (p, Some(rng)),
        None => (0.0, None),
    };
    for v in vs.iter_mut() {
        if let Some(rng) = rng.as_deref_mut()
            && v.active
            && v.next.is_none()
            && rng.random_bool(p_leave)
        {
            v.active = false;
            v.next = Some((ticks + 1, Next::DropToken(rng.random_range(50..=250))));
            counts.0 += 1;
            continue;
        }
        let Some((at, what)) = v.next else { continue };
        if at > ticks {
            continue;
        }
        match what {
            Next::DropToken(away) => {
                if let Some(t) = v.token.take() {
                    t.undeclare().await.unwrap();
                }
                v.next = Some((ticks + away, Next::Rejoin));
            }
            Next::Rejoin => {
                if let Some(s) = sessions.get(v.part) {
                    let key =
                        vz::liveliness_key(&format!("bench-d{}", v.part), &format!("v{}", v.sys));
                    v.token = Some(s.liveliness().declare_token(key).await.unwrap());
                }
                v.next = Some((ticks + 1, Next::Publish));
            }
            Next::Publish => {
                v.active = true;
                v.next = None;
                counts.1 += 1;
            }
        }
    }
}

/// Publishes one tick's frames of a vehicle; counts those published in the window.
async fn publish(
    v: &mut Vehicle,
    index: usize,
    ticks: u64,
    sent: &Sent,
    window: Option<(u64, u64)>,
    published: &mut [u64],
    aligned: bool,
) {
    let t_ms = u32::try_from(ticks * 20).unwrap_or(u32::MAX);
    let mut frames = vec![(true, measure::attitude(t_ms))];
    // A vehicle's own phase in the second: its 10 Hz and 1 Hz frames fall in tick `phase`
    // of every 5 and every 50 (all in tick 0 when aligned).
    let phase = if aligned { 0 } else { index as u64 % 50 };
    if (ticks + phase).is_multiple_of(5) {
        frames.push((true, measure::servo(t_ms)));
    }
    if (ticks + phase).is_multiple_of(50) {
        frames.push((false, measure::heartbeat()));
    }
    for (telemetry, msg) in frames {
        let s = v.seq;
        v.seq = s.wrapping_add(1);
        let f = Frame::encode_v2(
            vtol_link::SystemId(v.sys),
            vtol_link::ComponentId(1),
            s,
            &msg,
        );
        let t_send = now_ns();
        sent.slot(index, s).store(t_send, Ordering::Release);
        if telemetry && window.is_some_and(|(a, b)| t_send >= a && t_send < b) {
            published[v.part] += 1;
        }
        match &v.out {
            Out::Zenoh(p) => p.put(f.as_bytes().to_vec()).await.unwrap(),
            Out::Udp(s, to) => {
                s.send_to(f.as_bytes(), to).unwrap();
            }
        }
    }
}

fn footprints(ground: &Ground) -> Vec<(u64, u64)> {
    ground
        .procs
        .iter()
        .map(|p| procs::footprint(p.pid()))
        .collect()
}

fn sample(ground: &Ground, router_port: u16, t_s: f64) -> Sample {
    let f = footprints(ground);
    Sample {
        t_s,
        rss_kb: f.iter().map(|x| x.0).collect(),
        fds: f.iter().map(|x| x.1).collect(),
        sessions: procs::router_sessions(router_port),
    }
}

/// What the schedule hands back: published per part, the window, CPU at its start and end,
/// footprint samples, the leave and join counts.
struct Schedule {
    published: Vec<u64>,
    window: (u64, u64),
    cpu0: (Vec<u64>, u64),
    cpu1: (Vec<u64>, u64),
    foot0: Vec<(u64, u64)>,
    foot1: Vec<(u64, u64)>,
    samples: Vec<Sample>,
    counts: (u64, u64),
    /// Each client's socket's kernel drops after the stragglers.
    drops: Vec<u64>,
}

// Over 80 lines: one loop of phase control (warm-up, window, samples, churn) and the tick's
// publications; split, its parts would pass a dozen counters between them.
async fn schedule(
    setup: &Setup,
    endpoint: &str,
    router: &Proc,
    router_port: u16,
    ground: &Ground,
    sent: &Sent,
) -> Schedule {
    let (sessions, mut vs) = open_vehicles(setup, endpoint, ground).await;
    let cpu = |ground: &Ground| -> (Vec<u64>, u64) {
        (
            ground
                .procs
                .iter()
                .map(|p| procs::cpu_ns(p.pid()))
                .collect(),
            procs::cpu_ns(router.pid()),
        )
    };
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(setup.seed);
    let tick = Duration::from_millis(20);
    let slots = setup.vehicles.min(10);
    let start = tokio::time::Instant::now();
    let warm_deadline = Instant::now() + Duration::from_secs(120);
    let mut published = vec![0u64; setup.daemons];
    let (mut ticks, mut warm_until, mut window) = (0u64, None::<u64>, None::<(u64, u64)>);
    let (mut cpu0, mut foot0, mut samples, mut next_sample) =
        ((Vec::new(), 0), Vec::new(), Vec::new(), 0u64);
    let mut counts = (0u64, 0u64);
    loop {
        let t = now_ns();
        if warm_until.is_none() {
            let heard: usize = ground
                .sinks
                .iter()
                .map(|s| s.1.lock().unwrap().vehicles_heard.len())
                .sum();
            if heard == setup.vehicles {
                warm_until = Some(t + ((1.0 + setup.fill) * 1e9) as u64);
            } else if Instant::now() > warm_deadline {
                panic!(
                    "warm-up: the clients heard {heard} of {} vehicles in 120 s",
                    setup.vehicles
                );
            }
        }
        if let Some(w) = warm_until
            && window.is_none()
            && t >= w
        {
            let w = (t, t + (setup.seconds * 1e9) as u64);
            window = Some(w);
            for s in &ground.sinks {
                s.1.lock().unwrap().window = Some(w);
            }
            cpu0 = cpu(ground);
            foot0 = footprints(ground);
            next_sample = t;
        }
        if let Some((w0, end)) = window {
            if t >= next_sample {
                samples.push(sample(ground, router_port, (t - w0) as f64 / 1e9));
                next_sample += (setup.sample_every * 1e9) as u64;
            }
            if t >= end {
                break;
            }
        }
        let leave = (warm_until.is_some() && setup.churn > 0.0 && ticks.is_multiple_of(50))
            .then_some((setup.churn, &mut rng));
        churn(&mut vs, &sessions, ticks, leave, &mut counts).await;
        for slot in 0..slots {
            tokio::time::sleep_until(
                start + tick * ticks as u32 + tick * slot as u32 / slots as u32,
            )
            .await;
            let (a, b) = (slot * vs.len() / slots, (slot + 1) * vs.len() / slots);
            for (i, v) in vs.iter_mut().enumerate().take(b).skip(a) {
                if v.active {
                    publish(v, i, ticks, sent, window, &mut published, setup.aligned).await;
                }
            }
        }
        ticks += 1;
    }
    let window = window.unwrap();
    let (cpu1, foot1) = (cpu(ground), footprints(ground));
    // Stragglers: up to 2 s for the window's last frames to arrive (or be dropped at a client).
    let deadline = Instant::now() + Duration::from_secs(2);
    while Instant::now() < deadline
        && ground
            .sinks
            .iter()
            .zip(&published)
            .any(|(s, &p)| s.1.lock().unwrap().frames + procs::udp_drops(s.0) < p)
    {
        tokio::time::sleep(Duration::from_millis(10)).await;
    }
    let drops = ground.sinks.iter().map(|s| procs::udp_drops(s.0)).collect();
    drop(vs);
    drop(sessions);
    Schedule {
        published,
        window,
        cpu0,
        cpu1,
        foot0,
        foot1,
        samples,
        counts,
        drops,
    }
}

/// One measured run.
pub fn one_run(setup: &Setup) -> RunResult {
    let port = procs::free_tcp_port();
    let endpoint = format!("tcp/127.0.0.1:{port}");
    let mut rcmd = Command::new(std::env::current_exe().unwrap());
    rcmd.args(["--router", &endpoint]);
    let router = procs::spawn_ready(rcmd, "ready");
    let log_dir = tempfile::tempdir().unwrap();
    let sent = Arc::new(Sent::new(setup.vehicles));
    let stop = Arc::new(AtomicBool::new(false));
    let mut ground = start_ground(setup, &endpoint, log_dir.path(), &sent, &stop);
    let rt = tokio::runtime::Runtime::new().unwrap();
    let s = rt.block_on(schedule(setup, &endpoint, &router, port, &ground, &sent));
    stop.store(true, Ordering::Relaxed);
    let mut daemons = Vec::new();
    for (d, (_, acc, t)) in ground.sinks.drain(..).enumerate() {
        t.join().unwrap();
        let mut a = acc.lock().unwrap();
        a.latencies_ns.sort_unstable();
        daemons.push(DaemonResult {
            served: a.vehicles_heard.len(),
            published: s.published[d],
            received: a.frames,
            client_drops: s.drops[d],
            p50_ms: measure::percentile(&a.latencies_ns, 0.5),
            p99_ms: measure::percentile(&a.latencies_ns, 0.99),
            max_ms: measure::percentile(&a.latencies_ns, 1.0),
            cpu_ns: s.cpu1.0[d] - s.cpu0.0[d],
            rss_kb: (s.foot0[d].0, s.foot1[d].0),
            fds: (s.foot0[d].1, s.foot1[d].1),
        });
    }
    drop(ground);
    drop(router);
    RunResult {
        window_s: (s.window.1 - s.window.0) as f64 / 1e9,
        daemons,
        router_cpu_ns: s.cpu1.1 - s.cpu0.1,
        samples: s.samples,
        left: s.counts.0,
        joined: s.counts.1,
    }
}
