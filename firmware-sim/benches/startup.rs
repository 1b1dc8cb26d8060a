//! The twin as a test fixture, measured from outside as a test harness sees it: the real
//! `firmware-sim` binary (built with the bench profile), real TCP sockets, the harness channel.
//!
//! - process start → first HEARTBEAT on its MAVLink port (target < 10 ms);
//! - process start → armed in QHOVER: DO_SET_MODE and ARM acknowledged, and a HEARTBEAT asked
//!   for with REQUEST_MESSAGE showing both (target < 100 ms);
//! - 64 twins started at once, each answering with its first HEARTBEAT (target < 1 s);
//! - a 60 s lockstep flight (QHOVER take-off, 60 × `advance 1`), its telemetry read and decoded
//!   by the client as it comes (target < 0.5 s of wall time);
//! - `--fast` as a user runs it: the sim's speed, ATTITUDE per wall second, and a whole
//!   parameter list fetched while it runs.
//!
//! CPU is read from `/proc` (the twins' user + system time), so each figure has its cost next
//! to it. Run: `cargo bench -p firmware-sim --bench startup` (Linux).

use std::io::{BufRead, BufReader, Read, Write};
use std::net::TcpStream;
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

use mavlink::dialects::ardupilotmega as apm;
use vtol_link::{Frame, FrameDecoder, FrameSource};

const BIN: &str = env!("CARGO_BIN_EXE_firmware-sim");
const BOUND: Duration = Duration::from_secs(20);
const RUNS: usize = 40;

/// One twin process and its two ports.
struct Proc {
    child: Child,
    mavlink_port: u16,
    control_port: Option<u16>,
}

impl Drop for Proc {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

fn spawn(args: &[&str]) -> Child {
    Command::new(BIN)
        .arg("serve")
        .args(["--listen", "tcpin:127.0.0.1:0"])
        .args(args)
        .stdin(Stdio::null())
        .stdout(Stdio::piped())
        .stderr(Stdio::null())
        .spawn()
        .expect("firmware-sim starts")
}

/// Reads the start lines (`listening …`, and `control …` when asked).
fn started(mut child: Child, control: bool) -> Proc {
    let mut out = BufReader::new(child.stdout.take().expect("stdout"));
    let port = |line: &str| -> u16 { line.trim().rsplit(':').next().unwrap().parse().unwrap() };
    let mut line = String::new();
    out.read_line(&mut line).expect("listening line");
    let mavlink_port = port(&line);
    let control_port = control.then(|| {
        line.clear();
        out.read_line(&mut line).expect("control line");
        port(&line)
    });
    Proc {
        child,
        mavlink_port,
        control_port,
    }
}

/// A blocking MAVLink client.
struct Client {
    s: TcpStream,
    dec: FrameDecoder,
    out: FrameSource,
}

impl Client {
    fn connect(port: u16) -> Self {
        let s = TcpStream::connect(("127.0.0.1", port)).expect("connect");
        s.set_read_timeout(Some(BOUND)).unwrap();
        s.set_nodelay(true).unwrap();
        Self {
            s,
            dec: FrameDecoder::new(),
            out: FrameSource::new(vtol_link::SystemId(255), vtol_link::ComponentId(190)),
        }
    }

    fn next(&mut self) -> Frame {
        loop {
            if let Some(f) = self.dec.frames().next() {
                return f;
            }
            let mut buf = [0u8; 16 * 1024];
            let n = self.s.read(&mut buf).expect("read within the bound");
            assert!(n > 0, "twin closed the link");
            self.dec.push(&buf[..n]);
        }
    }

    fn wait<T>(&mut self, mut pred: impl FnMut(&apm::MavMessage) -> Option<T>) -> T {
        loop {
            if let Ok(m) = self.next().decode()
                && let Some(t) = pred(&m)
            {
                return t;
            }
        }
    }

    fn send(&mut self, msg: &apm::MavMessage) {
        let f = self.out.encode_v2(msg);
        self.s.write_all(f.as_bytes()).unwrap();
    }

    fn command(&mut self, command: apm::MavCmd, p1: f32, p2: f32) -> apm::MavResult {
        self.send(&apm::MavMessage::COMMAND_LONG(apm::COMMAND_LONG_DATA {
            param1: p1,
            param2: p2,
            command,
            target_system: 1,
            target_component: 1,
            ..Default::default()
        }));
        self.wait(|m| match m {
            apm::MavMessage::COMMAND_ACK(a) if a.command == command => Some(a.result),
            _ => None,
        })
    }
}

/// A line client of the harness channel.
struct Control {
    w: TcpStream,
    r: BufReader<TcpStream>,
}

impl Control {
    fn connect(port: u16) -> Self {
        let w = TcpStream::connect(("127.0.0.1", port)).expect("control");
        w.set_read_timeout(Some(BOUND)).unwrap();
        w.set_nodelay(true).unwrap();
        let r = BufReader::new(w.try_clone().unwrap());
        Self { w, r }
    }

    fn call(&mut self, line: &str) -> String {
        self.w.write_all(format!("{line}\n").as_bytes()).unwrap();
        let mut reply = String::new();
        self.r.read_line(&mut reply).unwrap();
        assert!(!reply.contains("error"), "{line}: {reply}");
        reply
    }
}

fn is_heartbeat(m: &apm::MavMessage) -> Option<apm::HEARTBEAT_DATA> {
    match m {
        apm::MavMessage::HEARTBEAT(h) => Some(h.clone()),
        _ => None,
    }
}

/// CPU time of a running process, s: the sum over its threads of the scheduler's own count
/// (`/proc/PID/task/*/schedstat`, in ns; threads that already ended are not counted).
fn cpu_s(pid: u32) -> f64 {
    let Ok(tasks) = std::fs::read_dir(format!("/proc/{pid}/task")) else {
        return 0.0;
    };
    tasks
        .filter_map(Result::ok)
        .filter_map(|t| std::fs::read_to_string(t.path().join("schedstat")).ok())
        .filter_map(|s| s.split_whitespace().next()?.parse::<u64>().ok())
        .sum::<u64>() as f64
        * 1e-9
}

fn percentile(xs: &mut [f64], p: f64) -> f64 {
    xs.sort_by(f64::total_cmp);
    xs[((xs.len() - 1) as f64 * p).round() as usize]
}

fn ms(d: Duration) -> f64 {
    d.as_secs_f64() * 1e3
}

fn startup_figures() {
    let mut cpu = 0.0;
    let mut first_hb = Vec::new();
    let mut armed = Vec::new();
    let mut listening = Vec::new();
    for _ in 0..RUNS {
        let t0 = Instant::now();
        let child = spawn(&["--control", "tcpin:127.0.0.1:0", "--lockstep"]);
        let p = started(child, true);
        listening.push(ms(t0.elapsed()));
        let mut c = Client::connect(p.mavlink_port);
        c.wait(is_heartbeat);
        first_hb.push(ms(t0.elapsed()));
        assert_eq!(
            c.command(apm::MavCmd::MAV_CMD_DO_SET_MODE, 1.0, 18.0),
            apm::MavResult::MAV_RESULT_ACCEPTED
        );
        assert_eq!(
            c.command(apm::MavCmd::MAV_CMD_COMPONENT_ARM_DISARM, 1.0, 0.0),
            apm::MavResult::MAV_RESULT_ACCEPTED
        );
        assert_eq!(
            c.command(apm::MavCmd::MAV_CMD_REQUEST_MESSAGE, 0.0, 0.0),
            apm::MavResult::MAV_RESULT_ACCEPTED
        );
        c.wait(|m| {
            is_heartbeat(m).filter(|h| h.custom_mode == 18 && h.base_mode.bits() & 128 != 0)
        });
        armed.push(ms(t0.elapsed()));
        cpu += cpu_s(p.child.id());
    }
    println!(
        "start-up of `firmware-sim serve --lockstep` ({RUNS} runs; median / p90 / max, ms); \
         the twin's CPU per run, start to armed: {:.2} ms",
        cpu * 1e3 / RUNS as f64
    );
    for (what, xs) in [
        ("process start -> `listening` printed", &mut listening),
        ("process start -> first HEARTBEAT", &mut first_hb),
        ("process start -> armed in QHOVER (HEARTBEAT)", &mut armed),
    ] {
        println!(
            "  {what:<46} {:7.2} {:7.2} {:7.2}",
            percentile(xs, 0.5),
            percentile(xs, 0.9),
            percentile(xs, 1.0)
        );
    }
}

fn fleet_figures(n: usize) {
    let t0 = Instant::now();
    let children: Vec<Child> = (0..n).map(|_| spawn(&[])).collect();
    let procs: Vec<Proc> = children.into_iter().map(|c| started(c, false)).collect();
    let mut clients: Vec<Client> = procs
        .iter()
        .map(|p| Client::connect(p.mavlink_port))
        .collect();
    for c in &mut clients {
        c.wait(is_heartbeat);
    }
    let all = t0.elapsed();
    let cpu: f64 = procs.iter().map(|p| cpu_s(p.child.id())).sum();
    println!(
        "{n} twins started at once, each answering: {:.0} ms of wall time; the twins' CPU {:.0} ms \
         ({:.1} ms per twin)",
        ms(all),
        cpu * 1e3,
        cpu * 1e3 / n as f64
    );
}

/// One 60 s lockstep flight: (wall time, wall time to the last reply, frames decoded, the
/// twin's CPU during the flight in s).
fn lockstep_flight() -> (Duration, Duration, u64, f64) {
    let p = started(
        spawn(&["--control", "tcpin:127.0.0.1:0", "--lockstep"]),
        true,
    );
    let mut c = Client::connect(p.mavlink_port);
    let mut ctl = Control::connect(p.control_port.unwrap());
    c.wait(is_heartbeat);
    let cpu0 = cpu_s(p.child.id());
    let t0 = Instant::now();
    c.command(apm::MavCmd::MAV_CMD_DO_SET_MODE, 1.0, 18.0);
    c.command(apm::MavCmd::MAV_CMD_COMPONENT_ARM_DISARM, 1.0, 0.0);
    // The reader decodes every frame as it arrives, as a script's connection would.
    let reader = std::thread::spawn(move || {
        let mut frames = 0u64;
        loop {
            let f = c.next();
            frames += 1;
            if let Ok(apm::MavMessage::ATTITUDE(a)) = f.decode()
                && a.time_boot_ms >= 60_000
            {
                return frames;
            }
        }
    });
    for _ in 0..60 {
        ctl.call("advance 1");
    }
    let advanced = t0.elapsed();
    let frames = reader.join().unwrap();
    let wall = t0.elapsed();
    let state = ctl.call("state");
    assert!(state.contains("\"armed\":true"), "{state}");
    (wall, advanced, frames, cpu_s(p.child.id()) - cpu0)
}

fn lockstep_scenario() {
    const FLIGHTS: usize = 10;
    let mut cpu = 0.0;
    let mut walls = Vec::new();
    let mut replies = Vec::new();
    let mut frames = 0;
    for _ in 0..FLIGHTS {
        let (wall, advanced, n, c) = lockstep_flight();
        cpu += c;
        walls.push(ms(wall));
        replies.push(ms(advanced));
        frames = n;
    }
    let cpu = cpu / FLIGHTS as f64;
    println!(
        "60 s lockstep flight (QHOVER, 60 x `advance 1`; {FLIGHTS} flights, median / max): {:.1} / {:.1} ms \
         of wall time ({:.1} ms to the last reply), {frames} frames decoded by the client; the twin's \
         CPU per flight: {:.1} ms ({:.0}x real time per CPU second)",
        percentile(&mut walls, 0.5),
        percentile(&mut walls, 1.0),
        percentile(&mut replies, 0.5),
        cpu * 1e3,
        60.0 / cpu
    );
}

fn fast_flood() {
    let p = started(spawn(&["--fast"]), false);
    let mut c = Client::connect(p.mavlink_port);
    c.wait(is_heartbeat);
    let count_for = |c: &mut Client, d: Duration| {
        let t0 = Instant::now();
        let (mut attitude, mut first_ms, mut last_ms) = (0u64, None, 0u32);
        while t0.elapsed() < d {
            if let Ok(apm::MavMessage::ATTITUDE(a)) = c.next().decode() {
                attitude += 1;
                first_ms.get_or_insert(a.time_boot_ms);
                last_ms = a.time_boot_ms;
            }
        }
        let wall = t0.elapsed().as_secs_f64();
        let sim = f64::from(last_ms - first_ms.unwrap_or(last_ms)) / 1e3;
        (attitude as f64 / wall, sim / wall)
    };
    let (per_s, speed) = count_for(&mut c, Duration::from_secs(2));
    c.send(&apm::MavMessage::PARAM_REQUEST_LIST(
        apm::PARAM_REQUEST_LIST_DATA {
            target_system: 1,
            target_component: 1,
        },
    ));
    let t0 = Instant::now();
    let count = firmware_sim::nav::params::TABLE.len();
    let mut seen = vec![false; count];
    while seen.iter().any(|s| !s) {
        let i = c.wait(|m| match m {
            apm::MavMessage::PARAM_VALUE(v) => Some(usize::from(v.param_index)),
            _ => None,
        });
        seen[i] = true;
    }
    println!(
        "`serve --fast`: {speed:.0}x real time, ATTITUDE {per_s:.1} per wall second; all {count} \
         parameters of a PARAM_REQUEST_LIST in {:.1} ms",
        ms(t0.elapsed())
    );
}

fn main() {
    // `cargo test` runs benches with no arguments only when asked; `cargo bench` passes --bench.
    if !std::env::args().any(|a| a == "--bench") {
        return;
    }
    startup_figures();
    fleet_figures(64);
    lockstep_scenario();
    fast_flood();
}
