//! How a blocking reader is stopped and woken without a receive timeout.

use std::io::{self};
use std::net::{Ipv4Addr, Ipv6Addr, SocketAddr, UdpSocket};
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::time::Duration;

use super::BLOCKING_TICK;
use tokio_util::sync::CancellationToken;

/// How a blocking reader learns that it is to stop, and is woken when no datagram comes.
///
/// The reader sleeps in its receive with no timeout, as a bare `recvfrom` loop does: a
/// receive timeout arms and cancels a kernel timer on every sleep, about 2 % of a forwarded
/// frame's CPU on this machine (BENCHMARKS.md). Instead a task of the runtime sends it an empty
/// datagram from a socket of its own (the alarm), which the reader knows by its source address
/// and discards: when the reader is to stop (cancelled, or the runtime ends), and after every
/// `idle` period in which the reader did not wake by itself (a udpin reader's peer expiry).
/// Without a loopback to send the alarm on, the reader falls back to a receive timeout.
#[derive(Debug)]
pub(crate) struct Wakeup {
    pub(crate) stopped: AtomicBool,
    /// The reader's wake-ups so far (written by the reader alone).
    pub(crate) count: AtomicU64,
    /// The alarm's address: datagrams from it are wake-ups, not traffic. `None`: the reader
    /// sleeps with a receive timeout instead.
    pub(crate) alarm: Option<SocketAddr>,
}

impl Wakeup {
    pub(crate) fn stopped(&self) -> bool {
        self.stopped.load(Ordering::Relaxed)
    }

    /// Notes a wake-up of the reader (`n` so far).
    pub(crate) fn woke(&self, n: u64) {
        self.count.store(n, Ordering::Relaxed);
    }

    /// A datagram from this address is the alarm.
    pub(crate) fn is_alarm(&self, from: Option<SocketAddr>) -> bool {
        from.is_some() && from == self.alarm
    }
}

/// The alarm's socket, bound on the reader's address (its loopback when the reader listens on
/// every address).
#[derive(Debug)]
pub(crate) struct Alarm {
    pub(crate) sock: UdpSocket,
    pub(crate) to: SocketAddr,
}

impl Alarm {
    pub(crate) fn new(reader: SocketAddr) -> io::Result<Alarm> {
        let ip = match reader.ip() {
            std::net::IpAddr::V4(ip) if ip.is_unspecified() => Ipv4Addr::LOCALHOST.into(),
            std::net::IpAddr::V6(ip) if ip.is_unspecified() => Ipv6Addr::LOCALHOST.into(),
            ip => ip,
        };
        let sock = UdpSocket::bind(SocketAddr::new(ip, 0))?;
        sock.set_nonblocking(true)?;
        Ok(Alarm {
            sock,
            to: SocketAddr::new(ip, reader.port()),
        })
    }

    pub(crate) fn ring(&self) {
        // A full receive buffer means the reader is awake anyway.
        let _ = self.sock.send_to(&[], self.to);
    }
}

/// Stops the reader when dropped: by its task at the end, or with the runtime.
pub(crate) struct Ring {
    pub(crate) stop: CancellationToken,
    pub(crate) wake: Arc<Wakeup>,
    pub(crate) alarm: Option<Alarm>,
    /// The reader's socket, when the alarm cannot reach it (connected to another address):
    /// shutting its receiving side down wakes the reader to stop.
    pub(crate) shut: Option<UdpSocket>,
}

impl Ring {
    pub(crate) fn ring(&self) {
        if let Some(a) = &self.alarm {
            a.ring();
        }
        if let Some(s) = &self.shut
            && self.wake.stopped()
        {
            let _ = rustix::net::shutdown(s, rustix::net::Shutdown::Read);
        }
    }
}

impl Drop for Ring {
    fn drop(&mut self) {
        self.stop.cancel();
        self.wake.stopped.store(true, Ordering::Relaxed);
        self.ring();
    }
}

/// Sets up the stop signal and the wake-ups of a blocking reader on `sock`: `cancel`, and also
/// the end of the runtime (the task holding the [`Ring`] is dropped then), so a runtime shut
/// down without cancelling never waits on the thread. Returns the stop token (for the
/// reader's writers) and what the reader looks at. `connected`: the socket hears only its
/// destination, so it is woken to stop by shutting its receiving side down.
pub(crate) fn blocking_wakeup(
    cancel: &CancellationToken,
    sock: &UdpSocket,
    idle: Option<Duration>,
    connected: bool,
) -> (CancellationToken, Arc<Wakeup>) {
    let stop = cancel.child_token();
    let alarm = sock
        .local_addr()
        .and_then(Alarm::new)
        .and_then(|a| Ok((a.sock.local_addr()?, a)));
    let alarm = match alarm {
        Ok((from, a)) => match sock.set_read_timeout(None) {
            Ok(()) => Some((from, a)),
            Err(e) => {
                tracing::debug!("udp reader without a timeout: {e}");
                None
            }
        },
        Err(e) => {
            tracing::debug!("udp reader alarm: {e}; waking on a timeout instead");
            None
        }
    };
    let wake = Arc::new(Wakeup {
        stopped: AtomicBool::new(false),
        count: AtomicU64::new(0),
        alarm: alarm.as_ref().map(|(from, _)| *from),
    });
    let ring = Ring {
        stop: stop.clone(),
        wake: Arc::clone(&wake),
        alarm: alarm.map(|(_, a)| a),
        shut: if connected {
            sock.try_clone()
                .inspect_err(|e| tracing::debug!("udp reader stop: {e}"))
                .ok()
        } else {
            None
        },
    };
    if ring.alarm.is_none() || (connected && ring.shut.is_none()) {
        let tick = idle.map_or(BLOCKING_TICK, |i| i.min(BLOCKING_TICK));
        if let Err(e) = sock.set_read_timeout(Some(tick)) {
            tracing::debug!("udp reader timeout: {e}");
        }
    }
    let idle = idle.filter(|_| ring.alarm.is_some());
    tokio::spawn(async move {
        let mut seen = 0;
        loop {
            tokio::select! {
                () = ring.stop.cancelled() => break,
                () = async {
                    match idle {
                        Some(p) => tokio::time::sleep(p).await,
                        None => std::future::pending().await,
                    }
                } => {
                    let n = ring.wake.count.load(Ordering::Relaxed);
                    // Its own ring wakes the reader once more: that is not traffic.
                    seen = if n == seen {
                        ring.ring();
                        n + 1
                    } else {
                        n
                    };
                }
            }
        }
        ring.wake.stopped.store(true, Ordering::Relaxed);
        // Until the reader is gone: an alarm may be lost to a full receive buffer.
        while Arc::strong_count(&ring.wake) > 1 {
            ring.ring();
            tokio::time::sleep(BLOCKING_TICK).await;
        }
    });
    (stop, wake)
}
