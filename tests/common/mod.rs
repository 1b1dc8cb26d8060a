//! What the router's tests share: links on in-memory byte streams, routed inline as the daemon
//! routes them.

use std::path::PathBuf;
use std::time::Duration;

use tempfile::TempDir;
use tokio::io::{AsyncReadExt, DuplexStream};
use tokio::sync::watch;
use tokio::task::JoinHandle;
use tokio_util::sync::CancellationToken;
use vtol_gcs::daemon::Routing;
use vtol_gcs::links::{LinkInfo, RouterHandle, Side};
use vtol_gcs::tlog::TlogHandle;
use vtol_link::{Frame, FrameDecoder, LinkId, LinkOptions, spawn_stream_link};

/// A link of `side` named `peer` on an in-memory byte stream, its frames routed by `router`
/// from its own task: the test's end of the stream, the link's id and its task.
pub fn stream_link(
    router: &Routing,
    side: Side,
    peer: &str,
    cancel: &CancellationToken,
) -> (DuplexStream, LinkId, JoinHandle<()>) {
    let (end, far) = tokio::io::duplex(1 << 16);
    let (id, task) = spawn_stream_link(
        far,
        peer.to_owned(),
        router.events(side),
        LinkOptions::default(),
        cancel.clone(),
    );
    (end, id, task)
}

/// A router as the daemon's, writing a tlog in a fresh temporary folder: the folder (kept alive
/// by the caller), the tlog's path, the router routing inline and its handle.
pub fn logged_router() -> (TempDir, PathBuf, Routing, RouterHandle) {
    let dir = tempfile::tempdir().unwrap();
    let tlog = TlogHandle::start(dir.path(), 4096).unwrap();
    let tlog_path = tlog.path.clone();
    let (router, handle) = Routing::new(Some(tlog), None);
    (dir, tlog_path, router, handle)
}

/// Reads frames from `end` until `stop(frames)` holds or `limit` passes.
pub async fn read_until(
    end: &mut DuplexStream,
    limit: Duration,
    stop: impl Fn(&[Frame]) -> bool,
) -> Vec<Frame> {
    let mut dec = FrameDecoder::new();
    let mut got = Vec::new();
    let mut buf = [0u8; 4096];
    let deadline = tokio::time::Instant::now() + limit;
    while !stop(&got) {
        match tokio::time::timeout_at(deadline, end.read(&mut buf)).await {
            Ok(Ok(k)) if k > 0 => {
                dec.push(&buf[..k]);
                got.extend(dec.frames());
            }
            _ => break,
        }
    }
    got
}

/// Waits (5 s at most) until the router lists `n` links; `what` names the wait in the panic.
pub async fn wait_links(links: &mut watch::Receiver<Vec<LinkInfo>>, n: usize, what: &str) {
    tokio::time::timeout(Duration::from_secs(5), links.wait_for(|l| l.len() == n))
        .await
        .unwrap_or_else(|_| panic!("timed out waiting for {what}"))
        .expect("router running");
}
