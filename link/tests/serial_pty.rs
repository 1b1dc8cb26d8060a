//! Serial links over a pseudo-terminal pair made by `socat`: frames both ways, then the device
//! vanishes (socat stops) and comes back, and both links reopen with the same LinkId.

mod common;

use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::time::Duration;

use common::{WAIT, hb, wait_down, wait_frame, wait_up};
use tokio::sync::mpsc;
use tokio::time::timeout;
use tokio_util::sync::CancellationToken;
use vtol_link::{LinkError, LinkOptions, LinkUrl, spawn_endpoint};

fn have_socat() -> bool {
    Command::new("socat")
        .arg("-V")
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .status()
        .is_ok_and(|s| s.success())
}

/// Starts socat with two linked ptys and waits until both symlinks exist.
async fn start_socat(a: &Path, b: &Path) -> Child {
    let child = Command::new("socat")
        .arg(format!("pty,raw,echo=0,link={}", a.display()))
        .arg(format!("pty,raw,echo=0,link={}", b.display()))
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .spawn()
        .expect("spawn socat");
    // Polling an external process's side effect; bounded by WAIT.
    timeout(WAIT, async {
        while !(a.exists() && b.exists()) {
            tokio::time::sleep(Duration::from_millis(10)).await;
        }
    })
    .await
    .expect("socat did not create the ptys");
    child
}

/// Stops our socat with SIGTERM (so it removes its links), then clears any leftovers so a
/// reopening link cannot hit a stale symlink.
fn stop_socat(mut child: Child, links: &[&PathBuf]) {
    let _ = Command::new("kill")
        .arg("-TERM")
        .arg(child.id().to_string())
        .status();
    let _ = child.wait();
    for l in links {
        let _ = std::fs::remove_file(l);
    }
}

#[tokio::test]
async fn serial_over_pty_pair_reopens_after_device_vanishes() {
    if !have_socat() {
        eprintln!("socat not installed (apt-get install -y socat); skipping the pty test");
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    let (pa, pb) = (dir.path().join("ttyA"), dir.path().join("ttyB"));
    let socat = start_socat(&pa, &pb).await;

    let opts = LinkOptions {
        reconnect_min: Duration::from_millis(20),
        reconnect_max: Duration::from_millis(200),
        ..Default::default()
    };
    let cancel = CancellationToken::new();
    let (ta, mut ea) = mpsc::channel(64);
    let (tb, mut eb) = mpsc::channel(64);
    let url_a: LinkUrl = format!("serial:{}:57600", pa.display()).parse().unwrap();
    let url_b: LinkUrl = format!("serial:{}", pb.display()).parse().unwrap();
    let ep_a = spawn_endpoint(&url_a, ta, opts.clone(), cancel.clone())
        .await
        .unwrap();
    let ep_b = spawn_endpoint(&url_b, tb, opts, cancel.clone())
        .await
        .unwrap();
    let (id_a, peer_a, tx_a) = wait_up(&mut ea).await;
    let (id_b, _, tx_b) = wait_up(&mut eb).await;
    assert_eq!(Some(id_a), ep_a.link_id());
    assert_eq!(Some(id_b), ep_b.link_id());
    assert!(peer_a.contains("ttyA@57600"), "{peer_a}");

    for seq in 0..20 {
        tx_a.try_send(hb(1, seq)).unwrap();
    }
    for seq in 0..20 {
        assert_eq!(wait_frame(&mut eb, id_b).await, hb(1, seq));
    }
    tx_b.try_send(hb(2, 1)).unwrap();
    assert_eq!(wait_frame(&mut ea, id_a).await, hb(2, 1));

    // The device vanishes: both links go down and keep retrying.
    stop_socat(socat, &[&pa, &pb]);
    wait_down(&mut ea, id_a).await;
    wait_down(&mut eb, id_b).await;

    // It comes back: same LinkIds, frames flow again.
    let socat = start_socat(&pa, &pb).await;
    let (id_a2, _, tx_a) = wait_up(&mut ea).await;
    let (id_b2, _, _) = wait_up(&mut eb).await;
    assert_eq!((id_a2, id_b2), (id_a, id_b));
    tx_a.try_send(hb(1, 99)).unwrap();
    assert_eq!(wait_frame(&mut eb, id_b).await, hb(1, 99));

    cancel.cancel();
    timeout(WAIT, ep_a.join()).await.unwrap();
    timeout(WAIT, ep_b.join()).await.unwrap();
    stop_socat(socat, &[&pa, &pb]);
}

#[tokio::test]
async fn a_missing_device_is_an_error_unless_waiting_was_asked_for() {
    let dir = tempfile::tempdir().unwrap();
    let (pa, pb) = (dir.path().join("ttyA"), dir.path().join("ttyB"));
    let cancel = CancellationToken::new();
    let url: LinkUrl = format!("serial:{}:57600", pa.display()).parse().unwrap();
    let (ta, mut ea) = mpsc::channel(64);
    let err = spawn_endpoint(&url, ta.clone(), LinkOptions::default(), cancel.clone())
        .await
        .unwrap_err();
    assert!(matches!(err, LinkError::NoDevice { .. }), "{err}");
    assert!(err.to_string().contains("ttyA"), "{err}");

    if !have_socat() {
        eprintln!("socat not installed (apt-get install -y socat); skipping the wait half");
        return;
    }
    let opts = LinkOptions {
        wait_for_device: true,
        reconnect_min: Duration::from_millis(20),
        reconnect_max: Duration::from_millis(200),
        ..Default::default()
    };
    let ep = spawn_endpoint(&url, ta, opts, cancel.clone())
        .await
        .unwrap();
    // The device appears after the endpoint started: the link comes up on it.
    let socat = start_socat(&pa, &pb).await;
    let (id, peer, _) = wait_up(&mut ea).await;
    assert_eq!(Some(id), ep.link_id());
    assert!(peer.contains("ttyA"), "{peer}");
    cancel.cancel();
    timeout(WAIT, ep.join()).await.unwrap();
    stop_socat(socat, &[&pa, &pb]);
}
