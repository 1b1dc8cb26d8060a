//! Fleets over Zenoh: `zenoh:FLEET/VEHICLE` and `zenoh:FLEET/*` links.
//!
//! Frames travel raw (sequence numbers and signatures untouched), one or more whole frames per
//! publication, on two keys per vehicle:
//! - `vtol/FLEET/VEHICLE/from_vehicle`: what the vehicle sends;
//! - `vtol/FLEET/VEHICLE/to_vehicle`: what the fleet sends to it.
//!
//! and a liveliness token on `vtol/FLEET/VEHICLE` says that the vehicle's end is up.
//!
//! Two roles ([`ZenohRole`]):
//! - the *vehicle* end (a daemon's `--serve zenoh:FLEET/VEHICLE`) is one link: what the router
//!   sends it is published on `from_vehicle`, what arrives on `to_vehicle` is its ingress, and
//!   it holds the vehicle's liveliness token;
//! - the *ground* end (a daemon's `--vehicle zenoh:FLEET/*`, or one vehicle) makes one link per
//!   vehicle: up when the vehicle's token appears (or its first frames arrive), down when the
//!   token goes away (its daemon stopped or its session was lost), and not up again until a
//!   new token appears; its egress is published on that vehicle's `to_vehicle`.
//!
//! One Zenoh session per process and set of [`ZenohOptions`] carries every endpoint.

mod ground;

use std::sync::{Arc, OnceLock};

use tokio::sync::{Mutex, mpsc};
use tokio::task::JoinHandle;
use tokio_util::sync::CancellationToken;
use zenoh::Session;
use zenoh::qos::CongestionControl;
use zenoh::sample::Sample;

use super::{
    Events, LinkError, LinkEvent, LinkId, LinkOptions, LinkSender, LinkStats, ZenohMode,
    ZenohOptions, ZenohRole, emit, emit_down, emit_frames, take_batch,
};
use crate::decoder::FrameDecoder;
use crate::frame::Frame;

/// Upper bound of one publication: queued frames beyond it wait for the next one.
const MAX_BATCH_BYTES: usize = 16 * 1024;
/// Samples a subscriber holds for its task before Zenoh waits (backpressure, not loss).
pub(crate) const SUBSCRIBER_DEPTH: usize = 4096;

/// The key of what a vehicle sends.
pub fn from_vehicle_key(fleet: &str, vehicle: &str) -> String {
    format!("vtol/{fleet}/{vehicle}/from_vehicle")
}

/// The key of what the fleet sends to a vehicle.
pub fn to_vehicle_key(fleet: &str, vehicle: &str) -> String {
    format!("vtol/{fleet}/{vehicle}/to_vehicle")
}

/// The key of a vehicle's liveliness token.
pub fn liveliness_key(fleet: &str, vehicle: &str) -> String {
    format!("vtol/{fleet}/{vehicle}")
}

pub(crate) fn zerr(what: &str, e: impl std::fmt::Display) -> LinkError {
    LinkError::Zenoh(format!("{what}: {e}"))
}

/// The Zenoh configuration [`ZenohOptions`] describe. With explicit endpoints (connect or
/// listen) multicast scouting is off: the session talks to exactly what it was given.
pub fn zenoh_config(opts: &ZenohOptions) -> Result<zenoh::Config, LinkError> {
    let mut c = zenoh::Config::default();
    let mode = match opts.mode {
        ZenohMode::Peer => "peer",
        ZenohMode::Client => "client",
        ZenohMode::Router => "router",
    };
    let json = |v: &[String]| {
        let quoted: Vec<String> = v.iter().map(|e| format!("{e:?}")).collect();
        format!("[{}]", quoted.join(","))
    };
    c.insert_json5("mode", &format!("{mode:?}"))
        .map_err(|e| zerr("Zenoh mode", e))?;
    if !opts.connect.is_empty() {
        c.insert_json5("connect/endpoints", &json(&opts.connect))
            .map_err(|e| zerr("--zenoh-connect", e))?;
    }
    if !opts.listen.is_empty() {
        c.insert_json5("listen/endpoints", &json(&opts.listen))
            .map_err(|e| zerr("--zenoh-listen", e))?;
    }
    if !opts.connect.is_empty() || !opts.listen.is_empty() {
        c.insert_json5("scouting/multicast/enabled", "false")
            .map_err(|e| zerr("Zenoh scouting", e))?;
    }
    for (key, value) in LIVENESS {
        c.insert_json5(key, value)
            .map_err(|e| zerr("Zenoh liveness settings", e))?;
    }
    Ok(c)
}

/// How quickly a session notices that its peer is gone and how eagerly it comes back, set on
/// every session (an endpoint's own `#retry_period_init_ms=...` still overrides the retries).
/// Zenoh's defaults (a 10 s lease, retries every 1-4 s, a 10 s open timeout) bring a fleet
/// back 2-4 s after a partition that drops packets silently; these bring it back within about
/// 1 s of the heal (docs/network.md, "Zenoh partitions"):
/// - a 3 s lease with 4 keep-alives in it: a session silent for 3 s is closed (its liveliness
///   tokens go, so the ground shows the vehicle's link down), and an idle link sends a
///   keep-alive every 0.75 s (a 3-byte message in one TCP segment, about 60 B/s each way on
///   Ethernet/IP; none while frames flow, as any message counts);
/// - a 1.5 s open timeout: a connect that a silent partition holds in SYN retransmissions is
///   abandoned after the first retransmission (at 1 s) instead of 10 s later, so that a SYN
///   goes out at least once a second (and a session over a link with up to 0.5 s round trips,
///   three of which an open takes, still opens);
/// - retries 0.25 s apart, doubling to at most 0.5 s: one small TCP SYN each.
const LIVENESS: [(&str, &str); 4] = [
    ("transport/link/tx/lease", "3000"),
    ("transport/link/tx/keep_alive", "4"),
    ("transport/unicast/open_timeout", "1500"),
    (
        "connect/retry",
        "{period_init_ms: 250, period_max_ms: 500, period_increase_factor: 2}",
    ),
];

/// The process's session for these options, opened on first use.
pub async fn session(opts: &ZenohOptions) -> Result<Session, LinkError> {
    static SESSIONS: OnceLock<Mutex<Vec<(ZenohOptions, Session)>>> = OnceLock::new();
    let key = ZenohOptions {
        role: ZenohRole::default(),
        ..opts.clone()
    };
    let mut all = SESSIONS.get_or_init(|| Mutex::new(Vec::new())).lock().await;
    if let Some((_, s)) = all.iter().find(|(k, s)| *k == key && !s.is_closed()) {
        return Ok(s.clone());
    }
    let config = zenoh_config(&key)?;
    let s = zenoh::open(config)
        .await
        .map_err(|e| zerr("cannot open the Zenoh session", e))?;
    all.retain(|(_, s)| !s.is_closed());
    all.push((key, s.clone()));
    Ok(s)
}

/// Opens a `zenoh:` endpoint in the role `opts.zenoh.role` gives.
pub(crate) async fn spawn_zenoh(
    fleet: &str,
    vehicle: Option<&str>,
    events: Events,
    opts: LinkOptions,
    cancel: CancellationToken,
) -> Result<(Option<LinkId>, JoinHandle<()>), LinkError> {
    if opts.zenoh.role == ZenohRole::Vehicle && vehicle.is_none() {
        return Err(LinkError::Zenoh(format!(
            "zenoh:{fleet}/* names no vehicle: the vehicle's end of a fleet is \
             zenoh:{fleet}/VEHICLE (the ground end may take zenoh:{fleet}/*)"
        )));
    }
    let session = session(&opts.zenoh).await?;
    match (opts.zenoh.role, vehicle) {
        (ZenohRole::Vehicle, None) => unreachable!("refused above"),
        (ZenohRole::Vehicle, Some(v)) => {
            let id = LinkId::next();
            let task = spawn_vehicle_end(session, fleet, v, id, events, opts, cancel).await?;
            Ok((Some(id), task))
        }
        (ZenohRole::Ground, v) => {
            let task = ground::spawn_ground_end(session, fleet, v, events, opts, cancel).await?;
            Ok((None, task))
        }
    }
}

/// Publishes what its queue receives on `key`, several whole frames per publication when
/// several are queued.
pub(crate) async fn publish_loop(
    session: Session,
    key: String,
    mut rx: mpsc::Receiver<Frame>,
    stats: Arc<LinkStats>,
) -> String {
    let publisher = match session
        .declare_publisher(key.clone())
        .congestion_control(CongestionControl::Block)
        .await
    {
        Ok(p) => p,
        Err(e) => return format!("cannot publish on {key}: {e}"),
    };
    let mut batch: Vec<u8> = Vec::with_capacity(MAX_BATCH_BYTES);
    while let Some(first) = rx.recv().await {
        let frames = take_batch(&first, &mut rx, &mut batch, MAX_BATCH_BYTES);
        let n = batch.len();
        match publisher.put(std::mem::take(&mut batch)).await {
            Ok(()) => stats.add_tx(frames, n),
            Err(e) => {
                stats.add_tx_error();
                tracing::debug!(%key, "publication failed: {e}");
            }
        }
    }
    "egress closed".to_string()
}

/// Decodes one sample's frames (whole frames, one or more) for `id`.
pub(crate) fn decode_sample(
    id: LinkId,
    sample: &Sample,
    decoder: &mut FrameDecoder,
    stats: &LinkStats,
    out: &mut Vec<(LinkId, Frame)>,
) {
    let bytes = sample.payload().to_bytes();
    stats.add_rx_bytes(bytes.len());
    // A publication holds whole frames: what is left is garbage, not the start of the next.
    decoder.push_final_with(&bytes, |f| out.push((id, f)));
    stats.add_decode(&decoder.take_stats());
}

async fn spawn_vehicle_end(
    session: Session,
    fleet: &str,
    vehicle: &str,
    id: LinkId,
    events: Events,
    opts: LinkOptions,
    cancel: CancellationToken,
) -> Result<JoinHandle<()>, LinkError> {
    let to_key = to_vehicle_key(fleet, vehicle);
    let subscriber = session
        .declare_subscriber(to_key.clone())
        .with(zenoh::handlers::FifoChannel::new(SUBSCRIBER_DEPTH))
        .await
        .map_err(|e| zerr(&format!("cannot subscribe to {to_key}"), e))?;
    let live_key = liveliness_key(fleet, vehicle);
    let token = session
        .liveliness()
        .declare_token(live_key.clone())
        .await
        .map_err(|e| {
            zerr(
                &format!("cannot declare the liveliness token {live_key}"),
                e,
            )
        })?;
    let from_key = from_vehicle_key(fleet, vehicle);
    let peer = format!("zenoh {fleet}/{vehicle}");
    Ok(tokio::spawn(async move {
        let _token = token;
        let stats = Arc::new(LinkStats::default());
        let (tx, rx) = mpsc::channel(opts.queue_len.max(1));
        let up = LinkEvent::Up {
            id,
            peer: peer.clone(),
            tx: LinkSender::new(tx, stats.clone(), opts.accept.clone()),
        };
        if !emit(&events, up, &cancel).await {
            return;
        }
        let writer = publish_loop(session, from_key, rx, stats.clone());
        let reader = async {
            let mut decoder = FrameDecoder::new();
            let mut frames = Vec::new();
            while let Ok(sample) = subscriber.recv_async().await {
                decode_sample(id, &sample, &mut decoder, &stats, &mut frames);
                if !emit_frames(&events, &mut frames, &cancel).await {
                    return "event receiver closed".to_string();
                }
            }
            "Zenoh session closed".to_string()
        };
        let reason = tokio::select! {
            _ = cancel.cancelled() => "shutdown".to_string(),
            r = writer => r,
            r = reader => r,
        };
        emit_down(&events, id, reason, &cancel).await;
    }))
}

/// The vehicle name in `vtol/FLEET/VEHICLE[/...]`, when the key has `chunks` chunks.
pub(crate) fn vehicle_of(key: &str, chunks: usize) -> Option<&str> {
    let mut it = key.split('/');
    let v = it.nth(2)?;
    (it.count() + 3 == chunks + 1).then_some(v)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn vehicle_names_come_from_their_keys() {
        assert_eq!(vehicle_of("vtol/test/v1", 2), Some("v1"));
        assert_eq!(vehicle_of("vtol/test/v1/from_vehicle", 3), Some("v1"));
        assert_eq!(vehicle_of("vtol/test/v1/from_vehicle", 2), None);
        assert_eq!(vehicle_of("vtol/test", 2), None);
    }

    #[test]
    fn explicit_endpoints_turn_multicast_scouting_off() {
        let opts = ZenohOptions {
            mode: ZenohMode::Client,
            connect: vec!["tcp/127.0.0.1:7447".into()],
            ..ZenohOptions::default()
        };
        let c = zenoh_config(&opts).unwrap();
        assert_eq!(c.get_json("mode").unwrap(), "\"client\"");
        assert_eq!(c.get_json("scouting/multicast/enabled").unwrap(), "false");
        let bad = ZenohOptions {
            listen: vec!["not an endpoint".into()],
            ..ZenohOptions::default()
        };
        assert!(zenoh_config(&bad).is_err());
    }

    #[test]
    fn every_session_notices_a_lost_peer_quickly_and_retries_often() {
        let c = zenoh_config(&ZenohOptions::default()).unwrap();
        assert_eq!(c.get_json("transport/link/tx/lease").unwrap(), "3000");
        assert_eq!(
            c.get_json("transport/unicast/open_timeout").unwrap(),
            "1500"
        );
        let retry = c.get_json("connect/retry").unwrap();
        assert!(retry.contains("\"period_max_ms\":500"), "{retry}");
    }
}
