//! The twin as a running MAVLink vehicle: transports from `vtol-link`, a sim clock, and the
//! [`Endpoint`] state machine, wired in one task.
//!
//! # Command line (stable; scripts and the pytest suite rely on it)
//!
//! ```text
//! firmware-sim serve [--listen URL]... [--speed N | --fast] [--param-file FILE] [--seed N]
//!                    [--model paper|physical] [--ideal-sensors] [--sysid N]
//!                    [--loss FRACTION] [--latency MS]
//! ```
//!
//! - `--listen URL`, repeatable, default `tcpin:127.0.0.1:5760` (SITL's SERIAL0): `tcpin:` accepts
//!   many clients and re-accepts; `udpin:` replies to every peer heard; `udpout:` sends at once;
//!   `tcp:` and `serial:` connect out.
//! - After every endpoint is bound, one line per `--listen` is printed on stdout, in order:
//!   `listening <url>` where `<url>` carries the real bound port (so `tcpin:127.0.0.1:0` prints
//!   e.g. `listening tcpin:127.0.0.1:40121`). Connect-out URLs print as given. Then stdout is
//!   flushed; logs go to stderr.
//! - `--loss FRACTION` drops that fraction of frames in each direction, drawn from a generator
//!   seeded by `--seed`; `--latency MS` delays every frame by that much in each direction. A
//!   lossy radio is then tested with real frames, retries and all.
//! - `--param-file FILE`: the parameters, and the mission beside them (`FILE` with the
//!   `.waypoints` extension, QGC WPL 110), loaded at start and saved on every change.
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
//! the twin without a socket.
//!
//! ```no_run
//! # async fn demo() -> Result<(), firmware_sim::serve::ServeError> {
//! use firmware_sim::serve::{ServeConfig, Twin};
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

use std::collections::HashMap;
use std::net::SocketAddr;
use std::time::Instant;

use tokio::io::{AsyncRead, AsyncWrite};
use tokio::sync::mpsc;
use tokio::task::JoinHandle;
use tokio_util::sync::CancellationToken;
use vtol_link::{Frame, LinkError, LinkEvent, LinkId, LinkOptions, LinkSender, LinkUrl};

use crate::clock::{ClockMode, SimClock};
use crate::endpoint::{Endpoint, EndpointConfig, LinkKey, Outbound};
use crate::mission;
use crate::params::{ParamFileError, Params};

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
        }
    }
}

impl ServeConfig {
    /// Loads the parameter file if one is given (a missing file starts from defaults and is
    /// created on the first change; a corrupt one is an error, never silently replaced), and
    /// the mission saved beside it.
    ///
    /// # Errors
    /// [`ServeError::Params`].
    pub fn load_param_file(&mut self) -> Result<(), ServeError> {
        if let Some(path) = &self.endpoint.param_file
            && path.exists()
        {
            self.endpoint.params = Params::load(path)?;
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
    /// The tokio runtime could not start.
    #[error("cannot start the runtime: {0}")]
    Runtime(std::io::Error),
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
    events: mpsc::Sender<LinkEvent>,
    options: LinkOptions,
    cancel: CancellationToken,
    task: JoinHandle<Endpoint>,
    endpoints: Vec<vtol_link::EndpointHandle>,
}

impl Twin {
    /// Opens every `listen` endpoint (failing fast if one cannot bind) and starts the vehicle
    /// loop. Runs until `cancel` fires.
    ///
    /// # Errors
    /// [`ServeError::Link`] for the first endpoint that cannot open.
    pub async fn start(config: ServeConfig, cancel: CancellationToken) -> Result<Self, ServeError> {
        let (events, rx) = mpsc::channel(EVENT_QUEUE);
        let mut bound = Vec::new();
        let mut endpoints = Vec::new();
        for url in &config.listen {
            let handle = vtol_link::spawn_endpoint(
                url,
                events.clone(),
                config.link_options.clone(),
                cancel.child_token(),
            )
            .await;
            let handle = match handle {
                Ok(h) => h,
                Err(e) => {
                    cancel.cancel();
                    return Err(e.into());
                }
            };
            bound.push(Bound {
                url: url.clone(),
                local_addr: handle.local_addr(),
            });
            endpoints.push(handle);
        }
        let endpoint = Endpoint::new(config.endpoint);
        let radio = Radio::new(config.impairment);
        let task = tokio::spawn(run(endpoint, config.clock, radio, rx, cancel.clone()));
        Ok(Self {
            bound,
            events,
            options: config.link_options,
            cancel,
            task,
            endpoints,
        })
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
}

/// The vehicle loop: link events are handled as they come; every clock batch advances the
/// twin to the due sim time and sends what became due.
async fn run(
    mut endpoint: Endpoint,
    mode: ClockMode,
    mut radio: Radio,
    mut events: mpsc::Receiver<LinkEvent>,
    cancel: CancellationToken,
) -> Endpoint {
    let mut clock = SimClock::new(mode, Instant::now());
    let mut links: HashMap<LinkId, LinkEntry> = HashMap::new();
    let mut batch = clock.pause().map(|p| {
        let mut i = tokio::time::interval(p);
        i.set_missed_tick_behavior(tokio::time::MissedTickBehavior::Delay);
        i
    });
    loop {
        tokio::select! {
            biased;
            () = cancel.cancelled() => break,
            ev = events.recv() => match ev {
                Some(LinkEvent::Up { id, peer, tx }) => {
                    tracing::info!(%id, %peer, "link up");
                    links.insert(id, LinkEntry { tx, bad_seen: 0 });
                    endpoint.add_link(key(id));
                }
                Some(LinkEvent::Frame { id, frame }) => {
                    if let Some(frame) = radio.pass(Way::In, id, frame) {
                        let out = endpoint.handle(key(id), frame.as_bytes());
                        dispatch(&links, &mut radio, out);
                    }
                }
                Some(LinkEvent::Down { id, reason }) => {
                    tracing::info!(%id, %reason, "link down");
                    links.remove(&id);
                    endpoint.remove_link(key(id));
                }
                // Only reachable once every sender is gone; keep flying for attached streams.
                None => cancel.cancelled().await,
            },
            () = next_batch(&mut batch) => {
                for entry in links.values_mut() {
                    let s = entry.tx.stats().snapshot();
                    let bad = s.bad_crc + s.bad_incompat;
                    endpoint.note_bad_frames(bad.saturating_sub(entry.bad_seen));
                    entry.bad_seen = bad;
                }
                let due = clock.due_sim_us(Instant::now());
                let out = endpoint.tick(due);
                dispatch(&links, &mut radio, out);
            }
            () = radio.next_due() => {
                let now = tokio::time::Instant::now();
                while let Some((way, id, frame)) = radio.pop_due(now) {
                    match way {
                        Way::In => {
                            let out = endpoint.handle(key(id), frame.as_bytes());
                            dispatch(&links, &mut radio, out);
                        }
                        Way::Out => send_now(&links, id, frame),
                    }
                }
            }
        }
    }
    endpoint
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
    delayed: std::collections::VecDeque<(tokio::time::Instant, Way, LinkId, Frame)>,
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

    /// The frame if it goes through now; `None` if lost or delayed.
    fn pass(&mut self, way: Way, id: LinkId, frame: Frame) -> Option<Frame> {
        use rand::Rng as _;
        if self.imp.loss > 0.0 && self.rng.random_bool(self.imp.loss) {
            return None;
        }
        if self.imp.latency.is_zero() {
            return Some(frame);
        }
        let due = tokio::time::Instant::now() + self.imp.latency;
        self.delayed.push_back((due, way, id, frame));
        None
    }

    async fn next_due(&self) {
        match self.delayed.front() {
            Some((due, ..)) => tokio::time::sleep_until(*due).await,
            None => std::future::pending().await,
        }
    }

    fn pop_due(&mut self, now: tokio::time::Instant) -> Option<(Way, LinkId, Frame)> {
        if self.delayed.front()?.0 > now {
            return None;
        }
        self.delayed.pop_front().map(|(_, w, id, f)| (w, id, f))
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

fn dispatch(links: &HashMap<LinkId, LinkEntry>, radio: &mut Radio, out: Vec<Outbound>) {
    for o in out {
        let id = LinkId(o.link.0 as u32);
        match Frame::from_bytes(bytes::Bytes::from(o.frame)) {
            Ok(f) => {
                if let Some(f) = radio.pass(Way::Out, id, f) {
                    send_now(links, id, f);
                }
            }
            Err(e) => tracing::error!("endpoint produced a bad frame: {e}"),
        }
    }
}

fn send_now(links: &HashMap<LinkId, LinkEntry>, id: LinkId, frame: Frame) {
    if let Some(entry) = links.get(&id) {
        // A full queue is a slow peer: the frame is dropped and counted by the link.
        let _ = entry.tx.try_send(frame);
    }
}
