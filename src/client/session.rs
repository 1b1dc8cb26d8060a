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

use std::collections::{BTreeMap, BTreeSet, HashMap};
use std::sync::Arc;
use std::sync::atomic::{AtomicUsize, Ordering};
use std::time::Duration;

use tokio::sync::{broadcast, mpsc, watch};
use tokio_util::sync::CancellationToken;
use vtol_link::dialect::MavMessage;
use vtol_link::{ComponentId, Frame, FrameSource, LinkEvent, LinkId, LinkSender, SystemId};

use super::machine::Inbound;
use super::pace::Pacer;
use crate::trust::signing::DaemonSigning;

/// Message ids the client's machines read; everything else is never decoded.
const WANTED: [u32; 16] = [
    0,   // HEARTBEAT
    22,  // PARAM_VALUE
    39,  // MISSION_ITEM
    40,  // MISSION_REQUEST
    44,  // MISSION_COUNT
    47,  // MISSION_ACK
    51,  // MISSION_REQUEST_INT
    73,  // MISSION_ITEM_INT
    77,  // COMMAND_ACK
    109, // RADIO_STATUS (the pacing of what the client sends)
    110, // FILE_TRANSFER_PROTOCOL (the parameter table as a file)
    111, // TIMESYNC
    148, // AUTOPILOT_VERSION (whether the vehicle offers FTP)
    244, // MESSAGE_INTERVAL
    253, // STATUSTEXT
    345, // PARAM_ERROR
];

/// MAV_COMP_ID_AUTOPILOT1.
const AUTOPILOT1: u8 = 1;
/// Messages only an autopilot streams, any of which finds the vehicle: on a lossy link the
/// first of its many streams to get through, not the next heartbeat or SYS_STATUS, ends the
/// wait (a ground station or a companion never sends these as component 1).
const TELEMETRY: [u32; 15] = [
    1,   // SYS_STATUS
    24,  // GPS_RAW_INT
    26,  // SCALED_IMU
    27,  // RAW_IMU
    29,  // SCALED_PRESSURE
    30,  // ATTITUDE
    32,  // LOCAL_POSITION_NED
    33,  // GLOBAL_POSITION_INT
    36,  // SERVO_OUTPUT_RAW
    62,  // NAV_CONTROLLER_OUTPUT
    65,  // RC_CHANNELS
    74,  // VFR_HUD
    111, // TIMESYNC: the autopilot's answer to the round-trip probe
    147, // BATTERY_STATUS
    245, // EXTENDED_SYS_STATE
];

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

/// Who the session has heard, for the diagnoses of a command that finds no vehicle or the
/// wrong one: every vehicle (heartbeat or autopilot telemetry that passed the signing rules),
/// and the systems whose frames were refused by the signing rules or arrived signed while the
/// client has no key.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct Heard {
    /// Vehicles heard, by system id.
    pub vehicles: BTreeSet<u8>,
    /// Systems whose frames failed signature verification (with a key).
    pub bad_signature: BTreeSet<u8>,
    /// Systems whose frames arrived unsigned although the client has a key.
    pub unsigned: BTreeSet<u8>,
    /// Systems whose frames arrived signed although the client has no key.
    pub signed: BTreeSet<u8>,
    /// Each vehicle's (MAV_AUTOPILOT, MAV_TYPE) from its last heartbeat, raw, by (system,
    /// component): which mode table it uses.
    pub kinds: BTreeMap<(u8, u8), (u8, u8)>,
}

/// Adds `sys` to the set `pick` chooses, telling the watchers only when it is new.
fn note(heard: &watch::Sender<Heard>, sys: u8, pick: fn(&mut Heard) -> &mut BTreeSet<u8>) {
    heard.send_if_modified(|h| pick(h).insert(sys));
}

/// How often a client on its own link says hello until it hears a vehicle.
const HELLO_EVERY: Duration = Duration::from_millis(500);

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
    /// Who has been heard.
    pub heard: watch::Sender<Heard>,
    /// Whether the radio's pacing holds outgoing messages back now (the requests' retry
    /// timers wait meanwhile).
    pub held: watch::Sender<bool>,
    /// Speak first: until a vehicle is heard, send [`hello`] on every link as it comes up and
    /// every [`HELLO_EVERY`] (a client on its own link: a `udpout` link's server learns its
    /// peer only from what the peer sends).
    pub hello: bool,
}

/// What a client sends before it has heard anything: a TIMESYNC request to every system. It
/// makes a `udpin` server (a daemon's endpoint, a vehicle) learn the client's address, and it
/// is not a HEARTBEAT: ArduPilot and the twin start their GCS-loss failsafe timer on any
/// heartbeat from the GCS system id, and a one-off command must not tell the vehicle that an
/// operator is watching.
#[must_use]
pub fn hello() -> MavMessage {
    MavMessage::TIMESYNC(vtol_link::dialect::TIMESYNC_DATA {
        tc1: 0,
        ts1: 1,
        target_system: 0,
        target_component: 0,
    })
}

impl Session {
    /// Runs the session until `cancel` fires or every sender is gone.
    // Long: one `select!` over the session's event sources (links, outgoing messages paced by the
    // radio, the hello and heartbeat ticks) sharing its send closure and link table.
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
            heard,
            held,
            hello: speak_first,
        } = self;
        let mut hello_tick = tokio::time::interval(HELLO_EVERY);
        hello_tick.set_missed_tick_behavior(tokio::time::MissedTickBehavior::Delay);
        let mut links: HashMap<LinkId, LinkSender> = HashMap::new();
        let mut source = FrameSource::new(me.0, me.1);
        let mut beat = tokio::time::interval(Duration::from_secs(1));
        beat.set_missed_tick_behavior(tokio::time::MissedTickBehavior::Delay);
        let mut send = |links: &HashMap<LinkId, LinkSender>,
                        msg: &MavMessage,
                        signing: &mut Option<DaemonSigning>| {
            let mut frame = source.encode_v2(msg);
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
        let mut pacer = Pacer::default();
        let now = || tokio::time::Instant::now().into_std();
        loop {
            // While the radio's buffer is full, outgoing messages wait in their queue.
            let wait = pacer.next_send(now());
            held.send_if_modified(|h| std::mem::replace(h, wait.is_some()) != wait.is_some());
            tokio::select! {
                () = cancel.cancelled() => break,
                ev = links_rx.recv() => match ev {
                    None => break,
                    Some(LinkEvent::Up { id, tx, .. }) => {
                        links.insert(id, tx);
                        links_up.send_replace(links.len());
                        if speak_first && heard.borrow().vehicles.is_empty() {
                            send(&links, &hello(), &mut signing);
                        }
                    }
                    Some(LinkEvent::Down { id, .. }) => {
                        links.remove(&id);
                        links_up.send_replace(links.len());
                    }
                    Some(LinkEvent::Frame { frame, .. }) => {
                        let finder = Finder { fixed_target, target: &target, heard: &heard };
                        if let Some(inb) = finder.take(&frame, &mut signing) {
                            if let MavMessage::RADIO_STATUS(r) = &inb.msg {
                                pacer.on_radio_status(r.txbuf, now());
                            }
                            // No receiver is fine: nothing is waiting for an answer right now.
                            let _ = inbound.send(Arc::new(inb));
                        }
                    }
                },
                msg = out_rx.recv(), if wait.is_none() => match msg {
                    Some(m) => {
                        send(&links, &m, &mut signing);
                        pacer.sent(now());
                    }
                    None => break,
                },
                () = tokio::time::sleep_until(
                    wait.map_or_else(tokio::time::Instant::now, tokio::time::Instant::from_std),
                ), if wait.is_some() => {}
                _ = hello_tick.tick(), if speak_first && heard.borrow().vehicles.is_empty() => {
                    send(&links, &hello(), &mut signing);
                }
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

/// What the session does with each frame it receives: the signing rules, who has been heard,
/// the vehicle found, and the decoded message for the waiting requests.
struct Finder<'a> {
    fixed_target: bool,
    target: &'a watch::Sender<Option<(SystemId, ComponentId)>>,
    heard: &'a watch::Sender<Heard>,
}

impl Finder<'_> {
    /// The decoded message for the requests, when the frame carries one they read.
    fn take(&self, frame: &Frame, signing: &mut Option<DaemonSigning>) -> Option<Inbound> {
        let heard = self.heard;
        let finds = frame.component_id() == AUTOPILOT1 && TELEMETRY.contains(&frame.message_id());
        if !finds && !WANTED.contains(&frame.message_id()) {
            return None;
        }
        let sys = frame.system_id();
        match signing {
            Some(s) => {
                if let Err(refusal) = s.verify_vehicle(frame) {
                    tracing::debug!(%refusal, "frame refused");
                    match refusal {
                        vtol_link::Refusal::BadSignature => {
                            note(heard, sys, |h| &mut h.bad_signature);
                        }
                        vtol_link::Refusal::Unsigned { .. } => {
                            note(heard, sys, |h| &mut h.unsigned);
                        }
                        _ => {}
                    }
                    return None;
                }
            }
            None => {
                if frame.is_signed() {
                    note(heard, sys, |h| &mut h.signed);
                }
            }
        }
        // The autopilot's own telemetry finds the vehicle as surely as its heartbeat, and
        // arrives many times a second: on a lossy link that saves waiting for the next 1 Hz
        // heartbeat.
        if finds {
            note(heard, sys, |h| &mut h.vehicles);
            self.found((SystemId(sys), ComponentId(AUTOPILOT1)));
        }
        if !WANTED.contains(&frame.message_id()) {
            return None;
        }
        // Leniently: a heartbeat of a MAV_TYPE the dialect lacks still finds its vehicle. An
        // enum value read as a stand-in could mislead the machines, so only exact messages
        // go on to them.
        let lenient = frame.decode_lenient().ok()?;
        let (sys, comp) = frame.sender();
        if let Some((mav_type, autopilot)) = frame.heartbeat_kind()
            && crate::tracker::state::is_vehicle_heartbeat(mav_type, autopilot)
        {
            note(heard, sys.0, |h| &mut h.vehicles);
            let kind = (autopilot, mav_type);
            heard.send_if_modified(|h| h.kinds.insert((sys.0, comp.0), kind) != Some(kind));
            self.found((sys, comp));
        }
        if !lenient.replaced.is_empty() {
            return None;
        }
        let msg = lenient.msg;
        Some(Inbound { sys, comp, msg })
    }

    /// The first vehicle heard is the target, unless one was given.
    fn found(&self, vehicle: (SystemId, ComponentId)) {
        if !self.fixed_target && self.target.borrow().is_none() {
            self.target.send_replace(Some(vehicle));
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use vtol_link::dialect as apm;

    fn frame(comp: u8, msg: &MavMessage) -> Frame {
        Frame::encode_v2(SystemId(1), ComponentId(comp), 0, msg)
    }

    fn position() -> MavMessage {
        MavMessage::GLOBAL_POSITION_INT(apm::GLOBAL_POSITION_INT_DATA::default())
    }

    /// Any of the autopilot's streams finds the vehicle, not only its heartbeat: on a lossy
    /// link the first to get through ends the wait.
    #[test]
    fn the_autopilots_position_finds_the_vehicle() {
        let (target, _) = watch::channel(None);
        let (heard, _) = watch::channel(Heard::default());
        let finder = Finder {
            fixed_target: false,
            target: &target,
            heard: &heard,
        };
        // A companion's (component 191) position is not the autopilot's.
        finder.take(&frame(191, &position()), &mut None);
        assert!(heard.borrow().vehicles.is_empty());
        assert_eq!(*target.borrow(), None);
        finder.take(&frame(AUTOPILOT1, &position()), &mut None);
        assert!(heard.borrow().vehicles.contains(&1));
        assert_eq!(
            *target.borrow(),
            Some((SystemId(1), ComponentId(AUTOPILOT1)))
        );
    }

    /// With the target named, the autopilot's answer to the round-trip probe finds it before
    /// its next heartbeat; a ground station's TIMESYNC (component 190) does not.
    #[test]
    fn the_autopilots_answer_to_the_probe_finds_the_vehicle() {
        let (target, _) = watch::channel(Some((SystemId(1), ComponentId(AUTOPILOT1))));
        let (heard, _) = watch::channel(Heard::default());
        let finder = Finder {
            fixed_target: true,
            target: &target,
            heard: &heard,
        };
        let sync = MavMessage::TIMESYNC(apm::TIMESYNC_DATA {
            tc1: 5,
            ts1: 7,
            target_system: 255,
            target_component: 190,
        });
        finder.take(&frame(190, &sync), &mut None);
        assert!(heard.borrow().vehicles.is_empty());
        finder.take(&frame(AUTOPILOT1, &sync), &mut None);
        assert!(heard.borrow().vehicles.contains(&1));
    }

    /// An in-process client is handed the autopilot's telemetry only until it knows its
    /// vehicle; the messages its machines read, always.
    #[test]
    fn telemetry_is_read_only_until_the_vehicle_is_known() {
        let f = frame(AUTOPILOT1, &position());
        assert!(reads(&f, false));
        assert!(!reads(&f, true));
        let hb = frame(
            AUTOPILOT1,
            &MavMessage::HEARTBEAT(apm::HEARTBEAT_DATA::default()),
        );
        assert!(reads(&hb, true));
    }
}
