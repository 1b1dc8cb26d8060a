//! Serial link (8N1, no flow control) through tokio-serial, reopened with capped back-off
//! when the device errors or vanishes (USB radio unplugged, pty closed). The [`LinkId`] stays
//! the same across reopenings. The back-off is capped at [`SERIAL_REOPEN_MAX`], well below the
//! other links' cap: trying to open a missing device costs one failed `open`, and a radio
//! plugged back in is then read again within a quarter of a second.

use tokio::task::JoinHandle;
use tokio_serial::{DataBits, FlowControl, Parity, SerialPortBuilderExt, SerialStream, StopBits};
use tokio_util::sync::CancellationToken;

use super::stream::run_reconnecting;
use super::{Events, LinkId, LinkOptions};

/// Longest wait between two attempts to open a serial device.
pub(crate) const SERIAL_REOPEN_MAX: std::time::Duration = std::time::Duration::from_millis(250);

/// Spawns a serial link that keeps reopening the device.
pub(super) fn spawn_serial(
    device: String,
    baud: u32,
    events: Events,
    opts: LinkOptions,
    cancel: CancellationToken,
) -> (LinkId, JoinHandle<()>) {
    let id = LinkId::next();
    let opts = LinkOptions {
        reconnect_max: opts.reconnect_max.min(SERIAL_REOPEN_MAX),
        ..opts
    };
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
    events: Events,
    opts: LinkOptions,
    cancel: CancellationToken,
) {
    let what = format!("serial {device}@{baud}");
    let peer = what.clone();
    let open_port = || {
        let r = open(&device, baud).map(|port| (port, peer.clone()));
        std::future::ready(r)
    };
    run_reconnecting(id, &what, open_port, events, opts, cancel).await;
}
