//! The forwarders under test (the daemon, the bare loop) as child processes, and their CPU.

use std::io::{BufRead, BufReader, Write as _};
use std::net::{SocketAddr, UdpSocket};
use std::process::{Child, Command, Stdio};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

#[derive(Clone, Copy, PartialEq, Eq)]
pub(crate) enum Kind {
    Bare,
    Daemon,
}

impl Kind {
    pub(crate) fn tag(self) -> &'static str {
        match self {
            Kind::Bare => "bare",
            Kind::Daemon => "daemon",
        }
    }

    pub(crate) fn name(self) -> &'static str {
        match self {
            Kind::Bare => "bare UDP forwarder",
            Kind::Daemon => "vtol-gcs daemon",
        }
    }
}

/// Per-thread counters of a process: run time (ns) and voluntary / non-voluntary context
/// switches, keyed by thread id.
pub(crate) struct CpuSample(Vec<(String, [u64; 3])>);

/// What a process used between two samples.
#[derive(Clone, Copy, Default)]
pub(crate) struct Used {
    pub(crate) cpu_s: f64,
    pub(crate) voluntary: u64,
    pub(crate) involuntary: u64,
}

impl Used {
    pub(crate) fn add(&mut self, other: Used) {
        self.cpu_s += other.cpu_s;
        self.voluntary += other.voluntary;
        self.involuntary += other.involuntary;
    }
}

impl CpuSample {
    /// Use between `before` and `self`; a thread that started since counts from 0 (threads that
    /// ended in between are lost, which only tokio's idle blocking threads do).
    pub(crate) fn since(&self, before: &CpuSample) -> Used {
        let mut sum = [0u64; 3];
        for (tid, now) in &self.0 {
            let then = before
                .0
                .iter()
                .find(|(t, _)| t == tid)
                .map_or([0; 3], |(_, b)| *b);
            for i in 0..3 {
                sum[i] += now[i] - then[i].min(now[i]);
            }
        }
        Used {
            cpu_s: sum[0] as f64 / 1e9,
            voluntary: sum[1],
            involuntary: sum[2],
        }
    }
}

/// A `Key:   value` line of a `/proc/.../status` file.
pub(crate) fn status_field(status: &str, key: &str) -> Option<u64> {
    status
        .lines()
        .find_map(|l| l.strip_prefix(key)?.strip_prefix(':'))
        .and_then(|v| v.split_whitespace().next()?.parse().ok())
}

/// Datagrams the kernel dropped on the UDP socket bound to `port` (receive buffer full), from
/// `/proc/net/udp`.
pub(crate) fn udp_drops(port: u16) -> u64 {
    let want = format!(":{port:04X}");
    std::fs::read_to_string("/proc/net/udp")
        .unwrap_or_default()
        .lines()
        .skip(1)
        .filter_map(|l| {
            let f: Vec<&str> = l.split_whitespace().collect();
            (f.get(1)?.ends_with(&want))
                .then(|| f.get(12)?.parse::<u64>().ok())
                .flatten()
        })
        .sum()
}

pub(crate) struct Forwarder {
    pub(crate) kind: Kind,
    pub(crate) child: Child,
    pub(crate) ingress: SocketAddr,
    pub(crate) last_status: Arc<Mutex<String>>,
    pub(crate) _log_dir: Option<tempfile::TempDir>,
}

pub(crate) fn free_udp_port() -> u16 {
    UdpSocket::bind("127.0.0.1:0")
        .unwrap()
        .local_addr()
        .unwrap()
        .port()
}

impl Forwarder {
    pub(crate) fn start(kind: Kind, sinks: &[SocketAddr]) -> Forwarder {
        let targets: Vec<String> = sinks.iter().map(ToString::to_string).collect();
        let (mut child, ingress, log_dir) = match kind {
            Kind::Bare => {
                let child = Command::new(std::env::current_exe().unwrap())
                    .arg("--bare-forwarder")
                    .arg(targets.join(","))
                    .stdout(Stdio::piped())
                    .stdin(Stdio::piped())
                    .spawn()
                    .expect("re-run self as the bare forwarder");
                (child, None, None)
            }
            Kind::Daemon => {
                let dir = tempfile::tempdir().unwrap();
                let port = free_udp_port();
                // FORWARDING_DAEMON=PATH: diagnostic, another build of the daemon.
                let exe = std::env::var_os("FORWARDING_DAEMON")
                    .unwrap_or_else(|| env!("CARGO_BIN_EXE_vtol-gcs").into());
                let mut cmd = Command::new(exe);
                cmd.args(["run", "--vehicle", &format!("udpin:127.0.0.1:{port}")]);
                for t in &targets {
                    cmd.args(["--serve", &format!("udpout:{t}")]);
                }
                // FORWARDING_NO_TLOG=1: diagnostic only (the published figures have the tlog on).
                if std::env::var_os("FORWARDING_NO_TLOG").is_some() {
                    cmd.arg("--no-log");
                } else {
                    cmd.arg("--log-dir").arg(dir.path());
                }
                cmd.arg("--headless");
                let child = cmd
                    .stdout(Stdio::piped())
                    .stdin(Stdio::null())
                    .spawn()
                    .expect("start vtol-gcs");
                (
                    child,
                    Some(SocketAddr::from(([127, 0, 0, 1], port))),
                    Some(dir),
                )
            }
        };
        // Readiness: the bare forwarder prints its port; the daemon prints `logging <path>`
        // once every endpoint is bound. Later lines (status) are kept for diagnostics.
        let (ready_tx, ready_rx) = std::sync::mpsc::channel();
        let no_log = kind == Kind::Daemon && std::env::var_os("FORWARDING_NO_TLOG").is_some();
        let last_status = Arc::new(Mutex::new(String::new()));
        let status = Arc::clone(&last_status);
        let out = child.stdout.take().unwrap();
        std::thread::spawn(move || {
            for line in BufReader::new(out).lines() {
                let Ok(line) = line else { break };
                if let Some(p) = line.strip_prefix("listening ") {
                    let _ = ready_tx.send(Some(p.parse::<SocketAddr>().unwrap()));
                } else if line.starts_with("logging ") || line.starts_with("serving ") && no_log {
                    let _ = ready_tx.send(None);
                } else {
                    *status.lock().unwrap() = line;
                }
            }
        });
        let got = ready_rx
            .recv_timeout(Duration::from_secs(20))
            .expect("forwarder ready in time");
        let ingress = got.or(ingress).unwrap();
        Forwarder {
            kind,
            child,
            ingress,
            last_status,
            _log_dir: log_dir,
        }
    }

    /// Counters of every thread of the process: run time from
    /// `/proc/<pid>/task/<tid>/schedstat` (ns resolution; utime + stime in /proc/<pid>/stat only
    /// has 10 ms ticks, too coarse for a sub-second saturation phase) and context switches from
    /// `/proc/<pid>/task/<tid>/status` (`/proc/<pid>/status` alone counts the main thread only).
    pub(crate) fn cpu(&self) -> CpuSample {
        let mut per_thread = Vec::new();
        if let Ok(dir) = std::fs::read_dir(format!("/proc/{}/task", self.child.id())) {
            for e in dir.flatten() {
                let tid = e.file_name().to_string_lossy().into_owned();
                let ns = std::fs::read_to_string(e.path().join("schedstat"))
                    .ok()
                    .and_then(|s| {
                        s.split_whitespace()
                            .next()
                            .and_then(|v| v.parse::<u64>().ok())
                    })
                    .unwrap_or(0);
                let status = std::fs::read_to_string(e.path().join("status")).unwrap_or_default();
                let vol = status_field(&status, "voluntary_ctxt_switches").unwrap_or(0);
                let invol = status_field(&status, "nonvoluntary_ctxt_switches").unwrap_or(0);
                per_thread.push((tid, [ns, vol, invol]));
            }
        }
        CpuSample(per_thread)
    }

    /// Peak resident set size of the process (`VmHWM`), bytes.
    pub(crate) fn peak_rss(&self) -> u64 {
        let status = std::fs::read_to_string(format!("/proc/{}/status", self.child.id()))
            .unwrap_or_default();
        status_field(&status, "VmHWM").unwrap_or(0) * 1024
    }

    pub(crate) fn threads(&self) -> usize {
        std::fs::read_dir(format!("/proc/{}/task", self.child.id())).map_or(0, Iterator::count)
    }

    /// Stops the process: SIGTERM for the daemon (so the tlog is flushed and closed), then
    /// SIGKILL if it does not go. Returns the tlog size in bytes.
    pub(crate) fn stop(mut self) -> Option<u64> {
        let pid = self.child.id().to_string();
        let _ = Command::new("kill").args(["-TERM", &pid]).status();
        let deadline = Instant::now() + Duration::from_secs(5);
        while Instant::now() < deadline {
            if let Ok(Some(_)) = self.child.try_wait() {
                break;
            }
            std::thread::sleep(Duration::from_millis(10));
        }
        let _ = self.child.kill();
        let _ = self.child.wait();
        let dir = self._log_dir.as_ref()?;
        let mut bytes = 0;
        for e in std::fs::read_dir(dir.path()).ok()?.flatten() {
            bytes += e.metadata().map_or(0, |m| m.len());
        }
        Some(bytes)
    }
}

impl Drop for Forwarder {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

/// The bare forwarder: `--bare-forwarder HOST:PORT[,HOST:PORT…]`. Runs until killed or until
/// its stdin closes (the bench process died).
pub(crate) fn bare_forwarder(targets: &str) -> ! {
    let clients: Vec<SocketAddr> = targets.split(',').map(|t| t.parse().unwrap()).collect();
    // FORWARDING_BARE_WORK_NS=N: the same loop with N ns of busy work after each datagram's
    // sends, to see what a given CPU cost per frame does to the latency on this machine.
    let work = std::env::var("FORWARDING_BARE_WORK_NS").ok().map(|v| {
        Duration::from_nanos(v.parse().unwrap_or_else(|_| {
            panic!("FORWARDING_BARE_WORK_NS={v:?}: not a whole number of nanoseconds")
        }))
    });
    let sock = UdpSocket::bind("127.0.0.1:0").unwrap();
    println!("listening {}", sock.local_addr().unwrap());
    std::io::stdout().flush().unwrap();
    std::thread::spawn(|| {
        let mut sink = [0u8; 16];
        while std::io::Read::read(&mut std::io::stdin(), &mut sink).is_ok_and(|n| n > 0) {}
        std::process::exit(0);
    });
    // FORWARDING_BARE_TOKIO=1: the same loop on a current-thread tokio runtime (readiness from
    // the reactor, then `recv_from`), to see what the reactor's path costs by itself.
    if std::env::var_os("FORWARDING_BARE_TOKIO").is_some() {
        let rt = tokio::runtime::Builder::new_current_thread()
            .enable_all()
            .build()
            .unwrap();
        rt.block_on(async move {
            sock.set_nonblocking(true).unwrap();
            let sock = tokio::net::UdpSocket::from_std(sock).unwrap();
            let mut buf = [0u8; 65_536];
            loop {
                let Ok((n, _)) = sock.recv_from(&mut buf).await else {
                    continue;
                };
                for c in &clients {
                    let _ = sock.try_send_to(&buf[..n], *c);
                }
            }
        });
    }
    let mut buf = [0u8; 65_536];
    loop {
        let Ok((n, _)) = sock.recv_from(&mut buf) else {
            continue;
        };
        for c in &clients {
            let _ = sock.send_to(&buf[..n], c);
        }
        if let Some(work) = work {
            let t = Instant::now();
            while t.elapsed() < work {
                std::hint::spin_loop();
            }
        }
    }
}
