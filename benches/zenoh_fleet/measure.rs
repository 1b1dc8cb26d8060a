//! What the clients measure: each ground daemon's client matches the telemetry it receives to
//! its publication (loss, latency); and the frames the vehicles publish.

use std::net::UdpSocket;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::{Mutex, OnceLock};
use std::time::{Duration, Instant};

use vtol_link::dialect::{self, MavMessage};

pub const ATTITUDE: u32 = 30;
pub const SERVO_OUTPUT_RAW: u32 = 36;

fn epoch() -> Instant {
    static EPOCH: OnceLock<Instant> = OnceLock::new();
    *EPOCH.get_or_init(Instant::now)
}

pub fn now_ns() -> u64 {
    u64::try_from(epoch().elapsed().as_nanos()).unwrap_or(u64::MAX)
}

/// Publication times (ns) by vehicle and sequence number (a vehicle's frames share one
/// sequence, as on a real link; it wraps every 4 s, far beyond any latency).
pub struct Sent(Vec<[AtomicU64; 256]>);

impl Sent {
    pub fn new(vehicles: usize) -> Self {
        Sent(
            (0..vehicles)
                .map(|_| std::array::from_fn(|_| AtomicU64::new(0)))
                .collect(),
        )
    }
    /// Vehicle `v` (0-based over the whole fleet).
    pub fn slot(&self, v: usize, seq: u8) -> &AtomicU64 {
        &self.0[v][usize::from(seq)]
    }
}

/// What one daemon's client received.
#[derive(Default)]
pub struct Received {
    pub window: Option<(u64, u64)>,
    pub frames: u64,
    pub latencies_ns: Vec<u64>,
    /// Vehicles (0-based over the whole fleet) heard at this client.
    pub vehicles_heard: std::collections::HashSet<usize>,
}

/// Which part of the fleet a client's daemon serves: vehicles `first ..= first + per - 1`
/// (0-based), system ids 1 to `per`.
#[derive(Clone, Copy)]
pub struct Part {
    pub first: usize,
    pub per: usize,
    pub vehicles: usize,
}

impl Part {
    /// The 0-based fleet index of system id `sys` in this part.
    pub fn vehicle(&self, sys: u8) -> Option<usize> {
        let v = self.first + usize::from(sys).checked_sub(1)?;
        (sys != 0 && usize::from(sys) <= self.per && v < self.vehicles).then_some(v)
    }
}

/// A client's socket: loopback, a receive buffer of 4 MiB (the forwarding bench's sinks').
pub fn client_socket() -> UdpSocket {
    let s = socket2::Socket::new(socket2::Domain::IPV4, socket2::Type::DGRAM, None).unwrap();
    let _ = s.set_recv_buffer_size(4 << 20);
    s.bind(&std::net::SocketAddr::from(([127, 0, 0, 1], 0)).into())
        .unwrap();
    s.into()
}

/// A client: receives its daemon's UDP copies and matches telemetry to its publication.
pub fn sink(sock: &UdpSocket, part: Part, sent: &Sent, acc: &Mutex<Received>, stop: &AtomicBool) {
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
        let Some(v) = part.vehicle(sys) else { continue };
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

pub fn percentile(sorted: &[u64], p: f64) -> f64 {
    if sorted.is_empty() {
        return f64::NAN;
    }
    let i = ((sorted.len() - 1) as f64 * p).round() as usize;
    sorted[i] as f64 / 1e6
}

pub fn attitude(t_ms: u32) -> MavMessage {
    MavMessage::ATTITUDE(dialect::ATTITUDE_DATA {
        time_boot_ms: t_ms,
        roll: 0.01,
        pitch: -0.02,
        yaw: 1.5,
        ..Default::default()
    })
}

pub fn servo(t_ms: u32) -> MavMessage {
    MavMessage::SERVO_OUTPUT_RAW(dialect::SERVO_OUTPUT_RAW_DATA {
        time_usec: t_ms.wrapping_mul(1000),
        servo1_raw: 1500,
        servo2_raw: 1510,
        ..Default::default()
    })
}

pub fn heartbeat() -> MavMessage {
    MavMessage::HEARTBEAT(dialect::HEARTBEAT_DATA {
        mavtype: dialect::MavType::MAV_TYPE_VTOL_TAILSITTER_DUOROTOR,
        autopilot: dialect::MavAutopilot::MAV_AUTOPILOT_ARDUPILOTMEGA,
        base_mode: dialect::MavModeFlag::MAV_MODE_FLAG_CUSTOM_MODE_ENABLED,
        custom_mode: 17,
        system_status: dialect::MavState::MAV_STATE_STANDBY,
        mavlink_version: 3,
    })
}
