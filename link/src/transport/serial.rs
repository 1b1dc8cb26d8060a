//! Serial link (8N1, no flow control) through tokio-serial, reopened with capped back-off
//! when the device errors or vanishes (USB radio unplugged, pty closed). The [`LinkId`] stays
//! the same across reopenings.

use std::sync::Arc;

use tokio::sync::mpsc;
use tokio::task::JoinHandle;
use tokio::time::Instant;
use tokio_serial::{DataBits, FlowControl, Parity, SerialPortBuilderExt, SerialStream, StopBits};
use tokio_util::sync::CancellationToken;

use super::{Backoff, LinkEvent, LinkId, LinkOptions, LinkStats, run_stream_link, sleep_or_cancel};

/// Spawns a serial link that keeps reopening the device.
pub(super) fn spawn_serial(
    device: String,
    baud: u32,
    events: mpsc::Sender<LinkEvent>,
    opts: LinkOptions,
    cancel: CancellationToken,
) -> (LinkId, JoinHandle<()>) {
    let id = LinkId::next();
    let task = tokio::spawn(serial_task(id, device, baud, events, opts, cancel));
    (id, task)
}

fn open(device: &str, baud: u32) -> tokio_serial::Result<SerialStream> {
    let mut port = tokio_serial::new(device, baud)
        .data_bits(DataBits::Eight)
        .parity(Parity::None)
        .stop_bits(StopBits::One)
        .flow_control(FlowControl::None)
        .open_native_async()?;
    // Exclusive mode (TIOCEXCL) would stop a second reader such as a sniffer; not needed.
    let _ = port.set_exclusive(false);
    Ok(port)
}

async fn serial_task(
    id: LinkId,
    device: String,
    baud: u32,
    events: mpsc::Sender<LinkEvent>,
    opts: LinkOptions,
    cancel: CancellationToken,
) {
    let stats = Arc::new(LinkStats::default());
    let mut backoff = Backoff::new(&opts);
    let mut failures: u32 = 0;
    loop {
        if cancel.is_cancelled() {
            return;
        }
        match open(&device, baud) {
            Ok(port) => {
                failures = 0;
                let started = Instant::now();
                let reason = run_stream_link(
                    id,
                    format!("serial {device}@{baud}"),
                    port,
                    stats.clone(),
                    &events,
                    &opts,
                    &cancel,
                )
                .await;
                if cancel.is_cancelled() || events.is_closed() {
                    return;
                }
                tracing::info!(%id, "serial {device} lost ({reason}), reopening");
                if started.elapsed() >= backoff.max() {
                    backoff.reset();
                }
            }
            Err(e) => {
                failures += 1;
                if failures == 1 {
                    tracing::warn!(%id, "cannot open serial {device}: {e}; retrying");
                } else {
                    tracing::debug!(%id, failures, "cannot open serial {device}: {e}");
                }
            }
        }
        if !sleep_or_cancel(backoff.next_delay(), &cancel).await {
            return;
        }
    }
}
