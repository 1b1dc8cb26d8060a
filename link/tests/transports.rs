//! Transport tests on real loopback sockets (port 0) and in-memory pipes. UDP endpoints are
//! tested with both kinds of owner: a queue ([`Events::Queue`], as the client and the tools) and
//! an inline one ([`Events::Inline`], as the daemon's router), for which the socket is read by a
//! blocking thread that hands each wake-up's frames to the owner in order while producers send
//! straight from their own task, batches with one `sendmmsg`.

mod common;

use std::sync::Arc;
use std::time::Duration;

use common::{WAIT, hb, wait_down, wait_for, wait_frame, wait_up};
use tokio::io::{AsyncReadExt, AsyncWriteExt};
use tokio::net::{TcpListener, TcpStream, UdpSocket};
use tokio::sync::mpsc;
use tokio::time::timeout;
use tokio_util::sync::CancellationToken;
use vtol_link::{
    EgressFilter, Events, Frame, FrameDecoder, LinkEvent, LinkEventHandler, LinkId, LinkOptions,
    LinkUrl, SendError, SendSummary, spawn_endpoint, spawn_stream_link,
};

fn url(s: &str) -> LinkUrl {
    s.parse().unwrap()
}

/// Reads from a TCP stream until `n` frames have been decoded.
async fn read_frames(s: &mut TcpStream, n: usize) -> Vec<Frame> {
    let mut d = FrameDecoder::new();
    let mut out = Vec::new();
    let mut buf = [0u8; 4096];
    timeout(WAIT, async {
        while out.len() < n {
            let k = s.read(&mut buf).await.unwrap();
            assert!(k > 0, "unexpected EOF");
            d.push(&buf[..k]);
            out.extend(d.frames());
        }
    })
    .await
    .expect("timed out reading frames");
    out
}

async fn recv_datagram(s: &UdpSocket) -> (Vec<u8>, std::net::SocketAddr) {
    let mut buf = [0u8; 2048];
    let (n, from) = timeout(WAIT, s.recv_from(&mut buf))
        .await
        .expect("timed out waiting for a datagram")
        .unwrap();
    (buf[..n].to_vec(), from)
}

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

/// A queue owner: the events in a bounded channel the test reads.
fn queue() -> (Events, mpsc::Receiver<LinkEvent>) {
    let (tx, rx) = mpsc::channel(1024);
    (Events::Queue(tx), rx)
}

/// An owner of a link's events and the queue the test reads them from.
type Owner = fn() -> (Events, mpsc::Receiver<LinkEvent>);

/// Both kinds of owner, by name.
fn owners() -> [(&'static str, Owner); 2] {
    [("queue", queue), ("inline", inline)]
}

#[tokio::test]
async fn udpin_serves_peers_in_order_and_expires_them() {
    for (owner, events) in owners() {
        udpin_case(owner, events).await;
    }
}

async fn udpin_case(owner: &str, events: Owner) {
    let (events, mut ev) = events();
    let cancel = CancellationToken::new();
    let opts = LinkOptions {
        udp_peer_timeout: Duration::from_millis(300),
        ..Default::default()
    };
    let ep = spawn_endpoint(&url("udpin:127.0.0.1:0"), events, opts, cancel.clone())
        .await
        .unwrap();
    let server = ep.local_addr().unwrap();
    assert_ne!(server.port(), 0);

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
        "{owner}: {peer_a}"
    );
    for seq in 0..40 {
        assert_eq!(wait_frame(&mut ev, id_a).await, hb(10, seq), "{owner}");
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
async fn udpout_sends_runs_hears_replies_and_keeps_only_what_it_accepts() {
    for (owner, events) in owners() {
        udpout_case(owner, events).await;
    }
}

async fn udpout_case(owner: &str, events: Owner) {
    let remote = UdpSocket::bind("127.0.0.1:0").await.unwrap();
    let port = remote.local_addr().unwrap().port();
    let (events, mut ev) = events();
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
    let (id, peer, tx) = wait_up(&mut ev).await;
    assert_eq!(Some(id), ep.link_id());
    assert!(
        peer.ends_with(&format!("127.0.0.1:{port}")),
        "{owner}: {peer}"
    );

    let mut run = vec![hb(1, 0), hb(2, 1), hb(1, 2), hb(1, 3)];
    let summary = tx.try_send_many(&mut run);
    assert_eq!((summary.taken, summary.filtered), (3, 1), "{owner}");
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

#[tokio::test]
async fn tcpin_serves_many_clients_and_a_reconnecting_one() {
    let (ev_tx, mut ev) = mpsc::channel(64);
    let cancel = CancellationToken::new();
    let ep = spawn_endpoint(
        &url("tcpin:127.0.0.1:0"),
        ev_tx,
        LinkOptions::default(),
        cancel.clone(),
    )
    .await
    .unwrap();
    let addr = ep.local_addr().unwrap();

    let mut c1 = TcpStream::connect(addr).await.unwrap();
    let (id1, _, tx1) = wait_up(&mut ev).await;
    let mut c2 = TcpStream::connect(addr).await.unwrap();
    let (id2, _, tx2) = wait_up(&mut ev).await;
    assert_ne!(id1, id2);

    c1.write_all(hb(11, 0).as_bytes()).await.unwrap();
    assert_eq!(wait_frame(&mut ev, id1).await, hb(11, 0));
    c2.write_all(hb(12, 0).as_bytes()).await.unwrap();
    assert_eq!(wait_frame(&mut ev, id2).await, hb(12, 0));

    // Batched writes: many queued frames arrive intact and in order.
    for seq in 0..50 {
        tx1.try_send(hb(1, seq)).unwrap();
    }
    tx2.try_send(hb(1, 77)).unwrap();
    let got = read_frames(&mut c1, 50).await;
    assert_eq!(got, (0..50).map(|s| hb(1, s)).collect::<Vec<_>>());
    assert_eq!(read_frames(&mut c2, 1).await, vec![hb(1, 77)]);

    // Client 1 leaves; the listener keeps serving.
    drop(c1);
    assert_eq!(wait_down(&mut ev, id1).await, "end of stream");
    assert_eq!(tx1.try_send(hb(1, 0)), Err(SendError::Closed));

    // A third client: our own reconnecting tcp client endpoint.
    let (cev_tx, mut cev) = mpsc::channel(64);
    let client = spawn_endpoint(
        &url(&format!("tcp:127.0.0.1:{}", addr.port())),
        cev_tx,
        LinkOptions::default(),
        cancel.clone(),
    )
    .await
    .unwrap();
    let (cid, _, ctx) = wait_up(&mut cev).await;
    assert_eq!(Some(cid), client.link_id());
    let (id3, _, tx3) = wait_up(&mut ev).await;
    ctx.try_send(hb(13, 5)).unwrap();
    assert_eq!(wait_frame(&mut ev, id3).await, hb(13, 5));
    tx3.try_send(hb(1, 6)).unwrap();
    assert_eq!(wait_frame(&mut cev, cid).await, hb(1, 6));

    // Client 2 still works alongside.
    c2.write_all(hb(12, 1).as_bytes()).await.unwrap();
    assert_eq!(wait_frame(&mut ev, id2).await, hb(12, 1));

    cancel.cancel();
    timeout(WAIT, ep.join()).await.unwrap();
    timeout(WAIT, client.join()).await.unwrap();
    // Every remaining link reported Down during shutdown.
    wait_down(&mut ev, id2).await;
    let _ = tx2;
}

/// A TCP listener on port 0 and a reconnecting `tcp:` client endpoint aimed at it, with the
/// given event queue length and back-off bounds in ms.
async fn tcp_client_to_listener(
    queue: usize,
    backoff_min_ms: u64,
    backoff_max_ms: u64,
) -> (
    TcpListener,
    std::net::SocketAddr,
    mpsc::Receiver<LinkEvent>,
    CancellationToken,
    vtol_link::EndpointHandle,
) {
    let listener = TcpListener::bind("127.0.0.1:0").await.unwrap();
    let addr = listener.local_addr().unwrap();
    let (ev_tx, ev) = mpsc::channel(queue);
    let cancel = CancellationToken::new();
    let opts = LinkOptions {
        reconnect_min: Duration::from_millis(backoff_min_ms),
        reconnect_max: Duration::from_millis(backoff_max_ms),
        ..Default::default()
    };
    let url = url(&format!("tcp:127.0.0.1:{}", addr.port()));
    let ep = spawn_endpoint(&url, ev_tx, opts, cancel.clone())
        .await
        .unwrap();
    (listener, addr, ev, cancel, ep)
}

#[tokio::test]
async fn tcp_client_reconnects_after_server_restart_with_same_id() {
    let (listener, addr, mut ev, cancel, ep) = tcp_client_to_listener(64, 20, 200).await;
    let id = ep.link_id().unwrap();
    assert!(ep.local_addr().is_none());

    let (mut s, _) = timeout(WAIT, listener.accept()).await.unwrap().unwrap();
    let (up_id, _, tx) = wait_up(&mut ev).await;
    assert_eq!(up_id, id);
    tx.try_send(hb(1, 1)).unwrap();
    assert_eq!(read_frames(&mut s, 1).await, vec![hb(1, 1)]);

    // Server goes away entirely.
    drop(s);
    drop(listener);
    wait_down(&mut ev, id).await;

    // Server comes back on the same port; the client finds it with the same LinkId.
    let listener = TcpListener::bind(addr).await.unwrap();
    let (mut s, _) = timeout(WAIT, listener.accept()).await.unwrap().unwrap();
    let (up_id, _, tx) = wait_up(&mut ev).await;
    assert_eq!(up_id, id);
    s.write_all(hb(7, 3).as_bytes()).await.unwrap();
    assert_eq!(wait_frame(&mut ev, id).await, hb(7, 3));
    tx.try_send(hb(1, 2)).unwrap();
    assert_eq!(read_frames(&mut s, 1).await, vec![hb(1, 2)]);
    let stats = tx.stats().snapshot();
    assert_eq!(stats.tx_frames, 2, "stats persist across reconnects");

    cancel.cancel();
    wait_down(&mut ev, id).await;
    timeout(WAIT, ep.join()).await.unwrap();
}

#[tokio::test]
async fn tcp_client_backs_off_on_immediate_eof() {
    // A server that accepts and closes at once must not make the client spin.
    let (listener, _addr, mut ev, cancel, ep) = tcp_client_to_listener(1024, 50, 400).await;
    // Back-off 50, 100, 200, 400, 400 ms: about five connections in 800 ms, never hundreds.
    let window = Duration::from_millis(800);
    let deadline = tokio::time::Instant::now() + window;
    let mut accepts = 0;
    while let Ok(Ok((s, _))) = tokio::time::timeout_at(deadline, listener.accept()).await {
        drop(s);
        accepts += 1;
    }
    assert!(
        (2..=8).contains(&accepts),
        "{accepts} connections in {window:?}"
    );
    let mut ups = 0;
    while let Ok(ev) = ev.try_recv() {
        ups += usize::from(matches!(ev, LinkEvent::Up { .. }));
    }
    assert!(ups <= accepts, "{ups} Up events for {accepts} connections");
    cancel.cancel();
    timeout(WAIT, ep.join()).await.unwrap();
}

#[tokio::test]
async fn duplex_link_skips_garbage_and_bad_frames() {
    let (ours, mut theirs) = tokio::io::duplex(4096);
    let (ev_tx, mut ev) = mpsc::channel(64);
    let cancel = CancellationToken::new();
    let (id, task) = spawn_stream_link(
        ours,
        "embedded twin",
        ev_tx,
        LinkOptions::default(),
        cancel.clone(),
    );
    let (up_id, peer, tx) = wait_up(&mut ev).await;
    assert_eq!((up_id, peer.as_str()), (id, "embedded twin"));

    let mut bad = hb(5, 2).as_bytes().to_vec();
    bad[11] ^= 0x40; // CRC now wrong
    let mut stream = vec![0xAA, 0xBB];
    stream.extend_from_slice(hb(5, 1).as_bytes());
    stream.extend_from_slice(&bad);
    stream.extend_from_slice(&hb(5, 3).as_bytes()[..7]); // truncated frame...
    stream.extend_from_slice(hb(5, 4).as_bytes()); // ...swallowed until CRC fails, then found
    stream.extend_from_slice(&[0x01; 40]);
    stream.extend_from_slice(hb(5, 5).as_bytes());
    theirs.write_all(&stream).await.unwrap();
    for seq in [1, 4, 5] {
        assert_eq!(wait_frame(&mut ev, id).await, hb(5, seq));
    }
    let s = tx.stats().snapshot();
    assert_eq!(s.rx_frames, 3);
    assert_eq!(s.rx_bytes, stream.len() as u64);
    assert!(s.bad_crc >= 1, "{s:?}");
    assert!(s.garbage_bytes >= 2 + 40 + bad.len() as u64 + 7, "{s:?}");

    // Egress.
    tx.try_send(hb(1, 1)).unwrap();
    let mut buf = [0u8; 64];
    let n = timeout(WAIT, theirs.read(&mut buf)).await.unwrap().unwrap();
    assert_eq!(&buf[..n], hb(1, 1).as_bytes());

    // EOF from the peer: Down, and the task ends.
    drop(theirs);
    assert_eq!(wait_down(&mut ev, id).await, "end of stream");
    timeout(WAIT, task).await.unwrap().unwrap();
}

#[tokio::test]
async fn full_queue_drops_and_counts() {
    let (ours, _theirs) = tokio::io::duplex(64); // tiny pipe nobody reads
    let (ev_tx, mut ev) = mpsc::channel(64);
    let cancel = CancellationToken::new();
    let opts = LinkOptions {
        queue_len: 4,
        ..Default::default()
    };
    let (_id, task) = spawn_stream_link(ours, "slow", ev_tx, opts, cancel.clone());
    let (_, _, tx) = wait_up(&mut ev).await;
    let mut dropped = 0;
    for seq in 0..100 {
        if tx.try_send(hb(1, seq)) == Err(SendError::Full) {
            dropped += 1;
        }
    }
    assert!(dropped >= 90, "{dropped}");
    assert_eq!(tx.stats().snapshot().tx_dropped_queue_full, dropped);
    cancel.cancel();
    timeout(WAIT, task).await.unwrap().unwrap();
}

#[tokio::test]
async fn bind_errors_surface_at_spawn() {
    let taken = TcpListener::bind("127.0.0.1:0").await.unwrap();
    let port = taken.local_addr().unwrap().port();
    let (ev_tx, _ev) = mpsc::channel(4);
    let err = spawn_endpoint(
        &url(&format!("tcpin:127.0.0.1:{port}")),
        ev_tx,
        LinkOptions::default(),
        CancellationToken::new(),
    )
    .await
    .unwrap_err();
    assert!(err.to_string().contains("cannot bind"), "{err}");
}
