//! The `zenoh:` link type on a real Zenoh session (TCP on loopback, no multicast scouting):
//! a vehicle end and a ground end of one fleet in one process.
#![cfg(feature = "zenoh")]

mod common;

use common::{hb, wait_down, wait_frame, wait_up};
use tokio::sync::mpsc;
use tokio_util::sync::CancellationToken;
use vtol_link::signing::sign_frame;
use vtol_link::{
    LinkEvent, LinkOptions, LinkUrl, SigningKey, ZenohMode, ZenohOptions, ZenohRole, spawn_endpoint,
};

fn options(role: ZenohRole, port: u16) -> LinkOptions {
    LinkOptions {
        zenoh: ZenohOptions {
            mode: ZenohMode::Peer,
            listen: vec![format!("tcp/127.0.0.1:{port}")],
            role,
            ..ZenohOptions::default()
        },
        ..LinkOptions::default()
    }
}

fn free_port() -> u16 {
    std::net::TcpListener::bind("127.0.0.1:0")
        .unwrap()
        .local_addr()
        .unwrap()
        .port()
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn frames_cross_the_fleet_byte_for_byte_and_liveliness_ends_the_link() {
    let port = free_port();
    let cancel = CancellationToken::new();
    let vehicle_cancel = cancel.child_token();
    let (vtx, mut vrx) = mpsc::channel(256);
    let (gtx, mut grx) = mpsc::channel(256);
    let url = |s: &str| s.parse::<LinkUrl>().unwrap();

    let ground = spawn_endpoint(
        &url("zenoh:t/*"),
        gtx,
        options(ZenohRole::Ground, port),
        cancel.clone(),
    )
    .await
    .expect("ground end");
    let vehicle = spawn_endpoint(
        &url("zenoh:t/v7"),
        vtx,
        options(ZenohRole::Vehicle, port),
        vehicle_cancel.clone(),
    )
    .await
    .expect("vehicle end");
    let (vid, vpeer, vsend) = wait_up(&mut vrx).await;
    assert_eq!(vehicle.link_id(), Some(vid));
    assert_eq!(vpeer, "zenoh t/v7");
    // The ground end makes the vehicle a link of its own once its token shows.
    let (gid, gpeer, gsend) = wait_up(&mut grx).await;
    assert_eq!(gpeer, "zenoh t/v7");

    // What the vehicle sends reaches the ground unchanged: sequence numbers, a signature.
    let key = SigningKey::from_passphrase("fleet");
    let signed = sign_frame(&key, &hb(7, 42), 3, 1_000_000).unwrap();
    let sent = [hb(7, 40), hb(7, 41), signed];
    for f in &sent {
        vsend.try_send(f.clone()).unwrap();
    }
    for f in &sent {
        let got = wait_frame(&mut grx, gid).await;
        assert_eq!(got.as_bytes(), f.as_bytes());
    }
    // And what the ground sends the vehicle reaches it.
    gsend.try_send(hb(255, 9)).unwrap();
    assert_eq!(
        wait_frame(&mut vrx, vid).await.as_bytes(),
        hb(255, 9).as_bytes()
    );

    // The vehicle's end stops: its token goes, and with it the ground's link.
    vehicle_cancel.cancel();
    vehicle.join().await;
    let why = wait_down(&mut grx, gid).await;
    assert!(why.contains("left the fleet"), "{why}");
    cancel.cancel();
    ground.join().await;
    // Nothing else came up meanwhile.
    while let Ok(ev) = grx.try_recv() {
        assert!(!matches!(ev, LinkEvent::Up { .. }), "{ev:?}");
    }
}

#[tokio::test]
async fn a_vehicle_end_must_name_its_vehicle() {
    let (tx, _rx) = mpsc::channel(8);
    let e = spawn_endpoint(
        &"zenoh:t/*".parse::<LinkUrl>().unwrap(),
        tx,
        options(ZenohRole::Vehicle, free_port()),
        CancellationToken::new(),
    )
    .await
    .unwrap_err();
    assert!(e.to_string().contains("names no vehicle"), "{e}");
}
