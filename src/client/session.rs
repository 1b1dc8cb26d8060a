//! The client's link owner: the one task that holds the ground station's identity and
//! sequence counter, writes every outgoing frame, decodes the few message types the client's
//! machines read, finds the vehicle, and sends the GCS heartbeat while an operator is present.
//!
//! It runs over any vtol-link transport: the links of an endpoint opened from a URL (a vehicle,
//! or a daemon's serve port), or, inside the daemon, the in-memory own-traffic link.
//!
//! With a key (a client on its own link) it signs every frame it sends and reads only frames
//! that pass the signing rules (the same `DaemonSigning` the daemon's router uses; the signing
//! state is saved when the session ends). Inside the daemon it has no key: the router signs
//! and verifies for it.

use std::collections::HashMap;
use std::sync::Arc;
use std::sync::atomic::{AtomicUsize, Ordering};
use std::time::Duration;

use tokio::sync::{broadcast, mpsc, watch};
use tokio_util::sync::CancellationToken;
use vtol_link::dialect::{MavAutopilot, MavMessage, MavType};
use vtol_link::{ComponentId, Frame, LinkEvent, LinkId, LinkSender, SystemId};

use super::machine::Inbound;
use crate::trust::signing::DaemonSigning;

/// Message ids the client's machines read; everything else is never decoded.
const WANTED: [u32; 6] = [
    0,   // HEARTBEAT
    22,  // PARAM_VALUE
    77,  // COMMAND_ACK
    111, // TIMESYNC
    253, // STATUSTEXT
    345, // PARAM_ERROR
];

/// MAV_COMP_ID_AUTOPILOT1.
const AUTOPILOT1: u8 = 1;
/// Messages only an autopilot streams (SYS_STATUS, ATTITUDE).
const TELEMETRY: [u32; 2] = [1, 30];

/// Whether the session reads `frame`: the message types its machines use and, while the
/// vehicle is not known yet, the autopilot telemetry that finds it. The rest is never looked
/// at, so an in-process link to the client need not carry it.
pub(crate) fn reads(frame: &Frame, target_known: bool) -> bool {
    let id = frame.message_id();
    WANTED.contains(&id)
        || (!target_known && frame.component_id() == AUTOPILOT1 && TELEMETRY.contains(&id))
}

/// Shared between the session task and every handle.
#[derive(Debug)]
pub(crate) struct Shared {
    /// Operator guards alive.
    pub operators: AtomicUsize,
    /// Frames written / dropped because no link was up or its queue was full.
    pub sent: AtomicUsize,
    pub dropped: AtomicUsize,
}

/// What the session task owns besides its channels.
pub(crate) struct Session {
    /// Our (system, component).
    pub me: (SystemId, ComponentId),
    /// Decoded messages for the waiting requests.
    pub inbound: broadcast::Sender<Arc<Inbound>>,
    /// The vehicle, once found.
    pub target: watch::Sender<Option<(SystemId, ComponentId)>>,
    /// The target was given: never replace it by the first heartbeat.
    pub fixed_target: bool,
    pub shared: Arc<Shared>,
    /// Links up now (a request waits for one before its first send).
    pub links_up: watch::Sender<usize>,
    /// Signing, for a client on its own link with a key.
    pub signing: Option<DaemonSigning>,
}

impl Session {
    /// Runs the session until `cancel` fires or every sender is gone.
    pub(crate) async fn run(
        self,
        mut links_rx: mpsc::Receiver<LinkEvent>,
        mut out_rx: mpsc::Receiver<MavMessage>,
        cancel: CancellationToken,
    ) {
        let Self {
            me,
            inbound,
            target,
            fixed_target,
            shared,
            links_up,
            mut signing,
        } = self;
        let mut links: HashMap<LinkId, LinkSender> = HashMap::new();
        let mut seq: u8 = 0;
        let mut beat = tokio::time::interval(Duration::from_secs(1));
        beat.set_missed_tick_behavior(tokio::time::MissedTickBehavior::Delay);
        let mut send = |links: &HashMap<LinkId, LinkSender>,
                        msg: &MavMessage,
                        signing: &mut Option<DaemonSigning>| {
            let mut frame = Frame::encode_v2(me.0, me.1, seq, msg);
            seq = seq.wrapping_add(1);
            if let Some(s) = signing {
                match s.sign_own(&frame) {
                    Ok(f) => frame = f,
                    Err(e) => {
                        tracing::warn!("not sent: {e}");
                        shared.dropped.fetch_add(1, Ordering::Relaxed);
                        return;
                    }
                }
            }
            let mut ok = false;
            for tx in links.values() {
                ok |= tx.try_send(frame.clone()).is_ok();
            }
            let counter = if ok { &shared.sent } else { &shared.dropped };
            counter.fetch_add(1, Ordering::Relaxed);
        };
        loop {
            tokio::select! {
                () = cancel.cancelled() => break,
                ev = links_rx.recv() => match ev {
                    None => break,
                    Some(LinkEvent::Up { id, tx, .. }) => {
                        links.insert(id, tx);
                        links_up.send_replace(links.len());
                    }
                    Some(LinkEvent::Down { id, .. }) => {
                        links.remove(&id);
                        links_up.send_replace(links.len());
                    }
                    Some(LinkEvent::Frame { frame, .. }) => {
                        let finds = !fixed_target
                            && frame.component_id() == AUTOPILOT1
                            && TELEMETRY.contains(&frame.message_id());
                        if !finds && !WANTED.contains(&frame.message_id()) {
                            continue;
                        }
                        if let Some(s) = &mut signing
                            && let Err(refusal) = s.verify_vehicle(&frame)
                        {
                            tracing::debug!(%refusal, "frame refused");
                            continue;
                        }
                        // The autopilot's own telemetry finds the vehicle as surely as its
                        // heartbeat, and arrives many times a second: on a lossy link that
                        // saves waiting for the next 1 Hz heartbeat.
                        if !fixed_target
                            && frame.component_id() == AUTOPILOT1
                            && TELEMETRY.contains(&frame.message_id())
                            && target.borrow().is_none()
                        {
                            target.send_replace(Some((SystemId(frame.system_id()), ComponentId(AUTOPILOT1))));
                        }
                        if !WANTED.contains(&frame.message_id()) {
                            continue;
                        }
                        let Ok(msg) = frame.decode() else { continue };
                        let (sys, comp) = frame.sender();
                        if !fixed_target
                            && target.borrow().is_none()
                            && let MavMessage::HEARTBEAT(h) = &msg
                            && is_vehicle(h.autopilot, h.mavtype)
                        {
                            target.send_replace(Some((sys, comp)));
                        }
                        // No receiver is fine: nothing is waiting for an answer right now.
                        let _ = inbound.send(Arc::new(Inbound { sys, comp, msg }));
                    }
                },
                msg = out_rx.recv() => match msg {
                    Some(m) => send(&links, &m, &mut signing),
                    None => break,
                },
                _ = beat.tick() => {
                    if shared.operators.load(Ordering::Relaxed) > 0 {
                        send(&links, &vtol_link::gcs_heartbeat(), &mut signing);
                    }
                }
            }
        }
        if let Some(s) = &signing
            && let Err(e) = s.save()
        {
            tracing::warn!("{e}");
        }
    }
}

/// A heartbeat from a vehicle: not a ground station, not an autopilot-less peripheral
/// (pymavlink's `probably_vehicle_heartbeat` rule).
fn is_vehicle(autopilot: MavAutopilot, mavtype: MavType) -> bool {
    autopilot != MavAutopilot::MAV_AUTOPILOT_INVALID
        && !matches!(
            mavtype,
            MavType::MAV_TYPE_GCS | MavType::MAV_TYPE_ONBOARD_CONTROLLER | MavType::MAV_TYPE_GIMBAL
        )
}
