//! The ground station's own MAVLink client: system 255, component 190 by default, over any
//! vtol-link transport (straight to a URL, or inside the daemon over its own-traffic link).
//!
//! - [`session`]: the one task that owns the identity, the sequence counter and the link.
//! - [`machine`], [`command`], [`param`], [`mission`]: the protocol exchanges as pure state
//!   machines (messages and time in, messages and a result out), tested without sockets.
//! - [`pace`]: the session's sends paced by the RADIO_STATUS of a telemetry radio on the link.
//! - [`ClientHandle`]: the async shell that drives those machines, cheap to clone; the
//!   command line and the terminal UI use it.
//!
//! The client sends a GCS heartbeat only while an [`OperatorGuard`] lives, so it never tells a
//! vehicle that an operator is watching when none is.

pub mod command;
pub mod interval;
pub mod machine;
pub mod mission;
pub mod own_traffic;
pub mod pace;
pub mod param;
pub mod probe;
mod session;
#[cfg(test)]
pub(crate) mod test_frames;
pub use session::{Heard, hello};
pub mod version;

use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::{Arc, Mutex};
use std::time::Duration;

use tokio::io::{AsyncRead, AsyncWrite};
use tokio::sync::{broadcast, mpsc, watch};
use tokio_util::sync::CancellationToken;
use vtol_link::dialect::{MavCmd, MavMessage, MavProtocolCapability, MavResult};
use vtol_link::{ComponentId, LinkOptions, LinkUrl, SystemId};

use command::CommandMachine;
pub use command::CommandOutcome;
use machine::{Inbound, Machine, Rtt};
use param::{ParamFailure, ParamMachine, PullMachine};

use crate::params::plan::{Step, StepError, Transaction};
use crate::params::{ParamSet, PushReport, Rules, TwinRules, order_writes};

/// The force-arm/disarm magic number of MAV_CMD_COMPONENT_ARM_DISARM's param 2.
pub const FORCE_MAGIC: f32 = 21196.0;
/// How long a request waits for the first vehicle heartbeat when no target was given.
pub const FIND_VEHICLE_TIMEOUT: Duration = Duration::from_secs(5);

/// ArduPlane's mode numbers, which the twin reuses (pymavlink and MAVProxy name them). Other
/// vehicles' tables are in [`crate::modes`]; [`ClientHandle::set_mode`] takes the vehicle's own.
pub const MODES: &[(&str, u32)] = crate::modes::PLANE;

/// Why a client request failed.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum ClientError {
    /// The vehicle answered no.
    #[error("refused by the vehicle: {reason}")]
    Refused {
        /// The vehicle's reason (its STATUSTEXT when it sent one).
        reason: String,
    },
    /// No answer after every retry.
    #[error("no answer from the vehicle: {0}")]
    Timeout(String),
    /// The link failed or the client stopped.
    #[error("link: {0}")]
    Link(String),
    /// No vehicle heartbeat was heard and no target was given.
    #[error("no vehicle heard (is the link right? try --target)")]
    NoVehicle,
    /// The request cannot be made as asked.
    #[error("{0}")]
    Usage(String),
}

/// Identity and target of a client.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct ClientConfig {
    /// Our system id (255 = ground station).
    pub system_id: SystemId,
    /// Our component id (190 = MAV_COMP_ID_MISSIONPLANNER, what ground stations use).
    pub component_id: ComponentId,
    /// The vehicle, when known in advance; otherwise the first vehicle heartbeat decides.
    pub target: Option<(SystemId, ComponentId)>,
}

impl Default for ClientConfig {
    fn default() -> Self {
        Self {
            system_id: SystemId(255),
            component_id: ComponentId(190),
            target: None,
        }
    }
}

/// The client: cheap to clone, `Send + Sync`; every method may run concurrently.
#[derive(Debug, Clone)]
pub struct ClientHandle {
    me: (SystemId, ComponentId),
    out: mpsc::Sender<MavMessage>,
    inbound: broadcast::Sender<Arc<Inbound>>,
    target: watch::Receiver<Option<(SystemId, ComponentId)>>,
    /// The session's target, for [`ClientHandle::select_vehicle`].
    select: watch::Sender<Option<(SystemId, ComponentId)>>,
    links_up: watch::Receiver<usize>,
    rtt: Arc<Mutex<Rtt>>,
    shared: Arc<session::Shared>,
    cache: Arc<Mutex<ParamSet>>,
    /// The vehicle's AUTOPILOT_VERSION capabilities, once asked (`None` inside: no answer).
    caps: Arc<Mutex<Option<VehicleCaps>>>,
    /// The last FTP session number used.
    ftp_session: Arc<std::sync::atomic::AtomicU8>,
    heard: watch::Receiver<Heard>,
    /// Whether the session holds outgoing messages back (a radio's buffer full).
    held: watch::Receiver<bool>,
}

/// While alive, the client sends its 1 Hz GCS heartbeat: an operator is watching.
#[derive(Debug)]
pub struct OperatorGuard {
    shared: Arc<session::Shared>,
}

impl Drop for OperatorGuard {
    fn drop(&mut self) {
        self.shared.operators.fetch_sub(1, Ordering::Relaxed);
    }
}

/// A vehicle and the capabilities its AUTOPILOT_VERSION gave (`None`: it did not answer).
type VehicleCaps = ((SystemId, ComponentId), Option<MavProtocolCapability>);

/// Frames buffered from the handles to the session task.
const OUT_QUEUE: usize = 1024;
/// Decoded messages buffered per waiting request; a request that falls behind sees a gap,
/// which its retries cover like a lost frame.
const INBOUND_QUEUE: usize = 4096;

impl ClientHandle {
    fn spawn(
        config: ClientConfig,
        links_rx: mpsc::Receiver<vtol_link::LinkEvent>,
        signing: Option<crate::trust::signing::DaemonSigning>,
        hello: bool,
        cancel: CancellationToken,
    ) -> Self {
        let me = (config.system_id, config.component_id);
        let (heard_tx, heard) = watch::channel(Heard::default());
        let (out, out_rx) = mpsc::channel(OUT_QUEUE);
        let (inbound, _) = broadcast::channel(INBOUND_QUEUE);
        let (target_tx, target) = watch::channel(config.target);
        let shared = Arc::new(session::Shared {
            operators: AtomicUsize::new(0),
            sent: AtomicUsize::new(0),
            dropped: AtomicUsize::new(0),
        });
        let (links_up_tx, links_up) = watch::channel(0);
        let (held_tx, held) = watch::channel(false);
        let session = session::Session {
            links_up: links_up_tx,
            me,
            inbound: inbound.clone(),
            target: target_tx.clone(),
            fixed_target: config.target.is_some(),
            shared: Arc::clone(&shared),
            signing,
            heard: heard_tx,
            held: held_tx,
            hello,
        };
        tokio::spawn(session.run(links_rx, out_rx, cancel));
        Self {
            me,
            out,
            inbound,
            target,
            select: target_tx,
            links_up,
            rtt: Arc::new(Mutex::new(Rtt::default())),
            shared,
            cache: Arc::new(Mutex::new(ParamSet::new())),
            caps: Arc::new(Mutex::new(None)),
            // Sessions numbered from the component id: two clients of one vehicle rarely
            // share one.
            ftp_session: Arc::new(std::sync::atomic::AtomicU8::new(me.1.0.wrapping_mul(7))),
            heard,
            held,
        }
    }

    /// A client on its own link to `url` (a vehicle, or a daemon's serve port). Returns once
    /// the endpoint is open (a `tcp:` client connects and reconnects in the background).
    ///
    /// # Errors
    /// [`ClientError::Link`] when the endpoint cannot be opened.
    pub async fn connect(
        url: &LinkUrl,
        config: ClientConfig,
        cancel: CancellationToken,
    ) -> Result<Self, ClientError> {
        Self::connect_signed(url, config, None, cancel).await
    }

    /// [`ClientHandle::connect`] with MAVLink 2 signing: every frame sent is signed, and only
    /// frames that pass the signing rules are read. The signing state is saved when the client
    /// stops.
    ///
    /// # Errors
    /// [`ClientError::Link`] when the endpoint cannot be opened.
    pub async fn connect_signed(
        url: &LinkUrl,
        config: ClientConfig,
        signing: Option<crate::trust::signing::DaemonSigning>,
        cancel: CancellationToken,
    ) -> Result<Self, ClientError> {
        let (tx, rx) = mpsc::channel(INBOUND_QUEUE);
        let endpoint = vtol_link::spawn_endpoint(url, tx, LinkOptions::default(), cancel.clone())
            .await
            .map_err(|e| ClientError::Link(format!("cannot open {url}: {e}")))?;
        tokio::spawn(endpoint.join());
        Ok(Self::spawn(config, rx, signing, true, cancel))
    }

    /// A client on its own byte stream (a TCP connection the caller opened, so that a refused
    /// connection fails at once), signing as [`ClientHandle::connect_signed`].
    pub fn over_own_stream<S>(
        stream: S,
        peer: &str,
        config: ClientConfig,
        signing: Option<crate::trust::signing::DaemonSigning>,
        cancel: CancellationToken,
    ) -> Self
    where
        S: AsyncRead + AsyncWrite + Send + 'static,
    {
        let (tx, rx) = mpsc::channel(INBOUND_QUEUE);
        let (_, task) =
            vtol_link::spawn_stream_link(stream, peer, tx, LinkOptions::default(), cancel.clone());
        drop(task);
        Self::spawn(config, rx, signing, true, cancel)
    }

    /// A client over a byte stream carrying MAVLink frames (the daemon's own-traffic link).
    pub fn over_stream<S>(stream: S, config: ClientConfig, cancel: CancellationToken) -> Self
    where
        S: AsyncRead + AsyncWrite + Send + 'static,
    {
        let (tx, rx) = mpsc::channel(INBOUND_QUEUE);
        let (_, task) = vtol_link::spawn_stream_link(
            stream,
            "vtol-gcs client",
            tx,
            LinkOptions::default(),
            cancel.clone(),
        );
        drop(task);
        Self::spawn(config, rx, None, false, cancel)
    }

    /// Waits until the session task has ended (after its cancellation): what it saves on the
    /// way out (the signing state) is then on disk.
    pub async fn stopped(&self) {
        let mut rx = self.links_up.clone();
        while rx.changed().await.is_ok() {}
    }

    /// Who has been heard so far (vehicles, and frames refused by the signing rules).
    #[must_use]
    pub fn heard(&self) -> Heard {
        self.heard.borrow().clone()
    }

    /// Waits up to `timeout` until `pred` holds for what has been heard; returns what was
    /// heard either way.
    pub async fn wait_heard(&self, timeout: Duration, pred: impl Fn(&Heard) -> bool) -> Heard {
        let mut rx = self.heard.clone();
        let _ = tokio::time::timeout(timeout, rx.wait_for(|h| pred(h))).await;
        self.heard()
    }

    /// Our (system, component).
    #[must_use]
    pub fn identity(&self) -> (SystemId, ComponentId) {
        self.me
    }

    /// The vehicle the client talks to, once found (first vehicle heartbeat or `--target`).
    #[must_use]
    pub fn target(&self) -> Option<(SystemId, ComponentId)> {
        *self.target.borrow()
    }

    /// Makes `system`/`component` the vehicle every later request goes to (the terminal UI's
    /// vehicle switch). The parameter cache belonged to the previous vehicle and is emptied.
    pub fn select_vehicle(&self, system: vtol_link::SystemId, component: vtol_link::ComponentId) {
        let next = Some((system, component));
        if self.select.send_replace(next) != next
            && let Ok(mut c) = self.cache.lock()
        {
            *c = ParamSet::new();
        }
    }

    /// Which frames the client reads: the message types it uses and, until the vehicle is
    /// known, the autopilot telemetry that finds it. For the link that carries a router's
    /// traffic to an in-process client ([`vtol_link::LinkOptions::accept`]): the rest never
    /// needs copying.
    #[must_use]
    pub fn read_filter(&self) -> vtol_link::EgressFilter {
        let target = self.target.clone();
        // Once found, the vehicle stays found: remember that instead of asking the channel for
        // every frame of its telemetry.
        let known = std::sync::atomic::AtomicBool::new(false);
        vtol_link::EgressFilter::new(move |frame| {
            let is_known = known.load(Ordering::Relaxed) || {
                let k = target.borrow().is_some();
                known.store(k, Ordering::Relaxed);
                k
            };
            session::reads(frame, is_known)
        })
    }

    /// Waits up to `timeout` for the vehicle to be known.
    ///
    /// # Errors
    /// [`ClientError::NoVehicle`].
    pub async fn wait_target(
        &self,
        timeout: Duration,
    ) -> Result<(SystemId, ComponentId), ClientError> {
        let mut rx = self.target.clone();
        match tokio::time::timeout(timeout, rx.wait_for(Option::is_some)).await {
            Ok(Ok(t)) => (*t).ok_or(ClientError::NoVehicle),
            Ok(Err(_)) => Err(ClientError::Link("client stopped".into())),
            Err(_) => Err(ClientError::NoVehicle),
        }
    }

    /// The current retransmission timeout (scaled to the measured round trip).
    #[must_use]
    pub fn rto(&self) -> Duration {
        self.rtt.lock().map(|r| r.rto()).unwrap_or(Rtt::INITIAL_RTO)
    }

    /// The smoothed round trip, once measured.
    #[must_use]
    pub fn srtt(&self) -> Option<Duration> {
        self.rtt.lock().ok().and_then(|r| r.srtt())
    }

    fn sample_rtt(&self, rtt: Option<Duration>) {
        if let (Some(s), Ok(mut r)) = (rtt, self.rtt.lock()) {
            r.sample(s);
        }
    }

    /// Marks an operator as present: the 1 Hz GCS heartbeat flows while any guard lives.
    #[must_use]
    pub fn operator_present(&self) -> OperatorGuard {
        self.shared.operators.fetch_add(1, Ordering::Relaxed);
        OperatorGuard {
            shared: Arc::clone(&self.shared),
        }
    }

    /// Whether an operator is present (an [`OperatorGuard`] lives).
    #[must_use]
    pub fn has_operator(&self) -> bool {
        self.shared.operators.load(Ordering::Relaxed) > 0
    }

    /// Fire-and-forget frame from the client's identity (e.g. SET_POSITION_TARGET_LOCAL_NED).
    ///
    /// # Errors
    /// [`ClientError::Link`] when the client has stopped.
    pub async fn send(&self, msg: MavMessage) -> Result<(), ClientError> {
        self.out
            .send(msg)
            .await
            .map_err(|_| ClientError::Link("client stopped".into()))
    }

    /// Waits up to `timeout` for a link to be up (a `tcp:` client connects in the background).
    ///
    /// # Errors
    /// [`ClientError::Link`].
    pub async fn wait_connected(&self, timeout: Duration) -> Result<(), ClientError> {
        let mut rx = self.links_up.clone();
        match tokio::time::timeout(timeout, rx.wait_for(|n| *n > 0)).await {
            Ok(Ok(_)) => Ok(()),
            Ok(Err(_)) => Err(ClientError::Link("client stopped".into())),
            Err(_) => Err(ClientError::Link(format!(
                "not connected after {} s",
                timeout.as_secs()
            ))),
        }
    }

    /// Runs a machine to its result: subscribe first, then send what it asks, feed it every
    /// inbound message and its deadlines. While the session holds outgoing messages back (a
    /// radio's buffer full, [`pace`]), the machine's deadlines wait: a retry would only queue
    /// behind the copy not sent yet, and a request is not given up for the radio's delay.
    async fn drive<M: Machine>(
        &self,
        m: &mut M,
        mut on_step: impl FnMut(&M),
    ) -> Result<M::Output, ClientError> {
        // A first send with no link up would only be lost and cost a timeout.
        self.wait_connected(FIND_VEHICLE_TIMEOUT).await?;
        let mut rx = self.inbound.subscribe();
        let mut held = self.held.clone();
        for msg in m.start(std::time::Instant::now()) {
            self.send(msg).await?;
        }
        loop {
            if let Some(out) = m.result() {
                return Ok(out);
            }
            let deadline = tokio::time::Instant::from_std(m.deadline());
            let holding = *held.borrow_and_update();
            let sends = tokio::select! {
                r = rx.recv() => match r {
                    Ok(inb) => m.on_message(std::time::Instant::now(), &inb),
                    Err(broadcast::error::RecvError::Lagged(_)) => Vec::new(),
                    Err(broadcast::error::RecvError::Closed) => {
                        return Err(ClientError::Link("client stopped".into()));
                    }
                },
                () = tokio::time::sleep_until(deadline), if !holding => {
                    m.on_time(std::time::Instant::now())
                }
                r = held.changed(), if holding => match r {
                    Ok(()) => Vec::new(),
                    Err(_) => return Err(ClientError::Link("client stopped".into())),
                },
            };
            for s in m.take_rtt_samples() {
                self.sample_rtt(Some(s));
            }
            on_step(m);
            for msg in sends {
                self.send(msg).await?;
            }
        }
    }

    async fn vehicle(&self) -> Result<(SystemId, ComponentId), ClientError> {
        match self.target() {
            Some(t) => Ok(t),
            None => self.wait_target(FIND_VEHICLE_TIMEOUT).await,
        }
    }

    /// Measures the round trip with TIMESYNC probes, so the first real request already has a
    /// timeout scaled to the link. `None` when the vehicle did not answer (the timeouts then
    /// start from [`Rtt::INITIAL_RTO`] and adapt as answers come).
    ///
    /// # Errors
    /// [`ClientError::NoVehicle`], [`ClientError::Link`].
    pub async fn probe_rtt(&self) -> Result<Option<Duration>, ClientError> {
        let target = self.vehicle().await?;
        let mut m = probe::ProbeMachine::new(target);
        self.drive(&mut m, |_| {}).await
    }

    /// The interval at which the vehicle sends `msgid` (GET_MESSAGE_INTERVAL, asked again until
    /// MESSAGE_INTERVAL answers): `Some(µs)` as the vehicle reports it (0 not sent or unknown,
    /// −1 disabled), `None` when it does not answer.
    ///
    /// # Errors
    /// [`ClientError::NoVehicle`], [`ClientError::Link`].
    pub async fn message_interval(&self, msgid: u32) -> Result<Option<i32>, ClientError> {
        let target = self.vehicle().await?;
        let mut m = interval::IntervalMachine::new(target, msgid, self.rto());
        self.drive(&mut m, |_| {}).await
    }

    /// COMMAND_LONG with retries (confirmation incremented), ACK matched by command and target,
    /// IN_PROGRESS extends the wait, a refusal carries the vehicle's STATUSTEXT reason.
    ///
    /// # Errors
    /// [`ClientError::Timeout`] without a final ACK; [`ClientError::NoVehicle`], [`ClientError::Link`].
    pub async fn command_long(
        &self,
        command: MavCmd,
        params: [f32; 7],
    ) -> Result<CommandOutcome, ClientError> {
        let target = self.vehicle().await?;
        let mut m = CommandMachine::new(self.me, target, command, params, self.rto());
        let out = self.drive(&mut m, |_| {}).await?;
        out.map_err(|e| {
            ClientError::Timeout(format!(
                "{command:?}: no COMMAND_ACK after {} tries",
                e.tries
            ))
        })
    }

    async fn command_ok(&self, command: MavCmd, params: [f32; 7]) -> Result<(), ClientError> {
        let o = self.command_long(command, params).await?;
        if o.accepted() {
            return Ok(());
        }
        let result = match o.result {
            MavResult::MAV_RESULT_TEMPORARILY_REJECTED => "temporarily rejected",
            MavResult::MAV_RESULT_DENIED => "denied",
            MavResult::MAV_RESULT_UNSUPPORTED => "unsupported",
            MavResult::MAV_RESULT_FAILED => "failed",
            _ => "not accepted",
        };
        Err(ClientError::Refused {
            reason: match o.reason {
                Some(r) => format!("{result}: {r}"),
                None => result.to_owned(),
            },
        })
    }

    /// Arms (`force` skips the pre-arm checks).
    ///
    /// # Errors
    /// [`ClientError::Refused`] with the vehicle's reason, or a link error.
    pub async fn arm(&self, force: bool) -> Result<(), ClientError> {
        let p2 = if force { FORCE_MAGIC } else { 0.0 };
        self.command_ok(
            MavCmd::MAV_CMD_COMPONENT_ARM_DISARM,
            [1.0, p2, 0., 0., 0., 0., 0.],
        )
        .await
    }

    /// Disarms (`force` allows it in flight).
    ///
    /// # Errors
    /// As [`ClientHandle::arm`].
    pub async fn disarm(&self, force: bool) -> Result<(), ClientError> {
        let p2 = if force { FORCE_MAGIC } else { 0.0 };
        self.command_ok(
            MavCmd::MAV_CMD_COMPONENT_ARM_DISARM,
            [0.0, p2, 0., 0., 0., 0., 0.],
        )
        .await
    }

    /// Mode by the vehicle's own name for it (any case: `QHOVER` on ArduPlane, `LOITER` on
    /// ArduCopter, `POSCTL` on PX4) or by its number.
    ///
    /// # Errors
    /// [`ClientError::Usage`] for a name the vehicle does not have; otherwise as
    /// [`ClientHandle::arm`].
    pub async fn set_mode(&self, name: &str) -> Result<(), ClientError> {
        self.change_mode(name).await.map(|_| ())
    }

    /// [`ClientHandle::set_mode`], returning the mode's name as the vehicle's table spells it.
    ///
    /// # Errors
    /// As [`ClientHandle::set_mode`].
    pub async fn change_mode(&self, given: &str) -> Result<String, ClientError> {
        let (autopilot, mav_type) = self.vehicle_kind().await?;
        let number = match given.trim().parse::<u32>() {
            Ok(n) => Some(n),
            Err(_) => crate::modes::mode_number(autopilot, mav_type, given),
        };
        let Some(number) = number else {
            let known: Vec<String> = crate::modes::modes_for(autopilot, mav_type)
                .iter()
                .map(|(n, m)| format!("{n} ({m})"))
                .collect();
            let vehicle = crate::modes::vehicle_name(autopilot, mav_type);
            return Err(ClientError::Usage(if known.is_empty() {
                format!(
                    "unknown mode '{given}': the modes of {vehicle} are not known; give its number"
                )
            } else {
                format!(
                    "unknown mode '{given}' for {vehicle}: one of {}",
                    known.join(", ")
                )
            }));
        };
        let params = if autopilot == crate::modes::AUTOPILOT_PX4 {
            // PX4: base mode with MAV_MODE_FLAG_CUSTOM_MODE_ENABLED, then main and sub mode.
            [
                1.0,
                f32::from(crate::modes::px4_main_mode(number)),
                f32::from(crate::modes::px4_sub_mode(number)),
                0.,
                0.,
                0.,
                0.,
            ]
        } else {
            // p1 = MAV_MODE_FLAG_CUSTOM_MODE_ENABLED, p2 = the custom mode (what pymavlink sends).
            [1.0, number as f32, 0., 0., 0., 0., 0.]
        };
        self.command_ok(MavCmd::MAV_CMD_DO_SET_MODE, params).await?;
        Ok(crate::modes::mode_name(autopilot, mav_type, number))
    }

    /// The vehicle's MAV_AUTOPILOT and MAV_TYPE, from its heartbeat (waited for up to
    /// [`FIND_VEHICLE_TIMEOUT`] when the vehicle was found by other telemetry).
    ///
    /// # Errors
    /// [`ClientError::NoVehicle`] when no vehicle is heard; [`ClientError::Timeout`] when it
    /// sends no heartbeat.
    pub async fn vehicle_kind(&self) -> Result<(u8, u8), ClientError> {
        let target = self.vehicle().await?;
        let key = (target.0.0, target.1.0);
        let heard = self
            .wait_heard(FIND_VEHICLE_TIMEOUT, |h| h.kinds.contains_key(&key))
            .await;
        heard.kinds.get(&key).copied().ok_or_else(|| {
            ClientError::Timeout(format!(
                "no heartbeat from vehicle {}:{}",
                target.0.0, target.1.0
            ))
        })
    }

    /// The vehicle's capabilities (AUTOPILOT_VERSION, asked once per vehicle); `None` when it
    /// does not answer.
    ///
    /// # Errors
    /// [`ClientError::NoVehicle`], [`ClientError::Link`].
    pub async fn capabilities(&self) -> Result<Option<MavProtocolCapability>, ClientError> {
        let target = self.vehicle().await?;
        if let Some((t, caps)) = self.caps.lock().ok().and_then(|c| *c)
            && t == target
        {
            return Ok(caps);
        }
        let mut m = version::VersionMachine::new(target, self.rto());
        let caps = self.drive(&mut m, |_| {}).await?;
        if let Ok(mut c) = self.caps.lock() {
            *c = Some((target, caps));
        }
        Ok(caps)
    }

    /// Whole table; progress reports (received, total). When the vehicle offers MAVLink FTP,
    /// the table comes as its packed parameter file (`@PARAM/param.pck`), with the parameter
    /// protocol as the fallback.
    ///
    /// # Errors
    /// [`ClientError::Timeout`] when the download stalls; link errors.
    pub async fn params_pull(
        &self,
        progress: Option<watch::Sender<(usize, usize)>>,
    ) -> Result<ParamSet, ClientError> {
        self.params_pull_via(progress, true).await
    }

    /// [`ClientHandle::params_pull`], with FTP only if `allow_ftp`.
    ///
    /// # Errors
    /// As [`ClientHandle::params_pull`].
    pub async fn params_pull_via(
        &self,
        progress: Option<watch::Sender<(usize, usize)>>,
        allow_ftp: bool,
    ) -> Result<ParamSet, ClientError> {
        let target = self.vehicle().await?;
        let ftp = allow_ftp
            && self
                .capabilities()
                .await?
                .is_some_and(|c| c.contains(MavProtocolCapability::MAV_PROTOCOL_CAPABILITY_FTP));
        if ftp {
            let session = self
                .ftp_session
                .fetch_add(1, Ordering::Relaxed)
                .wrapping_add(1);
            let mut m =
                param::FtpPullMachine::new(target, session, self.rto()).with_link_rtt(self.srtt());
            let out = self.drive(&mut m, |_| {}).await?;
            tracing::debug!("{}: {}", param::PARAM_FILE, m.summary());
            match out {
                Ok(set) => {
                    if let Some(p) = &progress {
                        p.send_replace((set.len(), set.len()));
                    }
                    if let Ok(mut c) = self.cache.lock() {
                        c.clone_from(&set);
                    }
                    return Ok(set);
                }
                Err(why) => {
                    tracing::info!("{why}: reading the table with the parameter protocol");
                }
            }
        }
        let rtt = self.rtt.lock().map(|r| *r).unwrap_or_default();
        let mut m = PullMachine::new(target, rtt);
        let out = self
            .drive(&mut m, |m| {
                tracing::trace!(progress = ?m.progress(), "{}", m.summary());
                if let Some(p) = &progress {
                    p.send_if_modified(|v| {
                        let now = m.progress();
                        let changed = *v != now;
                        *v = now;
                        changed
                    });
                }
            })
            .await?;
        tracing::debug!("parameter download: {}", m.summary());
        let set = out.map_err(|s| {
            ClientError::Timeout(format!(
                "download stalled at {} of {} parameters",
                s.received, s.total
            ))
        })?;
        if let Ok(mut c) = self.cache.lock() {
            c.clone_from(&set);
        }
        Ok(set)
    }

    /// One read by name.
    ///
    /// # Errors
    /// [`ClientError::Refused`] for a name the vehicle does not have; timeouts; link errors.
    pub async fn param_get(&self, name: &str) -> Result<crate::params::Param, ClientError> {
        let target = self.vehicle().await?;
        let mut m = ParamMachine::read(target, name, self.rto());
        let out = self.drive(&mut m, |_| {}).await?;
        let p = out.map_err(|f| failure(name, f))?;
        if let Ok(mut c) = self.cache.lock() {
            c.insert(name.to_owned(), p);
        }
        Ok(p)
    }

    /// One verified write: `Ok(confirmed value)` only when the echo matches the request after
    /// the vehicle's type conversion; a refusal carries the reason.
    ///
    /// # Errors
    /// [`ClientError::Refused`], [`ClientError::Timeout`], [`ClientError::Usage`] for a
    /// non-finite value, link errors.
    pub async fn param_set(&self, name: &str, value: f32) -> Result<f32, ClientError> {
        if !value.is_finite() {
            return Err(ClientError::Usage(format!(
                "{name}: {value} is not a finite number"
            )));
        }
        let known = self.cache.lock().ok().and_then(|c| c.get(name).copied());
        let ty = match known {
            Some(p) => p.ty,
            // The type decides what echo confirms the write: learn it first.
            None => self.param_get(name).await?.ty,
        };
        let target = self.vehicle().await?;
        let mut m = ParamMachine::write(target, name, value, ty, self.rto());
        let out = self.drive(&mut m, |_| {}).await?;
        let p = out.map_err(|f| failure(name, f))?;
        if let Ok(mut c) = self.cache.lock() {
            c.insert(name.to_owned(), p);
        }
        Ok(p.value)
    }

    /// Transactional upload of a set: pull, diff, write only what changed in an order that
    /// keeps every intermediate set acceptable, retry refused writes after any progress,
    /// verify every value by read-back, and on failure restore every value already changed.
    /// Progress reports (steps done, changes).
    ///
    /// # Errors
    /// [`ClientError::Usage`] when `wanted` names parameters the vehicle does not have (nothing
    /// is sent); pull errors. A refused or rolled-back push is `Ok` with the report saying so.
    pub async fn params_push(
        &self,
        wanted: &ParamSet,
        progress: Option<watch::Sender<(usize, usize)>>,
    ) -> Result<PushReport, ClientError> {
        let current = self.params_pull(None).await?;
        self.push_onto(&current, wanted, &TwinRules, progress).await
    }

    /// [`ClientHandle::params_push`] against a table already pulled, with a given rule model.
    ///
    /// # Errors
    /// As [`ClientHandle::params_push`].
    pub async fn push_onto(
        &self,
        current: &ParamSet,
        wanted: &ParamSet,
        rules: &dyn Rules,
        progress: Option<watch::Sender<(usize, usize)>>,
    ) -> Result<PushReport, ClientError> {
        let unknown = crate::params::unknown_names(current, wanted);
        if !unknown.is_empty() {
            return Err(ClientError::Usage(format!(
                "the vehicle has no parameter {}",
                unknown.join(", ")
            )));
        }
        let changes = crate::params::diff(current, wanted);
        let total = changes.len();
        let mut t = Transaction::new(order_writes(current, &changes, rules));
        let mut steps = 0;
        loop {
            let step = t.next_step();
            match step {
                Step::Done(report) => return Ok(report),
                Step::Write { name, value } => {
                    let r = self.param_set(&name, value).await;
                    t.written(step_result(r)?);
                }
                Step::Read { name } => {
                    let r = self.param_get(&name).await.map(|p| p.value);
                    t.read(step_result(r)?);
                }
            }
            steps += 1;
            if let Some(p) = &progress {
                p.send_replace((steps.min(total), total));
            }
        }
    }
}

/// A write's or read's result as the transaction sees it. A stopped client is no step result:
/// it ends the push with an error.
fn step_result(r: Result<f32, ClientError>) -> Result<Result<f32, StepError>, ClientError> {
    match r {
        Ok(v) => Ok(Ok(v)),
        Err(ClientError::Refused { reason }) => Ok(Err(StepError::Refused(reason))),
        Err(ClientError::Timeout(t)) => Ok(Err(StepError::Lost(t))),
        Err(e) => Err(e),
    }
}

fn failure(name: &str, f: ParamFailure) -> ClientError {
    match f {
        ParamFailure::Refused(reason) => ClientError::Refused { reason },
        // A name the vehicle does not know is an input error, not a refusal.
        ParamFailure::Unknown => ClientError::Usage(format!("the vehicle has no parameter {name}")),
        ParamFailure::NoAnswer { tries, last_echo } => ClientError::Timeout(match last_echo {
            Some(v) => {
                format!("{name}: no confirming echo after {tries} tries (vehicle reports {v})")
            }
            None => format!("{name}: no answer after {tries} tries"),
        }),
    }
}

#[cfg(test)]
mod tests {
    /// The UI shares one handle across tasks and threads.
    #[test]
    fn handle_is_send_sync_and_clone() {
        fn check<T: Send + Sync + Clone + 'static>() {}
        check::<super::ClientHandle>();
    }
}
