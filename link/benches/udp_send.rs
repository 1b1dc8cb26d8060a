//! What a udpout link pays per datagram in the kernel: an unconnected `sendto` (the route
//! looked up for every datagram) against `send` on a socket connected to the destination (the
//! route kept), a 40-byte datagram to a loopback listener. The listener is emptied between
//! timed batches, outside the time, so every datagram is delivered. One thread; criterion's
//! time per datagram is CPU time per datagram on a quiet machine (the kernel delivers a
//! loopback datagram within the call).
//!
//! Run: `cargo bench -p vtol-link --bench udp_send`

use std::net::UdpSocket;
use std::time::{Duration, Instant};

use criterion::{Criterion, criterion_group, criterion_main};

/// Datagrams per timed batch: well within the listener's receive buffer.
const BATCH: u64 = 128;

fn drain(sink: &UdpSocket) {
    let mut buf = [0u8; 64];
    while sink.recv(&mut buf).is_ok() {}
}

fn udp_send(c: &mut Criterion) {
    let sink = UdpSocket::bind("127.0.0.1:0").unwrap();
    sink.set_nonblocking(true).unwrap();
    let dest = sink.local_addr().unwrap();
    let datagram = [0x5au8; 40];
    let mut group = c.benchmark_group("udp datagram to a loopback listener");
    for connected in [false, true] {
        let sock = UdpSocket::bind("127.0.0.1:0").unwrap();
        if connected {
            sock.connect(dest).unwrap();
        }
        let name = if connected {
            "send, connected socket"
        } else {
            "sendto, unconnected socket"
        };
        group.bench_function(name, |b| {
            b.iter_custom(|iters| {
                let mut spent = Duration::ZERO;
                let mut left = iters;
                while left > 0 {
                    let n = left.min(BATCH);
                    let t = Instant::now();
                    for _ in 0..n {
                        let sent = if connected {
                            sock.send(&datagram)
                        } else {
                            sock.send_to(&datagram, dest)
                        };
                        assert_eq!(sent.unwrap(), datagram.len());
                    }
                    spent += t.elapsed();
                    left -= n;
                    drain(&sink);
                }
                spent
            });
        });
    }
    group.finish();
}

criterion_group!(benches, udp_send);
criterion_main!(benches);
