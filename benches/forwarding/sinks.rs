//! The sinks: one thread and socket per client, counting the current phase's frames and their
//! latency.

use std::net::{SocketAddr, UdpSocket};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use super::*;

#[derive(Default)]
pub(crate) struct Acc {
    pub(crate) phase: u32,
    pub(crate) count: u64,
    pub(crate) first_ns: u64,
    pub(crate) last_ns: u64,
    pub(crate) lat_ns: Vec<u32>,
    /// Receive times, kept only for `FORWARDING_LATENCY_DUMP`.
    pub(crate) rx_ns: Vec<u64>,
}

/// `FORWARDING_LATENCY_DUMP=DIR` (diagnostic): each paced phase's frames as `receive_ns
/// latency_ns` lines in `DIR/phase<N>-<rate>.txt`, to see when the slow ones come.
pub(crate) fn latency_dump() -> Option<&'static std::path::Path> {
    static DIR: std::sync::OnceLock<Option<std::path::PathBuf>> = std::sync::OnceLock::new();
    DIR.get_or_init(|| std::env::var_os("FORWARDING_LATENCY_DUMP").map(Into::into))
        .as_deref()
}

pub(crate) struct Sink {
    pub(crate) addr: SocketAddr,
    pub(crate) acc: Arc<Mutex<Acc>>,
    pub(crate) thread: Option<std::thread::JoinHandle<()>>,
}

pub(crate) struct Sinks {
    pub(crate) sinks: Vec<Sink>,
    pub(crate) stop: Arc<AtomicBool>,
}

impl Sinks {
    pub(crate) fn start(n: usize) -> Sinks {
        let stop = Arc::new(AtomicBool::new(false));
        let sinks = (0..n)
            .map(|i| {
                let sock = socket2::Socket::new(socket2::Domain::IPV4, socket2::Type::DGRAM, None)
                    .unwrap();
                sock.set_recv_buffer_size(SINK_RCVBUF).unwrap();
                sock.bind(&SocketAddr::from(([127, 0, 0, 1], 0)).into())
                    .unwrap();
                let sock: UdpSocket = sock.into();
                sock.set_read_timeout(Some(Duration::from_millis(20)))
                    .unwrap();
                let addr = sock.local_addr().unwrap();
                let acc = Arc::new(Mutex::new(Acc::default()));
                let (acc2, stop2) = (Arc::clone(&acc), Arc::clone(&stop));
                let thread = std::thread::Builder::new()
                    .name(format!("sink{i}"))
                    .spawn(move || sink_loop(&sock, &acc2, &stop2))
                    .unwrap();
                Sink {
                    addr,
                    acc,
                    thread: Some(thread),
                }
            })
            .collect();
        Sinks { sinks, stop }
    }

    pub(crate) fn begin(&self, phase: u32) {
        for s in &self.sinks {
            *s.acc.lock().unwrap() = Acc {
                phase,
                ..Acc::default()
            };
        }
    }

    pub(crate) fn total(&self) -> u64 {
        self.sinks.iter().map(|s| s.acc.lock().unwrap().count).sum()
    }

    /// Waits until `expected` frames arrived or nothing arrived for `quiet`, then takes the
    /// results.
    pub(crate) fn settle(&self, expected: u64, quiet: Duration) -> Vec<Acc> {
        let mut last = self.total();
        let mut last_change = Instant::now();
        while last < expected && last_change.elapsed() < quiet {
            std::thread::sleep(Duration::from_millis(5));
            let t = self.total();
            if t != last {
                last = t;
                last_change = Instant::now();
            }
        }
        self.sinks
            .iter()
            .map(|s| {
                std::mem::replace(
                    &mut *s.acc.lock().unwrap(),
                    Acc {
                        phase: u32::MAX,
                        ..Acc::default()
                    },
                )
            })
            .collect()
    }
}

impl Drop for Sinks {
    fn drop(&mut self) {
        self.stop.store(true, Ordering::Relaxed);
        for s in &mut self.sinks {
            if let Some(t) = s.thread.take() {
                let _ = t.join();
            }
        }
    }
}

pub(crate) fn sink_loop(sock: &UdpSocket, acc: &Mutex<Acc>, stop: &AtomicBool) {
    let mut buf = [0u8; 2048];
    while !stop.load(Ordering::Relaxed) {
        let Ok(n) = sock.recv(&mut buf) else { continue };
        let t = now_ns();
        let Some((phase, sent)) = parse_frame(&buf[..n]) else {
            continue;
        };
        let mut a = acc.lock().unwrap();
        if a.phase != phase {
            continue;
        }
        if a.count == 0 {
            a.first_ns = t;
        }
        a.count += 1;
        a.last_ns = t;
        a.lat_ns
            .push(u32::try_from(t.saturating_sub(sent)).unwrap_or(u32::MAX));
        if latency_dump().is_some() {
            a.rx_ns.push(t);
        }
    }
}
