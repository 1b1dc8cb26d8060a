//! A link over any byte stream: TCP sockets, serial ports, `tokio::io::duplex` pipes.
//!
//! The reader feeds a [`FrameDecoder`] and reports frames; the writer drains the egress
//! queue, batching whatever is queued into one `write_all` (streams have no datagram
//! boundaries to preserve, and fewer syscalls matter at high telemetry rates).

use std::fmt::Display;
use std::future::Future;
use std::sync::Arc;

use tokio::io::{AsyncRead, AsyncReadExt, AsyncWrite, AsyncWriteExt};
use tokio::sync::mpsc;
use tokio::task::JoinHandle;
use tokio_util::sync::CancellationToken;

use super::{
    Backoff, Events, LinkEvent, LinkId, LinkOptions, LinkSender, LinkStats, emit, emit_down,
    emit_frames, sleep_or_cancel, take_batch,
};
use crate::decoder::FrameDecoder;
use crate::frame::Frame;

/// Upper bound of one batched write; more queued frames wait for the next write.
const MAX_BATCH_BYTES: usize = 64 * 1024;
/// Room reserved in the decoder's buffer before each read.
const READ_CHUNK_BYTES: usize = 8 * 1024;

/// Runs one stream link until EOF, an I/O error, the owner going away, or `cancel`.
///
/// Sends `Up` (with a fresh egress queue) first and `Down` last; returns the reason it ended.
/// `stats` may be shared across reconnects of the same link. Use this directly to keep one
/// [`LinkId`] across your own reconnect loop; otherwise see [`spawn_stream_link`].
/// Writes are never flushed, so pass an unbuffered stream (sockets, serial ports and
/// `tokio::io::duplex` are fine; a `BufWriter` is not).
pub async fn run_stream_link<S>(
    id: LinkId,
    peer: String,
    stream: S,
    stats: Arc<LinkStats>,
    events: &Events,
    opts: &LinkOptions,
    cancel: &CancellationToken,
) -> String
where
    S: AsyncRead + AsyncWrite + Send + 'static,
{
    let (tx, rx) = mpsc::channel(opts.queue_len.max(1));
    let up = LinkEvent::Up {
        id,
        peer: peer.clone(),
        tx: LinkSender::new(tx, stats.clone(), opts.accept.clone()),
    };
    tracing::debug!(%id, %peer, "link up");
    if !emit(events, up, cancel).await {
        return "shutdown".to_string();
    }
    let (rd, wr) = tokio::io::split(stream);
    let reason = tokio::select! {
        _ = cancel.cancelled() => "shutdown".to_string(),
        r = read_loop(id, rd, &stats, events, cancel) => r,
        r = write_loop(wr, rx, &stats) => r,
    };
    emit_down(events, id, reason.clone(), cancel).await;
    reason
}

/// Spawns a stream link with a new [`LinkId`] (e.g. one end of `tokio::io::duplex` for an
/// in-memory vehicle). The task ends when the stream does, or on `cancel`.
pub fn spawn_stream_link<S>(
    stream: S,
    peer: impl Into<String>,
    events: impl Into<Events>,
    opts: LinkOptions,
    cancel: CancellationToken,
) -> (LinkId, JoinHandle<()>)
where
    S: AsyncRead + AsyncWrite + Send + 'static,
{
    let id = LinkId::next();
    let peer = peer.into();
    let events = events.into();
    let task = tokio::spawn(async move {
        let stats = Arc::new(LinkStats::default());
        run_stream_link(id, peer, stream, stats, &events, &opts, &cancel).await;
    });
    (id, task)
}

async fn read_loop<R: AsyncRead>(
    id: LinkId,
    rd: R,
    stats: &LinkStats,
    events: &Events,
    cancel: &CancellationToken,
) -> String {
    tokio::pin!(rd);
    let mut decoder = FrameDecoder::new();
    let mut frames: Vec<(LinkId, Frame)> = Vec::new();
    loop {
        decoder.buffer_mut().reserve(READ_CHUNK_BYTES);
        match rd.read_buf(decoder.buffer_mut()).await {
            Ok(0) => {
                decoder.finish_with(|frame| frames.push((id, frame)));
                stats.add_decode(&decoder.take_stats());
                emit_frames(events, &mut frames, cancel).await;
                return "end of stream".to_string();
            }
            Ok(n) => stats.add_rx_bytes(n),
            Err(e) => return format!("read error: {e}"),
        }
        // The frames of one read go to the owner together.
        frames.extend(decoder.frames().map(|frame| (id, frame)));
        stats.add_decode(&decoder.take_stats());
        if !emit_frames(events, &mut frames, cancel).await {
            return "event receiver closed".to_string();
        }
    }
}

async fn write_loop<W: AsyncWrite>(
    wr: W,
    mut rx: mpsc::Receiver<Frame>,
    stats: &LinkStats,
) -> String {
    tokio::pin!(wr);
    let mut batch: Vec<u8> = Vec::with_capacity(MAX_BATCH_BYTES);
    loop {
        let Some(first) = rx.recv().await else {
            // The owner dropped every sender: keep receiving, just never send again.
            std::future::pending::<()>().await;
            unreachable!();
        };
        let frames = take_batch(&first, &mut rx, &mut batch, MAX_BATCH_BYTES);
        // No flush: on a serial port it is tcdrain(), which would block the runtime thread
        // until the UART has sent everything. Streams passed here must not buffer writes.
        if let Err(e) = wr.write_all(&batch).await {
            return format!("write error: {e}");
        }
        stats.add_tx(frames, batch.len());
    }
}

/// Keeps one stream link alive for as long as `cancel` allows: `open` makes the connection
/// (returning the stream and a peer description), the link runs until it ends, then `open` is
/// tried again with capped back-off. A connection that lasted resets the back-off; one that
/// dies at once (a server that accepts and closes) keeps doubling it, so an EOF can never turn
/// into a spin. The [`LinkId`] and the counters stay the same across reconnections. Used by the
/// TCP client and the serial port; `what` names the target in logs.
pub(crate) async fn run_reconnecting<S, E, F, Fut>(
    id: LinkId,
    what: &str,
    mut open: F,
    events: Events,
    opts: LinkOptions,
    cancel: CancellationToken,
) where
    S: AsyncRead + AsyncWrite + Send + 'static,
    E: Display,
    F: FnMut() -> Fut,
    Fut: Future<Output = Result<(S, String), E>>,
{
    let stats = Arc::new(LinkStats::default());
    let mut backoff = Backoff::new(&opts);
    let mut failures: u32 = 0;
    loop {
        let attempt = tokio::select! {
            _ = cancel.cancelled() => return,
            r = open() => r,
        };
        match attempt {
            Ok((stream, peer)) => {
                failures = 0;
                let started = tokio::time::Instant::now();
                let reason =
                    run_stream_link(id, peer, stream, stats.clone(), &events, &opts, &cancel).await;
                if cancel.is_cancelled() || events.is_closed() {
                    return;
                }
                tracing::info!(%id, "{what} lost ({reason}), reconnecting");
                if started.elapsed() >= backoff.max() {
                    backoff.reset();
                }
            }
            Err(e) => {
                failures += 1;
                if failures == 1 {
                    tracing::warn!(%id, "{what}: {e}; retrying");
                } else {
                    tracing::debug!(%id, failures, "{what}: {e}");
                }
            }
        }
        if !sleep_or_cancel(backoff.next_delay(), &cancel).await {
            return;
        }
    }
}
