//! The twin as a running MAVLink vehicle: transports from `vtol-link`, a sim clock, and the
//! [`Endpoint`] state machine, wired in one task.
//!
//! # Command line (stable; scripts and the pytest suite rely on it)
//!
//! ```text
//! firmware-sim serve [--listen URL]... [--speed N | --fast | --lockstep] [--control URL]
//!                    [--tlog FILE] [--param-file FILE] [--seed N] [--model paper|physical]
//!                    [--ideal-sensors] [--sysid N] [--initial x=..,y=..,psi=..]
//!                    [--boot-calibration] [--loss FRACTION] [--latency MS] [--count N]
//! ```
//!
//! - `--listen URL`, repeatable, default `tcpin:127.0.0.1:5760` (SITL's SERIAL0): `tcpin:` accepts
//!   many clients and re-accepts; `udpin:` replies to every peer heard; `udpout:` sends at once;
//!   `tcp:` and `serial:` connect out.
//! - After every endpoint is bound, one line per `--listen` is printed on stdout, in order:
//!   `listening <url>` where `<url>` carries the real bound port (so `tcpin:127.0.0.1:0` prints
//!   e.g. `listening tcpin:127.0.0.1:40121`). Connect-out URLs print as given. With `--control`,
//!   one more line follows: `control tcpin:<host>:<port>`. Then stdout is flushed; logs go to
//!   stderr.
//! - `--control tcpin:HOST:PORT` opens the harness channel ([`crate::shell::harness`]: `advance`,
//!   `state`, `param`); `--lockstep` freezes sim time except when the channel advances it, and
//!   needs `--control`.
//! - Telemetry rates count in wall time whatever the speed (sim time under `--lockstep`), and a
//!   link short of room sheds telemetry before a reply: PARAM_VALUE and COMMAND_ACK are never
//!   lost behind a stream. Under `--lockstep` nothing is shed; the twin waits for the reader.
//! - `--tlog FILE` logs every frame in both directions ([`crate::shell::tlog`]).
//! - `--loss FRACTION` drops that fraction of frames in each direction, drawn from a generator
//!   seeded by `--seed`; `--latency MS` delays every frame by that much in each direction. A
//!   lossy radio is then tested with real frames, retries and all.
//! - `--param-file FILE`: the parameters, and the mission beside them (`FILE` with the
//!   `.waypoints` extension, QGC WPL 110), loaded at start and saved on every change.
//! - `--count N`: N twins on the same endpoints ([`crate::shell::fleet`]).
//! - `--signing-passphrase TEXT` / `--signing-key-file FILE`: MAVLink 2 signing, and
//!   SETUP_SIGNING from a signed or serial link ([`crate::shell::signing`]).
//! - Ctrl-C or SIGTERM: every link is closed and the process exits 0.
//!
//! The flags, the runtime and the signal handling live in the binary (`main.rs`), as in the
//! daemon; this module takes a [`ServeConfig`].
//!
//! # Embedding
//!
//! [`Twin::start`] runs the same vehicle inside an existing tokio runtime and returns a
//! [`Twin`] handle. [`Twin::attach_stream`] connects it to any byte stream, e.g. one end of
//! `tokio::io::duplex`, carrying real MAVLink frames: this is how the `vtol-gcs` daemon embeds
//! the twin without a socket. [`Twin::harness`] is the harness channel in process.
//!
//! Wall time is tokio's clock throughout (the sim clock, the batch timer, the radio's delays),
//! so under a paused tokio clock the twin runs as fast as the test advances time.
//!
//! ```no_run
//! # async fn demo() -> Result<(), firmware_sim::shell::serve::ServeError> {
//! use firmware_sim::shell::serve::{ServeConfig, Twin};
//! let cancel = tokio_util::sync::CancellationToken::new();
//! let twin = Twin::start(ServeConfig { listen: vec![], ..ServeConfig::default() }, cancel.clone()).await?;
//! let (ours, theirs) = tokio::io::duplex(64 * 1024);
//! twin.attach_stream(theirs, "embedded");
//! // read and write MAVLink frames on `ours`…
//! # drop(ours);
//! cancel.cancel();
//! twin.join().await;
//! # Ok(()) }
//! ```

use std::collections::{HashMap, HashSet};
use std::net::SocketAddr;
use std::path::PathBuf;

use tokio::io::{AsyncRead, AsyncWrite};
use tokio::sync::mpsc;
use tokio::task::JoinHandle;
use tokio::time::Instant;
use tokio_util::sync::CancellationToken;
use vtol_link::signing::{SigningFileError, SigningKey};
use vtol_link::{Frame, LinkError, LinkEvent, LinkId, LinkOptions, LinkSender, LinkUrl};

use crate::endpoint::{Endpoint, EndpointConfig, LinkKey, Outbound};
use crate::nav::mission;
use crate::nav::params::{ParamFileError, Params};
use crate::shell::clock::{BATCH, ClockMode, SimClock};
use crate::shell::harness::{Call, Harness, Reply, Request};
use crate::shell::signing::{Admit, SetupOutcome, TwinSigning};
use crate::shell::tlog::{TlogError, TlogSink};

pub use crate::shell::signing::signing_file_beside;

/// Capacity of the harness → twin request queue.
const HARNESS_QUEUE: usize = 64;

/// Egress queue per link under lockstep, frames: a client may leave a long advance's
/// telemetry unread for a while (about 15 minutes of sim time at the default rates) before
/// the twin has to wait for it.
pub const LOCKSTEP_QUEUE_LEN: usize = 64 * 1024;

/// Capacity of the transport → twin event queue.
const EVENT_QUEUE: usize = 4096;

/// Default listen address: SITL's SERIAL0, loopback only.
pub const DEFAULT_LISTEN: &str = "tcpin:127.0.0.1:5760";

/// Everything needed to run the twin.
#[derive(Debug, Clone)]
pub struct ServeConfig {
    /// Endpoints to open (may be empty when only [`Twin::attach_stream`] is used).
    pub listen: Vec<LinkUrl>,
    /// Real time, scaled, or as fast as possible.
    pub clock: ClockMode,
    /// The vehicle, its parameters and identity.
    pub endpoint: EndpointConfig,
    /// Queue sizes and timeouts of the links.
    pub link_options: LinkOptions,
    /// Simulated radio: frame loss and latency in each direction.
    pub impairment: Impairment,
    /// The harness channel's listener (`tcpin:` only), if any.
    pub control: Option<LinkUrl>,
    /// The twin's own tlog, if any (created; never overwritten).
    pub tlog: Option<PathBuf>,
    /// MAVLink 2 signing key: with one, the twin signs everything it sends and drops unsigned
    /// frames (except RADIO_STATUS), wrongly signed ones and replays. Its key and timestamp
    /// are kept in [`signing_file_beside`] the parameter file, if there is one; without one the
    /// key saved there (if any) is used. SETUP_SIGNING may change it ([`crate::shell::signing`]).
    pub signing: Option<SigningKey>,
}

/// A lossy, slow radio between the twin and its links, in each direction.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Impairment {
    /// Fraction of frames dropped, 0..1.
    pub loss: f64,
    /// Delay of every frame.
    pub latency: std::time::Duration,
    /// Seed of the loss draws.
    pub seed: u64,
}

impl Default for Impairment {
    fn default() -> Self {
        Self {
            loss: 0.0,
            latency: std::time::Duration::ZERO,
            seed: 1,
        }
    }
}

impl Default for ServeConfig {
    fn default() -> Self {
        Self {
            listen: vec![
                DEFAULT_LISTEN
                    .parse()
                    .unwrap_or_else(|_| unreachable!("valid URL")),
            ],
            clock: ClockMode::REAL_TIME,
            endpoint: EndpointConfig::default(),
            link_options: LinkOptions::default(),
            impairment: Impairment::default(),
            control: None,
            tlog: None,
            signing: None,
        }
    }
}

impl ServeConfig {
    /// Loads the parameter file if one is given (a missing file starts from defaults and is
    /// created on the first change; a corrupt one is an error, never silently replaced), and
    /// the mission saved beside it. A place the file cannot be written to is an error here, at
    /// start, rather than a "save failed" after a PARAM_SET was accepted.
    ///
    /// # Errors
    /// [`ServeError::Params`], [`ServeError::Mission`], [`ServeError::ParamFileNotWritable`].
    pub fn load_param_file(&mut self) -> Result<(), ServeError> {
        if let Some(path) = &self.endpoint.param_file {
            if path.exists() && !path.is_dir() {
                self.endpoint.params = Params::load(path)?;
            }
            crate::atomic_file::check_writable(path).map_err(|source| {
                ServeError::ParamFileNotWritable {
                    path: path.clone(),
                    source,
                }
            })?;
        }
        // The mission lives beside the parameter file, with the same rules.
        if let Some(path) = self
            .endpoint
            .param_file
            .as_deref()
            .map(mission::file_beside)
            && path.exists()
        {
            self.endpoint.mission = mission::Mission::load(&path)?;
        }
        Ok(())
    }
}

/// Why the twin could not start.
#[derive(Debug, thiserror::Error)]
pub enum ServeError {
    /// A transport could not be opened (address in use, bad URL…).
    #[error(transparent)]
    Link(#[from] LinkError),
    /// The parameter file is unusable.
    #[error(transparent)]
    Params(#[from] ParamFileError),
    /// The mission file beside it is unusable.
    #[error(transparent)]
    Mission(#[from] mission::MissionFileError),
    /// The parameter file's place does not take new files (a read-only mount, a path under a
    /// regular file, a directory in its place).
    #[error("--param-file {path} cannot be written: {source}")]
    ParamFileNotWritable {
        /// The file.
        path: PathBuf,
        /// Why not.
        source: std::io::Error,
    },
    /// The tokio runtime could not start.
    #[error("cannot start the runtime: {0}")]
    Runtime(std::io::Error),
    /// The control URL is not a `tcpin:` listener.
    #[error("--control takes a tcpin:HOST:PORT URL, got '{0}'")]
    ControlUrl(String),
    /// The control listener could not bind.
    #[error("cannot open the control listener {url}: {source}")]
    Control {
        /// The URL asked for.
        url: String,
        /// The bind error.
        source: std::io::Error,
    },
    /// The tlog could not be created.
    #[error(transparent)]
    Tlog(#[from] TlogError),
    /// The signing state file beside the parameter file is unusable.
    #[error(transparent)]
    Signing(#[from] SigningFileError),
    /// `--lockstep` with a simulated radio delay, which would make runs differ.
    #[error("--latency cannot be used with --lockstep: the delay runs on the wall clock")]
    LockstepLatency,
}

/// The opened `listen` endpoints of a twin, or the shared ones of a fleet.
pub(crate) struct Listeners {
    /// Where each ended up, in `listen` order.
    pub bound: Vec<Bound>,
    /// Their handles.
    pub endpoints: Vec<vtol_link::EndpointHandle>,
    /// The links that are local: a serial device is the cable, and SETUP_SIGNING is taken on it.
    pub local_links: HashSet<LinkId>,
}

/// Opens every URL in order, sending its link events to `events`; fails at the first that
/// cannot open (the ones already open stop with `cancel`).
pub(crate) async fn open_listeners(
    urls: &[LinkUrl],
    events: &mpsc::Sender<LinkEvent>,
    options: &LinkOptions,
    cancel: &CancellationToken,
) -> Result<Listeners, LinkError> {
    let mut l = Listeners {
        bound: Vec::new(),
        endpoints: Vec::new(),
        local_links: HashSet::new(),
    };
    for url in urls {
        if let LinkUrl::Zenoh { fleet, vehicle } = url {
            return Err(LinkError::Zenoh(format!(
                "{url}: the twin joins a fleet through a daemon: serve it on a local URL and \
                 run `vtol-gcs run --vehicle THAT_URL --serve zenoh:{fleet}/{}`",
                vehicle.as_deref().unwrap_or("VEHICLE")
            )));
        }
        let handle =
            vtol_link::spawn_endpoint(url, events.clone(), options.clone(), cancel.child_token())
                .await?;
        if let (LinkUrl::Serial { .. }, Some(id)) = (url, handle.link_id()) {
            l.local_links.insert(id);
        }
        l.bound.push(Bound {
            url: url.clone(),
            local_addr: handle.local_addr(),
        });
        l.endpoints.push(handle);
    }
    Ok(l)
}

/// One opened endpoint and where it ended up.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Bound {
    /// The URL as configured.
    pub url: LinkUrl,
    /// The bound local address (listeners and udpout), with the real port when 0 was asked.
    pub local_addr: Option<SocketAddr>,
}

impl Bound {
    /// The URL with the real port: what `firmware-sim serve` prints after `listening `.
    #[must_use]
    pub fn resolved_url(&self) -> String {
        let port = self.local_addr.map(|a| a.port());
        match (&self.url, port) {
            (LinkUrl::TcpIn { host, .. }, Some(p)) => format!("tcpin:{}:{p}", bracket(host)),
            (LinkUrl::UdpIn { host, .. }, Some(p)) => format!("udpin:{}:{p}", bracket(host)),
            (url, _) => url.to_string(),
        }
    }
}

fn bracket(host: &str) -> String {
    if host.contains(':') {
        format!("[{host}]")
    } else {
        host.to_owned()
    }
}

/// A running twin.
#[derive(Debug)]
pub struct Twin {
    bound: Vec<Bound>,
    control: Option<SocketAddr>,
    harness: Harness,
    events: mpsc::Sender<LinkEvent>,
    options: LinkOptions,
    cancel: CancellationToken,
    task: JoinHandle<Endpoint>,
    endpoints: Vec<vtol_link::EndpointHandle>,
    control_task: Option<JoinHandle<()>>,
}

impl Twin {
    /// Opens every `listen` endpoint (failing fast if one cannot bind), the control listener
    /// and the tlog, and starts the vehicle loop. Runs until `cancel` fires.
    ///
    /// # Errors
    /// [`ServeError::Link`] for the first endpoint that cannot open; the control listener's
    /// and the tlog's errors; [`ServeError::LockstepLatency`].
    pub async fn start(config: ServeConfig, cancel: CancellationToken) -> Result<Self, ServeError> {
        Self::start_member(config, cancel, HashSet::new()).await
    }

    /// [`Twin::start`] for a member of a fleet, which also hears the fleet's shared endpoints:
    /// `shared_local` are the links among them that are local (serial).
    pub(crate) async fn start_member(
        mut config: ServeConfig,
        cancel: CancellationToken,
        shared_local: HashSet<LinkId>,
    ) -> Result<Self, ServeError> {
        let lockstep = config.clock == ClockMode::Lockstep;
        if lockstep {
            if !config.impairment.latency.is_zero() {
                return Err(ServeError::LockstepLatency);
            }
            config.link_options.queue_len = config.link_options.queue_len.max(LOCKSTEP_QUEUE_LEN);
        }
        let control_addr = match &config.control {
            None => None,
            Some(LinkUrl::TcpIn { host, port }) => Some(format!("{}:{port}", bracket(host))),
            Some(other) => return Err(ServeError::ControlUrl(other.to_string())),
        };
        let tlog = config.tlog.as_deref().map(TlogSink::create).transpose()?;
        let signing = TwinSigning::start(
            config.signing.take(),
            config
                .endpoint
                .param_file
                .as_deref()
                .map(signing_file_beside),
        )?;
        let (calls_tx, calls) = mpsc::channel(HARNESS_QUEUE);
        let harness = Harness::new(calls_tx);
        let (control, control_task) = match control_addr {
            None => (None, None),
            Some(addr) => {
                let (local, task) = crate::shell::harness::spawn_listener(
                    &addr,
                    harness.clone(),
                    cancel.child_token(),
                )
                .await
                .map_err(|source| ServeError::Control { url: addr, source })?;
                (Some(local), Some(task))
            }
        };
        let (events, rx) = mpsc::channel(EVENT_QUEUE);
        let Listeners {
            bound,
            endpoints,
            mut local_links,
        } = match open_listeners(&config.listen, &events, &config.link_options, &cancel).await {
            Ok(l) => l,
            Err(e) => {
                cancel.cancel();
                return Err(e.into());
            }
        };
        local_links.extend(shared_local);
        let shell = Shell {
            endpoint: Endpoint::new(config.endpoint),
            clock: SimClock::new(config.clock, Instant::now()),
            lockstep,
            links: HashMap::new(),
            radio: Radio::new(config.impairment),
            tlog,
            signing,
            local_links,
            reserve: config.link_options.queue_len / 4,
            cancel: cancel.clone(),
        };
        let task = tokio::spawn(shell.run(rx, calls));
        Ok(Self {
            bound,
            control,
            harness,
            events,
            options: config.link_options,
            cancel,
            task,
            endpoints,
            control_task,
        })
    }

    /// The harness channel in process ([`crate::shell::harness`]): advance a lockstep twin, read its
    /// true state, write parameters.
    #[must_use]
    pub fn harness(&self) -> Harness {
        self.harness.clone()
    }

    /// The control listener's URL with its real port, if `control` was asked for: what
    /// `firmware-sim serve` prints after `control `.
    #[must_use]
    pub fn control_url(&self) -> Option<String> {
        self.control
            .map(|a| format!("tcpin:{}:{}", bracket(&a.ip().to_string()), a.port()))
    }

    /// The twin's event queue, for a fleet's shared endpoints ([`crate::shell::fleet`]).
    pub(crate) fn events(&self) -> mpsc::Sender<LinkEvent> {
        self.events.clone()
    }

    /// The opened endpoints, in `listen` order.
    #[must_use]
    pub fn bound(&self) -> &[Bound] {
        &self.bound
    }

    /// Connects the twin to a byte stream (e.g. one end of `tokio::io::duplex`). The link lives
    /// until the stream ends or the twin stops.
    pub fn attach_stream<S>(&self, stream: S, peer: &str) -> LinkId
    where
        S: AsyncRead + AsyncWrite + Send + 'static,
    {
        let (id, _task) = vtol_link::spawn_stream_link(
            stream,
            peer,
            self.events.clone(),
            self.options.clone(),
            self.cancel.child_token(),
        );
        id
    }

    /// Waits for the vehicle loop and every transport to stop (after `cancel`), returning the
    /// endpoint for inspection.
    pub async fn join(self) -> Option<Endpoint> {
        drop(self.events);
        let endpoint = self.task.await.ok();
        for e in self.endpoints {
            e.join().await;
        }
        if let Some(t) = self.control_task {
            let _ = t.await;
        }
        endpoint
    }
}

/// Runs the twin until `cancel` fires: the library form of `firmware-sim serve`.
///
/// # Errors
/// See [`Twin::start`].
pub async fn serve(config: ServeConfig, cancel: CancellationToken) -> Result<(), ServeError> {
    let twin = Twin::start(config, cancel).await?;
    twin.join().await;
    Ok(())
}

struct LinkEntry {
    tx: LinkSender,
    /// Bad frames already reported to the endpoint.
    bad_seen: u64,
    /// Telemetry frames left out because the link was short of room (kept for replies).
    shed: u64,
    /// Replies that found the queue full, oldest first: they go before anything else.
    backlog: std::collections::VecDeque<Frame>,
    /// Replies lost because even the backlog was full (a peer that reads nothing).
    replies_lost: u64,
}

impl LinkEntry {
    fn new(tx: LinkSender) -> Self {
        Self {
            tx,
            bad_seen: 0,
            shed: 0,
            backlog: std::collections::VecDeque::new(),
            replies_lost: 0,
        }
    }

    /// Moves backlogged replies into the queue while it has room.
    fn flush_backlog(&mut self) {
        while self.tx.room() > 0 {
            let Some(f) = self.backlog.pop_front() else {
                return;
            };
            let _ = self.tx.try_send(f);
        }
    }
}

/// Replies a link keeps waiting for room, frames; beyond it a reply is lost (and counted).
const REPLY_BACKLOG: usize = 4096;

/// Sim time one chunk of an `advance` runs before its frames go out, µs: the real-time
/// loop's batch, so a lockstep twin ticks its streams and events as finely as a real-time one.
const ADVANCE_CHUNK_US: u64 = BATCH.as_micros() as u64;

/// The vehicle loop's state: the endpoint, its clock, its links, the radio and the log.
struct Shell {
    endpoint: Endpoint,
    clock: SimClock,
    lockstep: bool,
    links: HashMap<LinkId, LinkEntry>,
    radio: Radio,
    tlog: Option<TlogSink>,
    /// Verifies what comes in and signs what goes out when keyed; handles SETUP_SIGNING.
    signing: TwinSigning,
    /// Links on serial devices, where SETUP_SIGNING is taken unsigned.
    local_links: HashSet<LinkId>,
    /// Free queue places kept for replies: below this, telemetry is shed.
    reserve: usize,
    /// Stops the loop, also while it waits for a lockstep reader.
    cancel: CancellationToken,
}

impl Shell {
    /// The vehicle loop: link events and harness calls are handled as they come; every clock
    /// batch advances the twin to the due sim time and sends what became due.
    async fn run(
        mut self,
        mut events: mpsc::Receiver<LinkEvent>,
        mut calls: mpsc::Receiver<Call>,
    ) -> Endpoint {
        let cancel = self.cancel.clone();
        let mut batch = self.clock.pause().map(|p| {
            let mut i = tokio::time::interval(p);
            i.set_missed_tick_behavior(tokio::time::MissedTickBehavior::Delay);
            i
        });
        let mut calls_open = true;
        loop {
            tokio::select! {
                biased;
                () = cancel.cancelled() => break,
                ev = events.recv() => match ev {
                    Some(ev) => self.on_link_event(ev).await,
                    // Only reachable once every sender is gone; keep flying for attached streams.
                    None => cancel.cancelled().await,
                },
                call = calls.recv(), if calls_open => match call {
                    Some(Call { request, reply }) => {
                        let r = self.on_request(request).await;
                        let _ = reply.send(r);
                    }
                    None => calls_open = false,
                },
                () = next_batch(&mut batch) => {
                    for entry in self.links.values_mut() {
                        entry.flush_backlog();
                    }
                    self.note_bad_frames();
                    self.signing.save_if_due();
                    self.tick().await;
                    if let Some(t) = &mut self.tlog {
                        t.hand_over();
                    }
                }
                () = self.radio.next_due() => {
                    let now = Instant::now();
                    while let Some((way, id, frame, telemetry)) = self.radio.pop_due(now) {
                        match way {
                            Way::In => self.on_frame(id, &frame).await,
                            Way::Out => self.deliver(id, frame, telemetry).await,
                        }
                    }
                }
            }
        }
        if let Some(t) = self.tlog.take() {
            let _ = tokio::task::spawn_blocking(move || t.finish()).await;
        }
        self.signing.finish();
        self.endpoint
    }

    async fn on_link_event(&mut self, ev: LinkEvent) {
        match ev {
            LinkEvent::Up { id, peer, tx } => {
                tracing::info!(%id, %peer, "link up");
                self.links.insert(id, LinkEntry::new(tx));
                self.endpoint.add_link(key(id));
                // The first frames (HEARTBEAT and every stream) go out now, not a batch later.
                self.tick().await;
            }
            LinkEvent::Frame { id, frame } => {
                if let Some(frame) = self.radio.pass(Way::In, id, frame, false) {
                    self.on_frame(id, &frame).await;
                }
            }
            LinkEvent::Down { id, reason } => {
                let (shed, replies_lost) = self
                    .links
                    .remove(&id)
                    .map_or((0, 0), |e| (e.shed, e.replies_lost));
                tracing::info!(%id, %reason, shed, replies_lost, "link down");
                self.endpoint.remove_link(key(id));
            }
        }
    }

    /// The time a tlog record carries: sim time under lockstep (the same on every run), Unix
    /// time otherwise.
    fn stamp_us(&self) -> u64 {
        if self.lockstep {
            self.endpoint.now_us()
        } else {
            crate::shell::tlog::unix_now_us()
        }
    }

    async fn on_frame(&mut self, id: LinkId, frame: &Frame) {
        // A keyed twin takes only rightly signed, fresh frames (and unsigned RADIO_STATUS):
        // anything else changes nothing and gets no answer. SETUP_SIGNING stops here, whatever
        // becomes of it: it carries a key, so neither the vehicle nor the tlog sees it.
        let local = self.local_links.contains(&id);
        let sysid = self.endpoint.sysid();
        match self
            .signing
            .admit(frame, local, sysid, std::time::SystemTime::now())
        {
            Admit::Pass => {}
            Admit::Refused(refusal) => {
                tracing::debug!(%id, %refusal, "frame refused");
                return;
            }
            Admit::SetupSigning(outcome) => {
                match outcome {
                    SetupOutcome::Keyed => {
                        tracing::info!(%id, "signing: new key from SETUP_SIGNING")
                    }
                    SetupOutcome::Disabled => {
                        tracing::info!(%id, "signing: switched off by SETUP_SIGNING")
                    }
                    SetupOutcome::Refused => tracing::warn!(
                        %id,
                        local,
                        "SETUP_SIGNING refused: not signed with the current key and not on a local (serial) link"
                    ),
                    SetupOutcome::NotForUs => {}
                }
                return;
            }
        }
        if self.tlog.is_some() {
            let stamp = self.stamp_us();
            if let Some(t) = &mut self.tlog {
                t.record(stamp, false, frame.as_bytes());
            }
        }
        let out = self.endpoint.handle(key(id), frame);
        self.dispatch(out).await;
        self.settle().await;
    }

    /// Lockstep: sends at once whatever the last event made due at the sim time standing (a
    /// message whose interval was just set, an event's text), so it follows its cause the same
    /// way on every run rather than whenever the next batch wakes.
    async fn settle(&mut self) {
        if self.lockstep {
            let now = self.endpoint.now_us();
            let out = self.endpoint.tick_at(now, now);
            self.dispatch(out).await;
        }
    }

    fn note_bad_frames(&mut self) {
        for entry in self.links.values_mut() {
            let s = entry.tx.stats().snapshot();
            let bad = s.bad_crc + s.bad_incompat;
            self.endpoint
                .note_bad_frames(bad.saturating_sub(entry.bad_seen));
            entry.bad_seen = bad;
        }
    }

    /// Runs the twin to the sim time the clock says is due and sends what became due.
    async fn tick(&mut self) {
        let now = Instant::now();
        let sim_us = self.clock.due_sim_us(now);
        let stream_us = self.clock.stream_us(now);
        let out = self.endpoint.tick_at(sim_us, stream_us);
        self.dispatch(out).await;
    }

    async fn on_request(&mut self, request: Request) -> Reply {
        match request {
            Request::Advance { seconds } => self.advance(seconds).await,
            Request::State => Reply::State(crate::shell::harness::TrueState::of(
                self.endpoint.vehicle().telemetry(),
            )),
            Request::Param { name, value } => {
                let r = self.endpoint.set_param_announced(&name, value);
                let out = self.endpoint.take_outbound();
                self.dispatch(out).await;
                self.settle().await;
                match r {
                    Ok(value) => Reply::Param { name, value },
                    Err(e) => Reply::Error(e.to_string()),
                }
            }
        }
    }

    /// Lockstep: flies `seconds` more of sim time in chunks, sending each chunk's frames
    /// (waiting for room, never dropping) before the next.
    async fn advance(&mut self, seconds: f64) -> Reply {
        if !self.lockstep {
            return Reply::Error(
                "advance needs a lockstep twin (firmware-sim serve --lockstep)".into(),
            );
        }
        let step_us = crate::model::vehicle::PHYSICS_DT_US;
        let target =
            self.endpoint.now_us() + (seconds * 1e6 / step_us as f64).round() as u64 * step_us;
        while self.endpoint.now_us() < target && !self.cancel.is_cancelled() {
            let next = (self.endpoint.now_us() + ADVANCE_CHUNK_US).min(target);
            self.clock.advance_to(next);
            let out = self.endpoint.tick_at(next, next);
            self.dispatch(out).await;
            // A long advance still lets the links' writers and other tasks run.
            tokio::task::consume_budget().await;
        }
        if let Some(t) = &mut self.tlog {
            t.hand_over();
        }
        Reply::Time(self.endpoint.now_us())
    }

    async fn dispatch(&mut self, out: Vec<Outbound>) {
        if out.is_empty() {
            return;
        }
        let stamp = self.stamp_us();
        for o in out {
            let id = LinkId(o.link.0 as u32);
            let f = match self.signing.outgoing(o.frame, std::time::SystemTime::now()) {
                Ok(f) => f,
                Err(e) => {
                    tracing::error!("cannot sign an outgoing frame: {e}");
                    continue;
                }
            };
            if let Some(t) = &mut self.tlog {
                t.record(stamp, true, f.as_bytes());
            }
            if let Some(f) = self.radio.pass(Way::Out, id, f, o.telemetry) {
                self.deliver(id, f, o.telemetry).await;
            }
        }
    }

    /// Queues a frame on its link. Under lockstep it waits for room (nothing is lost, the run
    /// stays the same). Otherwise the vehicle never waits for one slow peer: a link short of
    /// room sheds telemetry, keeping its last places for replies, and a reply that finds the
    /// queue full waits in the link's backlog, in order, for the next batch.
    async fn deliver(&mut self, id: LinkId, frame: Frame, telemetry: bool) {
        let Some(entry) = self.links.get_mut(&id) else {
            return;
        };
        if self.lockstep {
            // Waits for the reader, but not past a shutdown.
            tokio::select! {
                _ = entry.tx.send(frame) => {}
                () = self.cancel.cancelled() => {}
            }
            return;
        }
        // This loop is the queue's only producer, so room seen here is room at the send.
        if telemetry {
            if entry.backlog.is_empty() && entry.tx.room() > self.reserve {
                let _ = entry.tx.try_send(frame);
            } else {
                entry.shed += 1;
            }
            return;
        }
        entry.flush_backlog();
        if entry.backlog.is_empty() && entry.tx.room() > 0 {
            let _ = entry.tx.try_send(frame);
        } else if entry.backlog.len() < REPLY_BACKLOG {
            entry.backlog.push_back(frame);
        } else {
            entry.replies_lost += 1;
        }
    }
}

/// Which way a frame goes through the simulated radio.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Way {
    In,
    Out,
}

/// The simulated radio: seeded loss, then a fixed delay (a FIFO, since every frame waits the
/// same time).
struct Radio {
    imp: Impairment,
    rng: rand_chacha::ChaCha8Rng,
    delayed: std::collections::VecDeque<(Instant, Way, LinkId, Frame, bool)>,
}

impl Radio {
    fn new(imp: Impairment) -> Self {
        use rand::SeedableRng as _;
        Self {
            imp,
            rng: rand_chacha::ChaCha8Rng::seed_from_u64(imp.seed),
            delayed: std::collections::VecDeque::new(),
        }
    }

    /// The frame if it goes through now; `None` if lost or delayed (`telemetry` travels with a
    /// delayed frame).
    fn pass(&mut self, way: Way, id: LinkId, frame: Frame, telemetry: bool) -> Option<Frame> {
        use rand::Rng as _;
        if self.imp.loss > 0.0 && self.rng.random_bool(self.imp.loss) {
            return None;
        }
        if self.imp.latency.is_zero() {
            return Some(frame);
        }
        let due = Instant::now() + self.imp.latency;
        self.delayed.push_back((due, way, id, frame, telemetry));
        None
    }

    async fn next_due(&self) {
        match self.delayed.front() {
            Some((due, ..)) => tokio::time::sleep_until(*due).await,
            None => std::future::pending().await,
        }
    }

    fn pop_due(&mut self, now: Instant) -> Option<(Way, LinkId, Frame, bool)> {
        if self.delayed.front()?.0 > now {
            return None;
        }
        self.delayed
            .pop_front()
            .map(|(_, w, id, f, t)| (w, id, f, t))
    }
}

async fn next_batch(batch: &mut Option<tokio::time::Interval>) {
    match batch {
        Some(i) => {
            i.tick().await;
        }
        // As fast as possible: still yield so link events get their turn.
        None => tokio::task::yield_now().await,
    }
}

fn key(id: LinkId) -> LinkKey {
    LinkKey(u64::from(id.0))
}
