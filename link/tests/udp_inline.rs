//! UDP endpoints with an inline owner ([`Events::Inline`], as the daemon's router): the socket
//! is read by a blocking thread that hands each wake-up's frames to the owner in order, and
//! producers send straight from their own task, batches with one `sendmmsg`. Real loopback
//! sockets on port 0.

mod common;

use std::sync::Arc;
use std::time::Duration;

use common::{WAIT, hb, wait_down, wait_for, wait_frame, wait_up};
use tokio::net::UdpSocket;
use tokio::sync::mpsc;
use tokio::time::timeout;
use tokio_util::sync::CancellationToken;
use vtol_link::{
    EgressFilter, Events, Frame, LinkEvent, LinkEventHandler, LinkId, LinkOptions, LinkUrl,
    SendError, SendSummary, spawn_endpoint,
};

/// An inline owner that passes what it is handed to a queue the test reads, in order.
struct Recorder(mpsc::Sender<LinkEvent>);

impl LinkEventHandler for Recorder {
    fn event(&self, event: LinkEvent) -> bool {
        self.0.try_send(event).is_ok()
    }

    fn frames(&self, frames: &mut Vec<(LinkId, Frame)>) -> bool {
        frames
            .drain(..)
            .all(|(id, frame)| self.0.try_send(LinkEvent::Frame { id, frame }).is_ok())
    }
}

fn inline() -> (Events, mpsc::Receiver<LinkEvent>) {
    let (tx, rx) = mpsc::channel(1024);
    let handler: Arc<dyn LinkEventHandler> = Arc::new(Recorder(tx));
    (Events::Inline(handler), rx)
}

fn url(s: &str) -> LinkUrl {
    s.parse().unwrap()
}

async fn recv_datagram(s: &UdpSocket) -> (Vec<u8>, std::net::SocketAddr) {
    let mut buf = [0u8; 2048];
    let (n, from) = timeout(WAIT, s.recv_from(&mut buf))
        .await
        .expect("timed out waiting for a datagram")
        .unwrap();
    (buf[..n].to_vec(), from)
}

#[tokio::test]
async fn udpin_with_an_inline_owner_serves_peers_in_order_and_expires_them() {
    let (events, mut ev) = inline();
    let cancel = CancellationToken::new();
    let opts = LinkOptions {
        udp_peer_timeout: Duration::from_millis(300),
        ..Default::default()
    };
    let ep = spawn_endpoint(&url("udpin:127.0.0.1:0"), events, opts, cancel.clone())
        .await
        .unwrap();
    let server = ep.local_addr().unwrap();

    let a = UdpSocket::bind("127.0.0.1:0").await.unwrap();
    let b = UdpSocket::bind("127.0.0.1:0").await.unwrap();
    // Peer A: garbage before the frame in the same datagram is skipped and counted; a burst
    // that lands in one or several wake-ups arrives whole and in order.
    let mut dgram = vec![0x00, 0x11, 0xFE];
    dgram.extend_from_slice(hb(10, 0).as_bytes());
    a.send_to(&dgram, server).await.unwrap();
    for seq in 1..40 {
        a.send_to(hb(10, seq).as_bytes(), server).await.unwrap();
    }
    let (id_a, peer_a, tx_a) = wait_up(&mut ev).await;
    assert!(
        peer_a.contains(&a.local_addr().unwrap().to_string()),
        "{peer_a}"
    );
    for seq in 0..40 {
        assert_eq!(wait_frame(&mut ev, id_a).await, hb(10, seq));
    }
    b.send_to(hb(20, 1).as_bytes(), server).await.unwrap();
    let (id_b, _, tx_b) = wait_up(&mut ev).await;
    assert_ne!(id_a, id_b);
    assert_eq!(wait_frame(&mut ev, id_b).await, hb(20, 1));

    // A run for one peer goes out in order, one datagram per frame, from the server's port.
    let mut run: Vec<Frame> = (100..110).map(|seq| hb(1, seq)).collect();
    let summary = tx_a.try_send_many(&mut run);
    assert_eq!(
        summary,
        SendSummary {
            taken: 10,
            ..Default::default()
        }
    );
    assert!(run.is_empty());
    for seq in 100..110 {
        let (got, from) = recv_datagram(&a).await;
        assert_eq!(got, hb(1, seq).as_bytes());
        assert_eq!(from, server);
    }
    tx_b.try_send(hb(1, 200)).unwrap();
    assert_eq!(recv_datagram(&b).await.0, hb(1, 200).as_bytes());

    let s = tx_a.stats().snapshot();
    assert_eq!(s.rx_frames, 40);
    assert_eq!(s.garbage_bytes, 3);
    assert_eq!(s.tx_frames, 10);

    // Silence: both peers go down after the timeout, their queues close.
    let mut downs = vec![];
    for _ in 0..2 {
        match wait_for(&mut ev, "Down", |e| matches!(e, LinkEvent::Down { .. })).await {
            LinkEvent::Down { id, reason } => {
                assert!(reason.contains("silent"), "{reason}");
                downs.push(id);
            }
            _ => unreachable!(),
        }
    }
    downs.sort();
    let mut want = vec![id_a, id_b];
    want.sort();
    assert_eq!(downs, want);
    timeout(WAIT, tx_a.closed())
        .await
        .expect("queue closes when the peer expires");
    assert_eq!(tx_a.try_send(hb(1, 0)), Err(SendError::Closed));

    // Heard again: a new link. Cancelling ends the reader thread (within its tick) and
    // reports the link down.
    a.send_to(hb(10, 50).as_bytes(), server).await.unwrap();
    let (id_a2, _, _) = wait_up(&mut ev).await;
    assert_ne!(id_a2, id_a);
    cancel.cancel();
    assert_eq!(wait_down(&mut ev, id_a2).await, "shutdown");
    timeout(WAIT, ep.join()).await.unwrap();
}

#[tokio::test]
async fn udpout_with_an_inline_owner_sends_runs_hears_replies_and_keeps_only_what_it_accepts() {
    let remote = UdpSocket::bind("127.0.0.1:0").await.unwrap();
    let port = remote.local_addr().unwrap().port();
    let (events, mut ev) = inline();
    let cancel = CancellationToken::new();
    // This link takes frames from system 1 only.
    let opts = LinkOptions {
        accept: Some(EgressFilter::new(|f| f.system_id() == 1)),
        ..Default::default()
    };
    let ep = spawn_endpoint(
        &url(&format!("udpout:127.0.0.1:{port}")),
        events,
        opts,
        cancel.clone(),
    )
    .await
    .unwrap();
    let (id, _, tx) = wait_up(&mut ev).await;
    assert_eq!(Some(id), ep.link_id());

    let mut run = vec![hb(1, 0), hb(2, 1), hb(1, 2), hb(1, 3)];
    let summary = tx.try_send_many(&mut run);
    assert_eq!((summary.taken, summary.filtered), (3, 1));
    // Not accepted: dropped, and reported as dealt with.
    assert_eq!(tx.try_send(hb(2, 4)), Ok(()));
    tx.try_send(hb(1, 5)).unwrap();
    let mut from = None;
    for seq in [0, 2, 3, 5] {
        let (d, f) = recv_datagram(&remote).await;
        assert_eq!(d, hb(1, seq).as_bytes(), "one frame per datagram, in order");
        from = Some(f);
    }
    assert_eq!(from.unwrap().port(), ep.local_addr().unwrap().port());
    assert_eq!(tx.stats().snapshot().tx_frames, 4);

    remote
        .send_to(hb(2, 9).as_bytes(), from.unwrap())
        .await
        .unwrap();
    assert_eq!(wait_frame(&mut ev, id).await, hb(2, 9));

    cancel.cancel();
    wait_down(&mut ev, id).await;
    timeout(WAIT, ep.join()).await.unwrap();
}

#[test]
fn a_runtime_shut_down_without_cancelling_does_not_wait_for_the_readers() {
    let (done_tx, done_rx) = std::sync::mpsc::channel();
    std::thread::spawn(move || {
        let rt = tokio::runtime::Runtime::new().unwrap();
        let (_rx, _eps) = rt.block_on(async {
            let (events, rx) = inline();
            let cancel = CancellationToken::new();
            let mut eps = Vec::new();
            for u in ["udpin:127.0.0.1:0", "udpout:127.0.0.1:9"] {
                let ep = spawn_endpoint(
                    &url(u),
                    events.clone(),
                    LinkOptions::default(),
                    cancel.clone(),
                )
                .await
                .unwrap();
                eps.push(ep);
            }
            (rx, eps)
        });
        // Never cancelled: dropping the runtime must still stop the blocking readers.
        drop(rt);
        let _ = done_tx.send(());
    });
    done_rx
        .recv_timeout(WAIT)
        .expect("the runtime's shutdown waited on a blocking reader");
}

/// The remote addresses of the IPv4 UDP sockets bound to `port`, from `/proc/net/udp`
/// (`None`: not connected).
fn remotes_of_port(port: u16) -> Vec<Option<std::net::SocketAddr>> {
    let table = std::fs::read_to_string("/proc/net/udp").expect("Linux lists its UDP sockets");
    let hex_addr = |s: &str| {
        let (ip, port) = s.split_once(':').unwrap();
        let ip = u32::from_str_radix(ip, 16).unwrap();
        let port = u16::from_str_radix(port, 16).unwrap();
        // The address is in the kernel's (network) byte order, printed as a host integer.
        std::net::SocketAddr::from((std::net::Ipv4Addr::from(ip.swap_bytes()), port))
    };
    table
        .lines()
        .skip(1)
        .filter_map(|l| {
            let mut cols = l.split_whitespace().skip(1);
            let (local, remote) = (hex_addr(cols.next()?), hex_addr(cols.next()?));
            (local.port() == port).then_some((remote.port() != 0).then_some(remote))
        })
        .collect()
}

/// Waits until the sockets on `port` have these remote addresses (in any order).
async fn wait_remotes(port: u16, want: &[Option<std::net::SocketAddr>], what: &str) {
    let mut want = want.to_vec();
    want.sort();
    let fut = async {
        loop {
            let mut got = remotes_of_port(port);
            got.sort();
            if got == want {
                return;
            }
            tokio::time::sleep(Duration::from_millis(5)).await;
        }
    };
    timeout(WAIT, fut).await.unwrap_or_else(|_| {
        panic!(
            "{what}: sockets on port {port}: {:?}",
            remotes_of_port(port)
        )
    });
}

#[tokio::test]
async fn a_udpout_socket_is_connected_while_its_destination_listens_and_hears_every_sender() {
    // A port nobody listens on yet.
    let dest = std::net::UdpSocket::bind("127.0.0.1:0")
        .unwrap()
        .local_addr()
        .unwrap();
    let (events, mut ev) = inline();
    let cancel = CancellationToken::new();
    let ep = spawn_endpoint(
        &url(&format!("udpout:{dest}")),
        events,
        LinkOptions::default(),
        cancel.clone(),
    )
    .await
    .unwrap();
    let (id, _, tx) = wait_up(&mut ev).await;
    let port = ep.local_addr().unwrap().port();
    // One socket connected to the destination, one for every other sender.
    wait_remotes(port, &[Some(dest), None], "at the start").await;

    // Nobody listens: the kernel answers each datagram with an ICMP error, which a connected
    // socket reports. The first one makes the link send with the address instead, and no
    // datagram is lost to the errors.
    for seq in 0..50 {
        tx.try_send(hb(1, seq)).unwrap();
    }
    wait_remotes(port, &[None, None], "after a datagram nobody took").await;
    let stats = tx.stats().snapshot();
    assert_eq!((stats.tx_frames, stats.tx_errors), (50, 0));

    // A listener comes: it gets the datagrams at once, and its first reply connects the
    // socket again.
    let remote = UdpSocket::bind(dest).await.unwrap();
    tx.try_send(hb(1, 50)).unwrap();
    let (d, from) = recv_datagram(&remote).await;
    assert_eq!(d, hb(1, 50).as_bytes());
    assert_eq!(from.port(), port);
    remote.send_to(hb(2, 0).as_bytes(), from).await.unwrap();
    assert_eq!(wait_frame(&mut ev, id).await, hb(2, 0));
    wait_remotes(port, &[Some(dest), None], "after the destination replied").await;
    tx.try_send(hb(1, 51)).unwrap();
    assert_eq!(recv_datagram(&remote).await.0, hb(1, 51).as_bytes());
    remote.send_to(hb(2, 1).as_bytes(), from).await.unwrap();
    assert_eq!(wait_frame(&mut ev, id).await, hb(2, 1));

    // Another sender, from another address, is heard on the same link.
    let other = UdpSocket::bind("127.0.0.1:0").await.unwrap();
    other.send_to(hb(3, 0).as_bytes(), from).await.unwrap();
    assert_eq!(wait_frame(&mut ev, id).await, hb(3, 0));
    assert_eq!(tx.stats().snapshot().tx_errors, 0);

    cancel.cancel();
    assert_eq!(wait_down(&mut ev, id).await, "shutdown");
    timeout(WAIT, ep.join()).await.unwrap();
    // The sender held the last reference to the socket.
    drop(tx);
    wait_remotes(port, &[], "after the link's end").await;
}
