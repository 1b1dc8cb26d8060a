//! The processes of a run (the router, the ground daemons) and what is read of them in /proc.

use std::io::{BufRead, BufReader};
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

pub fn free_tcp_port() -> u16 {
    std::net::TcpListener::bind("127.0.0.1:0")
        .unwrap()
        .local_addr()
        .unwrap()
        .port()
}

/// CPU time of every thread of a process, ns.
pub fn cpu_ns(pid: u32) -> u64 {
    let Ok(dir) = std::fs::read_dir(format!("/proc/{pid}/task")) else {
        return 0;
    };
    dir.flatten()
        .filter_map(|e| std::fs::read_to_string(e.path().join("schedstat")).ok())
        .filter_map(|s| s.split_whitespace().next()?.parse::<u64>().ok())
        .sum()
}

/// Resident memory (kB) and open descriptors of a process: what a soak watches stay flat.
pub fn footprint(pid: u32) -> (u64, u64) {
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

/// Zenoh sessions at the router: its established TCP connections (one per session on
/// loopback TCP; the router listens on `port`).
pub fn router_sessions(port: u16) -> u64 {
    let Ok(tcp) = std::fs::read_to_string("/proc/net/tcp") else {
        return 0;
    };
    let local = format!(":{port:04X}");
    tcp.lines()
        .skip(1)
        .filter(|l| {
            let f: Vec<&str> = l.split_whitespace().collect();
            f.len() > 3 && f[1].ends_with(&local) && f[3] == "01"
        })
        .count() as u64
}

/// Datagrams the kernel dropped at a UDP socket bound on 127.0.0.1:`port` (its receive buffer
/// full: the client did not read fast enough). The last field of /proc/net/udp.
pub fn udp_drops(port: u16) -> u64 {
    let Ok(udp) = std::fs::read_to_string("/proc/net/udp") else {
        return 0;
    };
    let local = format!("0100007F:{port:04X}");
    udp.lines()
        .skip(1)
        .filter_map(|l| {
            let f: Vec<&str> = l.split_whitespace().collect();
            (f.get(1) == Some(&local.as_str())).then(|| f.last()?.parse::<u64>().ok())?
        })
        .sum()
}

pub struct Proc(pub Child);

impl Proc {
    pub fn pid(&self) -> u32 {
        self.0.id()
    }
}

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
pub fn spawn_ready(mut cmd: Command, ready: &'static str) -> Proc {
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
    rx.recv_timeout(Duration::from_secs(60))
        .unwrap_or_else(|_| panic!("no '{ready}' line in 60 s"));
    Proc(child)
}

/// `--router ENDPOINT`: a Zenoh router until stdin closes.
pub fn router(endpoint: &str) -> ! {
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
