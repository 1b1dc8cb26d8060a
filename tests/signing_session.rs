//! A signed session through the daemon's router survives a 10-minute idle and a 90 s vehicle
//! link outage with no command refused, without waiting minutes: the time is a test clock.
//!
//! What it models: the daemon's signing path exactly as `vtol-gcs run` wires it (the inline
//! router, a `DaemonSigning` in it, a `trust=sign` client link: the same path as the daemon's
//! own traffic), over real in-memory byte links. The far end of the vehicle link is a vehicle
//! checking signatures with `vtol_link::signing::Signing`, the rules the keyed twin applies,
//! and answering each command with a signed COMMAND_ACK that the router must verify before the
//! client gets it. Both sides read the same test clock, which the test moves forward: 10
//! minutes with no frame at all (idle), then the vehicle link cut for 90 s and reopened as a new
//! link, once with the vehicle remembering its streams (a radio outage) and once having
//! forgotten them (a vehicle reboot). Timestamps that only counted frames would be stale after
//! the idle; the wall-clock timestamps pass every time.

use std::sync::Arc;
use std::sync::atomic::{AtomicU64, Ordering};
use std::time::{Duration, SystemTime};

use tokio::io::{AsyncReadExt, AsyncWriteExt, DuplexStream};
use tokio_util::sync::CancellationToken;
use vtol_gcs::daemon::Routing;
use vtol_gcs::links::Side;
use vtol_gcs::trust::policy::{EndpointPolicy, Trust};
use vtol_gcs::trust::signing::{DaemonSigning, WallClock};
use vtol_link::dialect::{self, MavMessage};
use vtol_link::signing::{Accepted, Signing};
use vtol_link::{Frame, FrameDecoder, LinkOptions, SigningKey, spawn_stream_link};

/// Reads one frame of `msg_id` from `end`, with `limit` as the upper bound.
async fn next_frame(
    end: &mut DuplexStream,
    dec: &mut FrameDecoder,
    msg_id: u32,
    limit: Duration,
) -> Frame {
    let deadline = tokio::time::Instant::now() + limit;
    let mut buf = [0u8; 4096];
    loop {
        if let Some(f) = dec.frames().find(|f| f.message_id() == msg_id) {
            return f;
        }
        match tokio::time::timeout_at(deadline, end.read(&mut buf)).await {
            Ok(Ok(n)) if n > 0 => dec.push(&buf[..n]),
            other => panic!("no frame of id {msg_id} within {limit:?}: {other:?}"),
        }
    }
}

fn command(seq: u8) -> Frame {
    let msg = MavMessage::COMMAND_LONG(dialect::COMMAND_LONG_DATA {
        target_system: 1,
        target_component: 1,
        command: dialect::MavCmd::MAV_CMD_COMPONENT_ARM_DISARM,
        param1: 0.0,
        ..Default::default()
    });
    Frame::encode_v2(
        vtol_link::SystemId(255),
        vtol_link::ComponentId(0),
        seq,
        &msg,
    )
}

fn vehicle_heartbeat() -> Frame {
    let msg = MavMessage::HEARTBEAT(dialect::HEARTBEAT_DATA {
        mavtype: dialect::MavType::MAV_TYPE_VTOL_TAILSITTER_DUOROTOR,
        autopilot: dialect::MavAutopilot::MAV_AUTOPILOT_GENERIC,
        ..Default::default()
    });
    Frame::encode_v2(vtol_link::SystemId(1), vtol_link::ComponentId(1), 0, &msg)
}

fn ack() -> Frame {
    let msg = MavMessage::COMMAND_ACK(dialect::COMMAND_ACK_DATA {
        command: dialect::MavCmd::MAV_CMD_COMPONENT_ARM_DISARM,
        result: dialect::MavResult::MAV_RESULT_ACCEPTED,
        target_system: 255,
        target_component: 0,
        ..Default::default()
    });
    Frame::encode_v2(vtol_link::SystemId(1), vtol_link::ComponentId(1), 1, &msg)
}

/// The vehicle end of one vehicle link.
struct VehicleEnd {
    end: DuplexStream,
    dec: FrameDecoder,
}

async fn open_vehicle_link(router: &Routing, cancel: &CancellationToken) -> VehicleEnd {
    let (end, far) = tokio::io::duplex(1 << 16);
    spawn_stream_link(
        far,
        "vehicle",
        router.events(Side::Vehicle),
        LinkOptions::default(),
        cancel.clone(),
    );
    VehicleEnd {
        end,
        dec: FrameDecoder::new(),
    }
}

#[tokio::test]
async fn a_signed_session_survives_idle_and_outage() {
    let key = SigningKey::from_passphrase("session test");
    // 2026-11-23, moved by the test.
    let t0 = SystemTime::UNIX_EPOCH + Duration::from_secs(1_795_000_000);
    let elapsed_ms = Arc::new(AtomicU64::new(0));
    let now = {
        let e = Arc::clone(&elapsed_ms);
        move || t0 + Duration::from_millis(e.load(Ordering::Relaxed))
    };
    let clock: WallClock = Arc::new(now.clone());
    let advance = |s: u64| elapsed_ms.fetch_add(s * 1000, Ordering::Relaxed);

    let dir = tempfile::tempdir().unwrap();
    let daemon_signing = DaemonSigning::start(
        key.clone(),
        Some(dir.path().join("signing.toml")),
        true,
        clock,
    )
    .unwrap();
    let (router, handle) = Routing::new(None, Some(daemon_signing));
    let counters = handle.signing.expect("signing counters");
    let cancel = CancellationToken::new();

    let (mut client, far) = tokio::io::duplex(1 << 16);
    spawn_stream_link(
        far,
        "sign client",
        router.events_with(
            Side::Client,
            EndpointPolicy {
                trust: Trust::Sign,
                rate: None,
            },
        ),
        LinkOptions::default(),
        cancel.clone(),
    );
    let mut client_dec = FrameDecoder::new();
    let mut vehicle = Signing::new(key.clone(), 0, 0);
    let mut link = open_vehicle_link(&router, &cancel).await;
    let limit = Duration::from_secs(5);

    // One exchange: the vehicle's signed heartbeat (so the router knows where system 1 is), the
    // client's unsigned command signed by the router and accepted by the vehicle, the vehicle's
    // signed ACK verified by the router and delivered to the client.
    let mut seq = 0u8;
    let mut exchange = async |link: &mut VehicleEnd, vehicle: &mut Signing, what: &str| {
        let hb = vehicle.sign(&vehicle_heartbeat(), now()).unwrap();
        link.end.write_all(hb.as_bytes()).await.unwrap();
        // The heartbeat reaches the client: the router has learnt the vehicle link.
        let got = next_frame(&mut client, &mut client_dec, 0, limit).await;
        assert_eq!(got.as_bytes(), hb.as_bytes(), "{what}: heartbeat changed");
        client.write_all(command(seq).as_bytes()).await.unwrap();
        seq = seq.wrapping_add(1);
        let cmd = next_frame(&mut link.end, &mut link.dec, 76, limit).await;
        assert!(cmd.is_signed(), "{what}: command not signed by the daemon");
        let verdict = vehicle.verify(&cmd, now());
        assert!(
            matches!(verdict, Ok(Accepted::Signed { .. })),
            "{what}: the vehicle refused the command: {verdict:?}"
        );
        let reply = vehicle.sign(&ack(), now()).unwrap();
        link.end.write_all(reply.as_bytes()).await.unwrap();
        let got = next_frame(&mut client, &mut client_dec, 77, limit).await;
        let decoded = got.decode().unwrap();
        let MavMessage::COMMAND_ACK(a) = decoded else {
            panic!("{what}: not an ACK")
        };
        assert_eq!(a.command, dialect::MavCmd::MAV_CMD_COMPONENT_ARM_DISARM);
    };

    exchange(&mut link, &mut vehicle, "start").await;

    // Ten minutes without a frame either way.
    advance(600);
    exchange(&mut link, &mut vehicle, "after a 10-minute idle").await;

    // The vehicle link is cut for 90 s; the vehicle keeps its streams (a radio outage).
    drop(link);
    advance(90);
    let mut link = open_vehicle_link(&router, &cancel).await;
    exchange(&mut link, &mut vehicle, "after a 90 s outage").await;

    // Cut again for 90 s, and the vehicle restarts: it has forgotten every stream, and starts
    // from the timestamp it saved.
    drop(link);
    advance(90);
    let saved = vehicle.state(now()).timestamp;
    let mut vehicle = Signing::new(key, 0, saved);
    let mut link = open_vehicle_link(&router, &cancel).await;
    exchange(
        &mut link,
        &mut vehicle,
        "after an outage and a vehicle restart",
    )
    .await;

    let c = counters.snapshot();
    assert_eq!(c.refused(), 0, "the daemon refused vehicle frames: {c:?}");
    assert_eq!(c.verified, 8, "{c:?}");
    assert_eq!(c.signed, 4, "{c:?}");
    drop(link);
    cancel.cancel();
    router.close();
}

/// `vtol-gcs run --signing-passphrase …` with the embedded twin (also what the terminal UI
/// runs): the twin is keyed too, the daemon's own client (the UI's commands) is heard, the
/// twin's frames are verified and none is refused, and the timestamp is saved.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_keyed_daemon_commands_its_keyed_embedded_twin() {
    let dir = tempfile::tempdir().unwrap();
    let state_file = dir.path().join("signing.toml");
    let config = vtol_gcs::config::Config {
        serve: Vec::new(),
        log_dir: None,
        signing: Some(SigningKey::from_passphrase("embedded")),
        signing_state: Some(state_file.clone()),
        ..vtol_gcs::config::Config::default()
    };
    let cancel = CancellationToken::new();
    let mut tasks = tokio::task::JoinSet::new();
    let running = vtol_gcs::daemon::start(&config, &cancel, &mut tasks)
        .await
        .expect("daemon starts");
    assert!(state_file.exists(), "state saved at start");
    let client = running.client.clone();
    let limit = Duration::from_secs(20);
    client.wait_target(limit).await.expect("vehicle heard");
    tokio::time::timeout(limit, client.param_set("HOVER_ALT", 1.25))
        .await
        .expect("in time")
        .expect("the keyed twin took the daemon's signed PARAM_SET");
    tokio::time::timeout(limit, client.set_mode("QHOVER"))
        .await
        .expect("in time")
        .expect("the keyed twin took the daemon's signed mode change");
    let c = running.router.signing.as_ref().unwrap().snapshot();
    assert!(c.verified > 0 && c.signed > 0, "{c:?}");
    assert_eq!(c.refused(), 0, "{c:?}");
    cancel.cancel();
    while tasks.join_next().await.is_some() {}
    let saved = vtol_link::SigningState::load(&state_file).unwrap();
    assert!(saved.timestamp > 0);
}
