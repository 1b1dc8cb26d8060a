//! The router, driven as the daemon drives it (inline, from the link tasks), over real
//! in-memory byte links: bytes out equal bytes in (raw forwarding,
//! sequence numbers intact), no echo to the ingress link, targeted frames only where the
//! target was seen, and every frame logged to the tlog in both directions.

mod common;

use std::time::Duration;

use common::{logged_router, read_until, stream_link, wait_links};
use proptest::prelude::*;
use tokio::io::{AsyncWriteExt, DuplexStream};
use tokio_util::sync::CancellationToken;
use vtol_gcs::daemon::Routing;
use vtol_gcs::links::Side;
use vtol_gcs::tlog::TlogReader;
use vtol_link::Frame;
use vtol_link::dialect::{self, MavMessage};

fn param_request_read(target_system: u8, index: i16) -> MavMessage {
    MavMessage::PARAM_REQUEST_READ(dialect::PARAM_REQUEST_READ_DATA {
        param_index: index,
        target_system,
        target_component: 0,
        param_id: "HOVER_ALT".into(),
    })
}

fn statustext(n: u8) -> MavMessage {
    MavMessage::STATUSTEXT(dialect::STATUSTEXT_DATA {
        severity: dialect::MavSeverity::MAV_SEVERITY_INFO,
        text: format!("frame {n}").as_str().into(),
        ..Default::default()
    })
}

/// Reads frames from `end` until `n` arrived or `limit` passed.
async fn read_frames(end: &mut DuplexStream, n: usize, limit: Duration) -> Vec<Frame> {
    read_until(end, limit, |f| f.len() >= n).await
}

struct Harness {
    vehicle: DuplexStream,
    clients: Vec<DuplexStream>,
    cancel: CancellationToken,
    router: Routing,
    link_tasks: Vec<tokio::task::JoinHandle<()>>,
    tlog_path: std::path::PathBuf,
    handle: vtol_gcs::links::RouterHandle,
    _dir: tempfile::TempDir,
}

async fn harness(n_clients: usize) -> Harness {
    let (dir, tlog_path, router, handle) = logged_router();
    let cancel = CancellationToken::new();
    let (vehicle, _, task) = stream_link(&router, Side::Vehicle, "vehicle", &cancel);
    let mut link_tasks = vec![task];
    let mut clients = Vec::new();
    for i in 0..n_clients {
        let (c, _, task) = stream_link(&router, Side::Client, &format!("client {i}"), &cancel);
        link_tasks.push(task);
        clients.push(c);
    }
    // Wait until the router has every link up (an event, with an upper bound).
    let mut links = handle.links.clone();
    wait_links(&mut links, n_clients + 1, "links up").await;
    Harness {
        vehicle,
        clients,
        cancel,
        router,
        link_tasks,
        tlog_path,
        handle,
        _dir: dir,
    }
}

async fn finish(h: Harness) -> Vec<(u64, Frame)> {
    h.cancel.cancel();
    for task in h.link_tasks {
        task.await.unwrap();
    }
    h.router.close();
    TlogReader::open(&h.tlog_path).unwrap().collect()
}

#[tokio::test]
async fn targeted_frames_reach_only_links_where_the_target_was_seen() {
    let mut h = harness(2).await;
    // Client 0 announces itself as system 200, client 1 as 201.
    for (i, sys) in [(0usize, 200u8), (1, 201)] {
        let f = Frame::encode_v2(
            vtol_link::SystemId(sys),
            vtol_link::ComponentId(0),
            0,
            &statustext(0),
        );
        h.clients[i].write_all(f.as_bytes()).await.unwrap();
    }
    // The vehicle sees both broadcasts.
    let seen = read_frames(&mut h.vehicle, 2, Duration::from_secs(5)).await;
    assert_eq!(seen.len(), 2);
    // A vehicle frame targeted at 201 must reach client 1 only.
    let targeted = Frame::encode_v2(
        vtol_link::SystemId(1),
        vtol_link::ComponentId(1),
        9,
        &param_request_read(201, 3),
    );
    let marker = Frame::encode_v2(
        vtol_link::SystemId(1),
        vtol_link::ComponentId(1),
        10,
        &statustext(1),
    );
    h.vehicle.write_all(targeted.as_bytes()).await.unwrap();
    h.vehicle.write_all(marker.as_bytes()).await.unwrap();
    // Each client also hears the other's broadcast; keep the vehicle's frames.
    let from_vehicle = |v: Vec<Frame>| {
        v.into_iter()
            .filter(|f| f.system_id() == 1)
            .collect::<Vec<_>>()
    };
    let c1 = from_vehicle(read_frames(&mut h.clients[1], 3, Duration::from_secs(5)).await);
    assert_eq!(c1, vec![targeted.clone(), marker.clone()]);
    // Client 0 gets the broadcast marker and nothing of the vehicle's before it.
    let c0 = from_vehicle(read_frames(&mut h.clients[0], 2, Duration::from_secs(5)).await);
    assert_eq!(c0, vec![marker]);
    let log = finish(h).await;
    // Both directions are in the log: 2 client frames (stamp bits 3), 2 vehicle frames (0).
    assert_eq!(log.iter().filter(|(t, _)| t & 3 == 3).count(), 2);
    assert_eq!(log.iter().filter(|(t, _)| t & 3 == 0).count(), 2);
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 12, .. ProptestConfig::default() })]
    /// Broadcast frames from the vehicle reach every client byte for byte, in order, with their
    /// own sequence numbers; nothing comes back to the vehicle link.
    #[test]
    fn bytes_out_equal_bytes_in(seqs in proptest::collection::vec(any::<u8>(), 1..60), n_clients in 1usize..4) {
        let rt = tokio::runtime::Runtime::new().unwrap();
        rt.block_on(async {
            let mut h = harness(n_clients).await;
            let frames: Vec<Frame> = seqs.iter().enumerate()
                .map(|(i, s)| Frame::encode_v2(vtol_link::SystemId(1), vtol_link::ComponentId(1), *s, &statustext(u8::try_from(i % 250).unwrap())))
                .collect();
            let mut sent = Vec::new();
            for f in &frames {
                sent.extend_from_slice(f.as_bytes());
            }
            h.vehicle.write_all(&sent).await.unwrap();
            for c in &mut h.clients {
                let got = read_frames(c, frames.len(), Duration::from_secs(5)).await;
                let got_bytes: Vec<u8> = got.iter().flat_map(|f| f.as_bytes().to_vec()).collect();
                assert_eq!(got_bytes, sent);
            }
            // No echo: the first thing the vehicle link receives is a client's marker, sent
            // after every vehicle frame was delivered.
            let marker = Frame::encode_v2(vtol_link::SystemId(255), vtol_link::ComponentId(0), 0, &statustext(255));
            h.clients[0].write_all(marker.as_bytes()).await.unwrap();
            let first = read_frames(&mut h.vehicle, 1, Duration::from_secs(5)).await;
            assert_eq!(first, vec![marker]);
            let log = finish(h).await;
            assert_eq!(log.len(), frames.len() + 1);
        });
    }
}

#[tokio::test]
async fn unknown_message_ids_and_v1_frames_are_forwarded_unchanged() {
    let mut h = harness(1).await;
    // An id no dialect here knows, framed correctly (its CRC cannot be checked).
    let id = 65_001;
    assert!(
        vtol_link::frame::crc_extra(id).is_none(),
        "pick an id the dialect does not know"
    );
    let unknown = Frame::encode_raw_v2(
        vtol_link::SystemId(1),
        vtol_link::ComponentId(1),
        5,
        id,
        &[1, 2, 3, 4],
        77,
    )
    .unwrap();
    let v1 = Frame::encode_v1(
        vtol_link::SystemId(1),
        vtol_link::ComponentId(1),
        6,
        &statustext(3),
    )
    .unwrap();
    let marker = Frame::encode_v2(
        vtol_link::SystemId(1),
        vtol_link::ComponentId(1),
        7,
        &statustext(4),
    );
    for f in [&unknown, &v1, &marker] {
        h.vehicle.write_all(f.as_bytes()).await.unwrap();
    }
    let got = read_frames(&mut h.clients[0], 3, Duration::from_secs(5)).await;
    assert_eq!(
        got.iter()
            .map(|f| f.as_bytes().to_vec())
            .collect::<Vec<_>>(),
        vec![
            unknown.as_bytes().to_vec(),
            v1.as_bytes().to_vec(),
            marker.as_bytes().to_vec()
        ]
    );
    finish(h).await;
}

#[tokio::test]
async fn a_slow_client_loses_frames_counted_while_the_others_get_everything() {
    let mut h = harness(2).await;
    // Client 1 never reads: its duplex buffer fills, then its egress queue, then its drops are
    // counted. Client 0 reads each batch before the next is sent, so it never falls behind.
    let mut seq = 0u8;
    for _batch in 0..40 {
        let mut bytes = Vec::new();
        for i in 0..500u32 {
            seq = seq.wrapping_add(1);
            bytes.extend_from_slice(
                Frame::encode_v2(
                    vtol_link::SystemId(1),
                    vtol_link::ComponentId(1),
                    seq,
                    &statustext((i % 250) as u8),
                )
                .as_bytes(),
            );
        }
        h.vehicle.write_all(&bytes).await.unwrap();
        let got = read_frames(&mut h.clients[0], 500, Duration::from_secs(20)).await;
        assert_eq!(got.len(), 500, "the reading client must get every frame");
    }
    let links = h.handle.links.borrow().clone();
    let dropped: Vec<u64> = links
        .iter()
        .map(|l| l.stats.snapshot().tx_dropped_queue_full)
        .collect();
    assert_eq!(
        dropped.iter().filter(|d| **d > 0).count(),
        1,
        "only the slow client drops: {dropped:?}"
    );
    finish(h).await;
}
