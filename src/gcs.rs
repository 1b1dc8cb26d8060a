//! The daemon's own MAVLink identity: a HEARTBEAT at 1 Hz as a ground station (type GCS,
//! autopilot INVALID, so scripts never take it for the vehicle). Its traffic enters the router
//! through an in-memory byte link like any other client, so it is routed and logged the same way.

use std::time::Duration;

use tokio::io::{AsyncReadExt, AsyncWriteExt, DuplexStream};
use tokio_util::sync::CancellationToken;
use vtol_link::Frame;

/// Sends the heartbeat every second on `stream` until `cancel` fires. What arrives is read
/// and discarded, so the link never backs up.
pub async fn run(stream: DuplexStream, system_id: u8, component_id: u8, cancel: CancellationToken) {
    let (mut rd, mut wr) = tokio::io::split(stream);
    let mut tick = tokio::time::interval(Duration::from_secs(1));
    let mut seq: u8 = 0;
    let mut sink = vec![0u8; 4096];
    loop {
        tokio::select! {
            () = cancel.cancelled() => return,
            _ = tick.tick() => {
                let frame = Frame::encode_v2(system_id, component_id, seq, &vtol_link::gcs_heartbeat());
                seq = seq.wrapping_add(1);
                if wr.write_all(frame.as_bytes()).await.is_err() {
                    return;
                }
            }
            n = rd.read(&mut sink) => {
                if matches!(n, Ok(0) | Err(_)) {
                    return;
                }
            }
        }
    }
}
