//! `vtol-gcs run`: wires the links, the router, the tlog writer, the vehicle tracker and the
//! daemon's own client, and runs them until the cancellation token fires (Ctrl-C or SIGTERM in
//! the binary). On the way out the tlog is flushed and closed. Nothing here prints: the binary
//! owns the terminal (status lines or the terminal UI) and reads what it shows from [`Running`].

use std::net::SocketAddr;
use std::path::PathBuf;
use std::sync::Arc;

use firmware_sim::shell::serve::{ServeConfig, Twin};
use tokio::sync::watch;
use tokio::task::JoinSet;
use tokio_util::sync::CancellationToken;
use vtol_link::{Events, LinkOptions, LinkUrl, ZenohRole, spawn_endpoint, spawn_stream_link};

use crate::client::ClientHandle;
use crate::client::own_traffic;
use crate::config::{Config, VehicleSource};
use crate::links::{RouterHandle, Side};
use crate::router::{Router, SharedRouter};
use crate::tlog::TlogHandle;
use crate::tlog::TlogStats;
use crate::tracker;
use crate::tracker::{SharedHistory, VehicleState};
use crate::trust::policy::{EndpointPolicy, Trust};
use crate::trust::signing::{DaemonSigning, SAVE_EVERY, default_state_file, system_clock};

/// Frames buffered for the tracker, which takes them on its tick or every
/// [`tracker::TAP_RUN`] frames; a drop only loses a display update.
const TAP_QUEUE: usize = 8192;
/// Records waiting for the tlog writer thread at most (it writes every 50 ms).
const TLOG_QUEUE: usize = 65_536;
/// In-memory link buffer between the daemon and the embedded twin or its own heartbeat.
const DUPLEX_BYTES: usize = 256 * 1024;

/// Errors that stop the daemon from starting.
#[derive(Debug, thiserror::Error)]
pub enum DaemonError {
    /// A link could not be opened (address in use, bad host …).
    #[error("cannot open {url}: {source}")]
    Link {
        /// The URL.
        url: LinkUrl,
        /// The cause.
        source: vtol_link::LinkError,
    },
    /// The log could not be created.
    #[error(transparent)]
    Tlog(#[from] crate::tlog::TlogError),
    /// A `trust=sign` endpoint without a signing key.
    #[error(
        "serve URL '{url}' asks for trust=sign but the daemon has no signing key (give --signing-passphrase or --signing-key-file)"
    )]
    SignWithoutKey {
        /// The endpoint.
        url: String,
    },
    /// The signing state file cannot be used (unreadable, broken, or not writable).
    #[error(transparent)]
    SigningState(#[from] vtol_link::SigningFileError),
    /// Signing is on, no `--signing-state` was given and neither `XDG_STATE_HOME` nor `HOME`
    /// is set.
    #[error("no place for the signing state file: give --signing-state FILE")]
    NoSigningState,
    /// The default state directory cannot be created.
    #[error("cannot create {}: {source}", path.display())]
    StateDir {
        /// The directory.
        path: PathBuf,
        /// The cause.
        source: std::io::Error,
    },
    /// The log to replay could not be opened.
    #[error("cannot open {path} for replay: {source}")]
    Replay {
        /// The file.
        path: PathBuf,
        /// The cause.
        source: std::io::Error,
    },
}

/// What a running daemon exposes (to the status line, the UI and tests).
#[derive(Debug, Clone)]
pub struct Running {
    /// The daemon's own MAVLink client (commands, parameters, the operator heartbeat).
    pub client: ClientHandle,
    /// Live tlog counters, if logging.
    pub tlog_stats: Option<std::sync::Arc<TlogStats>>,
    /// Where a `--vehicle` URL that listens ended up (the real port when 0 was asked for).
    pub vehicle_addr: Option<SocketAddr>,
    /// Where each serve URL ended up (the real port when 0 was asked for), with its policy.
    pub serving: Vec<(LinkUrl, Option<SocketAddr>, EndpointPolicy)>,
    /// The signing state file, when signing.
    pub signing_state: Option<PathBuf>,
    /// The tlog file, if logging.
    pub tlog_path: Option<PathBuf>,
    /// Latest vehicle and link state (shared: a reader borrows it, never copies it).
    pub state: watch::Receiver<Arc<VehicleState>>,
    /// Router counters and live links.
    pub router: RouterHandle,
    /// The recent past, for charts.
    pub history: SharedHistory,
    /// The daemon's parameter downloads (`fetch_params`: at first contact and after reboots).
    pub param_fetches: std::sync::Arc<crate::reboot::ParamFetches>,
    /// The vehicle link as the stream fit measured it ([`crate::fit`]).
    pub link_fit: watch::Receiver<Option<crate::stream_fit::LinkFit>>,
}

/// Peer name of the daemon's own-traffic link (its client: heartbeat, commands, parameters):
/// the UI and the status line do not count it as a client.
pub const OWN_TRAFFIC_PEER: &str = "vtol-gcs (own traffic)";

/// Peer name of the vehicle link of a replayed log: the UI offers no commands on it.
pub const REPLAY_PEER: &str = "replay";

/// Formats a served endpoint with its bound address, e.g. `tcpin:127.0.0.1:43121`.
#[must_use]
pub fn describe(url: &LinkUrl, addr: Option<SocketAddr>) -> String {
    match (url, addr) {
        (LinkUrl::TcpIn { .. }, Some(a)) => format!("tcpin:{a}"),
        (LinkUrl::UdpIn { .. }, Some(a)) => format!("udpin:{a}"),
        _ => url.to_string(),
    }
}

/// Starts every part of the daemon. Returns once all endpoints are bound; the tasks run on in
/// `tasks` until `cancel` fires.
///
/// # Errors
/// A serve or vehicle endpoint that cannot be opened, or a log that cannot be created.
pub async fn start(
    config: &Config,
    cancel: &CancellationToken,
    tasks: &mut JoinSet<()>,
) -> Result<Running, DaemonError> {
    let signing = open_signing(config)?;
    let signing_state = signing
        .as_ref()
        .and_then(|s| s.file().map(std::path::Path::to_owned));
    let tlog = match &config.log_dir {
        Some(dir) => Some(TlogHandle::start(dir, TLOG_QUEUE)?),
        None => None,
    };
    let tlog_path = tlog.as_ref().map(|t| t.path.clone());
    let tlog_stats = tlog.as_ref().map(|t| std::sync::Arc::clone(&t.stats));

    let (tap_tx, tap_rx) = crate::tap::tap(TAP_QUEUE, tracker::TAP_RUN);
    let (state_tx, state_rx) = watch::channel(Arc::new(VehicleState::default()));
    let (router, router_handle) = start_router(tlog, tap_tx, signing, cancel, tasks);
    let history: SharedHistory = std::sync::Arc::new(std::sync::Mutex::new(
        crate::tracker::History::new(crate::tracker::now()),
    ));
    tasks.spawn(tracker::run(
        config.tracker_period,
        tap_rx,
        router_handle.links.clone(),
        state_tx,
        std::sync::Arc::clone(&history),
        cancel.clone(),
    ));

    // Clients first, so nothing the vehicle says at start-up is missed by a waiting client.
    let serving = serve(config, &router, cancel, tasks).await?;
    let client = attach_own_client(config, &router, cancel, tasks);
    let vehicle_addr = open_vehicle(config, &router, &client, &state_rx, cancel, tasks).await?;

    let param_fetches = std::sync::Arc::new(crate::reboot::ParamFetches::default());
    tasks.spawn(crate::reboot::watch(
        state_rx.clone(),
        client.clone(),
        config.fetch_params,
        std::sync::Arc::clone(&param_fetches),
        cancel.clone(),
    ));

    // A replayed log takes no requests: nothing to fit.
    let (fit_tx, link_fit) = watch::channel(None);
    if !matches!(config.vehicle, VehicleSource::Replay(_)) {
        // The home position and the VTOL state, asked for when the vehicle does not send them.
        tasks.spawn(crate::client::interval::ask_on_connect(
            state_rx.clone(),
            client.clone(),
            cancel.clone(),
        ));
        tasks.spawn(crate::stream_fit::run(
            state_rx.clone(),
            client.clone(),
            fit_tx,
            cancel.clone(),
        ));
    }

    Ok(Running {
        link_fit,
        client,
        param_fetches,
        tlog_stats,
        vehicle_addr,
        serving,
        signing_state,
        tlog_path,
        state: state_rx,
        router: router_handle,
        history,
    })
}

/// The daemon's signing, when it has a key: its state file (the default one, its directory
/// created, unless one is given) and whether the vehicle's signatures are checked.
fn open_signing(config: &Config) -> Result<Option<DaemonSigning>, DaemonError> {
    for spec in &config.serve {
        if spec.policy.trust == Trust::Sign && config.signing.is_none() {
            return Err(DaemonError::SignWithoutKey {
                url: spec.to_string(),
            });
        }
    }
    let signing = match &config.signing {
        Some(key) => {
            let file = match &config.signing_state {
                Some(f) => f.clone(),
                None => {
                    let f = default_state_file().ok_or(DaemonError::NoSigningState)?;
                    if let Some(dir) = f.parent() {
                        std::fs::create_dir_all(dir).map_err(|source| DaemonError::StateDir {
                            path: dir.to_owned(),
                            source,
                        })?;
                    }
                    f
                }
            };
            // A replayed log is old by nature: its signatures are not checked.
            let verify = !matches!(config.vehicle, VehicleSource::Replay(_));
            Some(DaemonSigning::start(
                key.clone(),
                Some(file),
                verify,
                system_clock(),
            )?)
        }
        None => None,
    };
    Ok(signing)
}

/// The router shared by the link tasks, with the daemon's key when it has one.
fn inline_router(
    tlog: Option<TlogHandle>,
    tap: Option<crate::tap::TapSender>,
    signing: Option<DaemonSigning>,
) -> (SharedRouter, RouterHandle) {
    // The hot path: each link task routes what it receives itself (no router task, no queue
    // between a link and the router).
    let (mut router, mut router_handle) = Router::new(tlog, tap);
    if let Some(s) = signing {
        router_handle.signing = Some(router.set_signing(s));
    }
    (router.share(), router_handle)
}

/// The daemon's router without the rest of the daemon (no tracker, no client): links handed
/// its [`Routing::events`] are routed, logged and signed as in `vtol-gcs run`. For tests and
/// tools that drive links themselves; the router itself stays inside the daemon.
#[derive(Debug, Clone)]
pub struct Routing {
    router: SharedRouter,
}

impl Routing {
    /// A router that logs to `tlog` (if any) and, with `signing`, checks the vehicle's
    /// signatures and signs for `sign` links. Returns its counters and live links too.
    #[must_use]
    pub fn new(tlog: Option<TlogHandle>, signing: Option<DaemonSigning>) -> (Self, RouterHandle) {
        let (router, handle) = inline_router(tlog, None, signing);
        (Self { router }, handle)
    }

    /// Where the links of `side` report.
    #[must_use]
    pub fn events(&self, side: Side) -> Events {
        self.router.events(side)
    }

    /// Where the links of one endpoint report: each link it opens carries `policy`.
    #[must_use]
    pub fn events_with(&self, side: Side, policy: EndpointPolicy) -> Events {
        self.router.events_with(side, policy)
    }

    /// Stops routing: later events are refused (their links stop), what the last run routed
    /// is sent, and the tlog is closed.
    pub fn close(&self) {
        self.router.close();
    }
}

/// The router, shared by the link tasks, with its tasks: closing it at shutdown (the tlog
/// flushed), and saving the signing state every [`SAVE_EVERY`].
fn start_router(
    tlog: Option<TlogHandle>,
    tap: crate::tap::TapSender,
    signing: Option<DaemonSigning>,
    cancel: &CancellationToken,
    tasks: &mut JoinSet<()>,
) -> (SharedRouter, RouterHandle) {
    let (router, router_handle) = inline_router(tlog, Some(tap), signing);
    {
        let (router, cancel) = (router.clone(), cancel.clone());
        tasks.spawn(async move {
            cancel.cancelled().await;
            // Later frames are refused; the tlog is flushed and closed.
            router.close();
        });
    }
    if router_handle.signing.is_some() {
        let (router, cancel) = (router.clone(), cancel.clone());
        tasks.spawn(async move {
            let mut every = tokio::time::interval(SAVE_EVERY);
            every.tick().await;
            loop {
                tokio::select! {
                    () = cancel.cancelled() => return,
                    _ = every.tick() => router.save_signing(),
                }
            }
        });
    }
    (router, router_handle)
}

/// Opens the serve endpoints: where each ended up, with its policy.
async fn serve(
    config: &Config,
    router: &SharedRouter,
    cancel: &CancellationToken,
    tasks: &mut JoinSet<()>,
) -> Result<Vec<(LinkUrl, Option<SocketAddr>, EndpointPolicy)>, DaemonError> {
    let mut serving = Vec::new();
    for spec in &config.serve {
        let events = router.events_with(Side::Client, spec.policy);
        // A zenoh: serve URL is this vehicle's end of a fleet.
        let mut opts = config.link.clone();
        opts.zenoh.role = ZenohRole::Vehicle;
        let h = spawn_endpoint(&spec.url, events, opts, cancel.clone())
            .await
            .map_err(|source| DaemonError::Link {
                url: spec.url.clone(),
                source,
            })?;
        serving.push((spec.url.clone(), h.local_addr(), spec.policy));
        tasks.spawn(h.join());
    }
    Ok(serving)
}

/// The daemon's own client (heartbeat, commands, parameters) on an in-memory link.
fn attach_own_client(
    config: &Config,
    router: &SharedRouter,
    cancel: &CancellationToken,
    tasks: &mut JoinSet<()>,
) -> ClientHandle {
    let (gcs_end, router_end) = tokio::io::duplex(DUPLEX_BYTES);
    let client = own_traffic::attach(
        gcs_end,
        config.system_id,
        config.component_id,
        cancel.clone(),
    );
    // The own-traffic link carries only what the client reads: the vehicle's telemetry at
    // thousands of frames a second would otherwise cross two tasks and be parsed twice to be
    // thrown away. With a key the router signs the client's frames (the link's trust is
    // `sign`), with the same timestamp source as every other frame the daemon signs.
    let own_policy = EndpointPolicy {
        trust: if config.signing.is_some() {
            Trust::Sign
        } else {
            Trust::Trusted
        },
        rate: None,
    };
    let (_, link_task) = spawn_stream_link(
        router_end,
        OWN_TRAFFIC_PEER,
        router.events_with(Side::Client, own_policy),
        LinkOptions {
            accept: Some(client.read_filter()),
            ..config.link.clone()
        },
        cancel.clone(),
    );
    tasks.spawn(async move {
        let _ = link_task.await;
    });
    client
}

/// Opens the vehicle side: the embedded twin, a replayed log or a URL. Returns where a vehicle
/// URL that listens ended up.
async fn open_vehicle(
    config: &Config,
    router: &SharedRouter,
    client: &ClientHandle,
    state: &watch::Receiver<Arc<VehicleState>>,
    cancel: &CancellationToken,
    tasks: &mut JoinSet<()>,
) -> Result<Option<SocketAddr>, DaemonError> {
    let vehicle_tx = router.events(Side::Vehicle);
    let mut vehicle_addr = None;
    match &config.vehicle {
        VehicleSource::Embedded => {
            let (twin_end, router_end) = tokio::io::duplex(DUPLEX_BYTES);
            let (_, link_task) = spawn_stream_link(
                router_end,
                "embedded twin",
                vehicle_tx,
                config.link.clone(),
                cancel.clone(),
            );
            tasks.spawn(async move {
                let _ = link_task.await;
            });
            tasks.spawn(embedded_twin(
                twin_end,
                config.signing.clone(),
                cancel.clone(),
            ));
        }
        VehicleSource::Replay(replay) => {
            let reader = replay.open().map_err(|source| DaemonError::Replay {
                path: replay.path.clone(),
                source,
            })?;
            let (log_end, router_end) = tokio::io::duplex(DUPLEX_BYTES);
            let (_, link_task) = spawn_stream_link(
                router_end,
                REPLAY_PEER,
                vehicle_tx,
                config.link.clone(),
                cancel.clone(),
            );
            tasks.spawn(async move {
                let _ = link_task.await;
            });
            let (path, speed, cancel) = (replay.path.clone(), replay.speed, cancel.clone());
            tasks.spawn(async move {
                crate::log::replay::run(reader, &path, speed, log_end, cancel).await;
            });
        }
        VehicleSource::Url(url) => {
            // A zenoh: vehicle URL is the ground end of a fleet: each vehicle its own link.
            let mut opts = config.link.clone();
            opts.zenoh.role = ZenohRole::Ground;
            // A vehicle back from a new address is the same vehicle, not a second one.
            opts.udp_follow_system = true;
            let h = spawn_endpoint(url, vehicle_tx, opts, cancel.clone())
                .await
                .map_err(|source| DaemonError::Link {
                    url: url.clone(),
                    source,
                })?;
            vehicle_addr = h.local_addr();
            tasks.spawn(h.join());
            if matches!(url, LinkUrl::UdpOut { .. }) {
                tasks.spawn(udpout_hello(client.clone(), state.clone(), cancel.clone()));
            }
        }
    }
    Ok(vehicle_addr)
}

/// How often the daemon speaks first on a `udpout` vehicle link while no vehicle is heard.
const HELLO_EVERY: std::time::Duration = std::time::Duration::from_secs(1);

/// Speaks first on a `udpout` vehicle link: a vehicle listening on `udpin` learns where to send
/// only from what it hears. While no vehicle is heard (at start, and after a vehicle restart
/// that forgot its peer) the daemon's client sends [`crate::client::hello`] once a second:
/// a TIMESYNC request, not a heartbeat, so it never arms or feeds the vehicle's GCS-loss
/// failsafe (ArduPilot and the twin count any HEARTBEAT from SYSID_MYGCS as the operator's).
async fn udpout_hello(
    client: ClientHandle,
    state: watch::Receiver<Arc<VehicleState>>,
    cancel: CancellationToken,
) {
    let mut every = tokio::time::interval(HELLO_EVERY);
    loop {
        tokio::select! {
            () = cancel.cancelled() => return,
            _ = every.tick() => {}
        }
        let now = tracker::now();
        let heard = state.borrow().vehicles.values().any(|v| !v.is_lost(now));
        if !heard && client.send(crate::client::hello()).await.is_err() {
            return;
        }
    }
}

/// Runs the twin inside the daemon on one end of an in-memory byte link.
/// With a key the twin is keyed too (no parameter file, so nothing is persisted: its
/// timestamps follow the wall clock).
async fn embedded_twin(
    stream: tokio::io::DuplexStream,
    signing: Option<vtol_link::SigningKey>,
    cancel: CancellationToken,
) {
    let config = ServeConfig {
        listen: Vec::new(),
        signing,
        ..ServeConfig::default()
    };
    match Twin::start(config, cancel).await {
        Ok(twin) => {
            twin.attach_stream(stream, "vtol-gcs");
            twin.join().await;
        }
        Err(e) => tracing::error!("embedded twin did not start: {e}"),
    }
}

/// Runs the daemon until `cancel` fires, then waits for every task (the tlog is flushed).
///
/// # Errors
/// See [`start`].
pub async fn run(config: Config, cancel: CancellationToken) -> Result<(), DaemonError> {
    let mut tasks = JoinSet::new();
    start(&config, &cancel, &mut tasks).await?;
    cancel.cancelled().await;
    while tasks.join_next().await.is_some() {}
    Ok(())
}
