//! What the router's tests share: links on in-memory byte streams, routed inline as the daemon
//! routes them.

use tokio::io::DuplexStream;
use tokio::task::JoinHandle;
use tokio_util::sync::CancellationToken;
use vtol_gcs::router::InlineRouter;
use vtol_gcs::tap::Side;
use vtol_link::{LinkId, LinkOptions, spawn_stream_link};

/// A link of `side` named `peer` on an in-memory byte stream, its frames routed by `router`
/// from its own task: the test's end of the stream, the link's id and its task.
pub fn stream_link(
    router: &InlineRouter,
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
