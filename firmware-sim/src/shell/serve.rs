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
use vtol_link::{LinkError, LinkEvent, LinkId, LinkOptions, LinkUrl};

use crate::endpoint::{Endpoint, EndpointConfig};
use crate::nav::mission;
use crate::nav::params::{ParamFileError, Params};
use crate::shell::clock::{ClockMode, SimClock};
use crate::shell::harness::Harness;
pub use crate::shell::radio::Impairment;
use crate::shell::radio::Radio;
use crate::shell::signing::TwinSigning;
use crate::shell::tlog::{TlogError, TlogSink};
use crate::shell::vehicle_loop::Shell;

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
            vtol_link::text_file::check_writable(path).map_err(|source| {
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
    // Long: the twin's start-up in order (clock, control port, tlog, signing, harness, listeners,
    // shell task), each step's result feeding the shell built at the end.
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
        // A twin given its system id (`--sysid`, a fleet member) reports it everywhere, its
        // SYSID_THISMAV parameter included.
        if let Some(sysid) = config.endpoint.sysid {
            let _ = config
                .endpoint
                .params
                .set_internal("SYSID_THISMAV", f64::from(sysid));
        }
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
