//! TCP endpoints: `tcpin` (listener, every client is a link, re-accepts forever) and `tcp`
//! (client that reconnects with capped back-off and keeps its [`LinkId`]).
//!
//! The `mavlink` crate's tcpin accepts one client and drops the listener (PROTOCOL.md E.3);
//! here the listener lives for the endpoint's lifetime. TCP_NODELAY is set on every socket
//! because MAVLink frames are small and latency matters more than packet count.

use std::net::SocketAddr;
use std::sync::Arc;
use std::time::Duration;

use tokio::net::{TcpListener, TcpStream};
use tokio::task::JoinHandle;
use tokio_util::sync::CancellationToken;
use tokio_util::task::TaskTracker;

use super::stream::run_reconnecting;
use super::{
    Events, LinkError, LinkId, LinkOptions, LinkStats, SocketEndpoint, resolve, run_stream_link,
    sleep_or_cancel,
};

/// Pause after a failed accept (e.g. EMFILE) so it cannot become a busy loop.
const ACCEPT_ERROR_PAUSE: Duration = Duration::from_millis(100);

/// Binds a tcpin listener and spawns its accept loop.
pub(super) async fn spawn_tcpin(
    at: SocketEndpoint<'_>,
) -> Result<(SocketAddr, JoinHandle<()>), LinkError> {
    let url = at.url;
    let mut last = None;
    let mut listener = None;
    for &addr in &at.addrs {
        match TcpListener::bind(addr).await {
            Ok(l) => {
                listener = Some(l);
                break;
            }
            Err(e) => last = Some((addr, e)),
        }
    }
    let listener = match (listener, last) {
        (Some(l), _) => l,
        (None, Some((addr, source))) => {
            return Err(LinkError::Bind {
                url: url.to_string(),
                addr,
                source,
            });
        }
        (None, None) => {
            return Err(LinkError::NoAddress {
                host: at.host.to_string(),
            });
        }
    };
    let local = listener.local_addr().map_err(|source| LinkError::Io {
        url: url.to_string(),
        source,
    })?;
    tracing::info!(%url, %local, "tcpin listening");
    let task = tokio::spawn(tcpin_task(listener, at.events, at.opts, at.cancel));
    Ok((local, task))
}

async fn tcpin_task(
    listener: TcpListener,
    events: Events,
    opts: LinkOptions,
    cancel: CancellationToken,
) {
    let clients = TaskTracker::new();
    loop {
        let accepted = tokio::select! {
            _ = cancel.cancelled() => break,
            r = listener.accept() => r,
        };
        let (stream, peer) = match accepted {
            Ok(x) => x,
            Err(e) => {
                tracing::warn!("tcpin accept error: {e}");
                if !sleep_or_cancel(ACCEPT_ERROR_PAUSE, &cancel).await {
                    break;
                }
                continue;
            }
        };
        if let Err(e) = stream.set_nodelay(true) {
            tracing::debug!(%peer, "cannot set TCP_NODELAY: {e}");
        }
        let (events, opts, cancel) = (events.clone(), opts.clone(), cancel.clone());
        clients.spawn(async move {
            let id = LinkId::next();
            let stats = Arc::new(LinkStats::default());
            run_stream_link(
                id,
                format!("tcp {peer}"),
                stream,
                stats,
                &events,
                &opts,
                &cancel,
            )
            .await;
        });
    }
    // Stop accepting before waiting for the clients' Down events.
    drop(listener);
    clients.close();
    clients.wait().await;
}

/// Spawns a reconnecting TCP client link.
pub(super) fn spawn_tcp_client(
    host: String,
    port: u16,
    events: Events,
    opts: LinkOptions,
    cancel: CancellationToken,
) -> (LinkId, JoinHandle<()>) {
    let id = LinkId::next();
    let task = tokio::spawn(tcp_client_task(id, host, port, events, opts, cancel));
    (id, task)
}

async fn connect(host: &str, port: u16) -> Result<TcpStream, String> {
    let addrs = resolve(host, port).await.map_err(|e| e.to_string())?;
    let mut err = String::new();
    for addr in addrs {
        match TcpStream::connect(addr).await {
            Ok(s) => return Ok(s),
            Err(e) => err = format!("connect {addr}: {e}"),
        }
    }
    Err(err)
}

async fn tcp_client_task(
    id: LinkId,
    host: String,
    port: u16,
    events: Events,
    opts: LinkOptions,
    cancel: CancellationToken,
) {
    let what = format!("tcp {host}:{port}");
    let open = || async {
        let stream = connect(&host, port).await?;
        let _ = stream.set_nodelay(true);
        let peer = stream
            .peer_addr()
            .map_or_else(|_| format!("tcp {host}:{port}"), |a| format!("tcp {a}"));
        Ok::<_, String>((stream, peer))
    };
    run_reconnecting(id, &what, open, events, opts, cancel).await;
}
