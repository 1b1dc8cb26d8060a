//! The client commands of the binary: `params pull|push|get|set|diff|save`, `mission ...`,
//! `arm`, `disarm`, `mode`, `reboot`, each on its own link (`--link`, default the daemon's serve
//! port).
//!
//! Exit status (docs/cli.md): 0 done; 1 refused by the vehicle (nothing left changed; for
//! `params diff`: the vehicle differs from the file); 2 a usage or input error (bad file,
//! unknown parameter, wrong key); 3 no vehicle, no answer, or a link failure; 4 a rollback that
//! could not complete (the message names what the vehicle now holds). One line on standard
//! error per failure.

use std::path::PathBuf;
use std::process::ExitCode;

use clap::Args;
use tokio_util::sync::CancellationToken;
use vtol_gcs::client::{ClientConfig, ClientError, ClientHandle};
use vtol_gcs::trust::signing::{DaemonSigning, default_state_file, system_clock};
use vtol_link::{ComponentId, LinkUrl, SigningKey, SystemId};

mod mission_cmd;
mod params_cmd;
pub use mission_cmd::{MissionArgs, mission};
pub use params_cmd::{ParamsArgs, params};

/// Done.
pub const EXIT_OK: u8 = 0;
/// Refused by the vehicle; nothing left changed.
pub const EXIT_REFUSED: u8 = 1;
/// `params diff`: the vehicle differs from the file.
pub const EXIT_DIFFERENT: u8 = 1;
/// Usage or input error.
pub const EXIT_USAGE: u8 = 2;
/// No vehicle, no answer, or a link failure.
pub const EXIT_LINK: u8 = 3;
/// A rollback that could not complete.
pub const EXIT_ROLLBACK: u8 = 4;

/// How long after the link opens every vehicle on it has been heard (heartbeats come at
/// 1 Hz): a command without `--target` refuses to pick one of several.
const VEHICLES_SETTLE: std::time::Duration = std::time::Duration::from_millis(1200);

/// The daemon's default serve port.
const DEFAULT_LINK: &str = "tcp:127.0.0.1:5770";

/// Where and to whom.
#[derive(Debug, Clone, Args)]
pub struct LinkArgs {
    /// The vehicle or a daemon's serve port: tcp:H:P, udpout:H:P, udpin:H:P, serial:DEV[:BAUD]
    /// (default: the environment variable VTOL_GCS_LINK, else the daemon's default serve port).
    #[arg(long, env = "VTOL_GCS_LINK", default_value = DEFAULT_LINK, global = true)]
    link: LinkUrl,
    /// The vehicle as SYS[:COMP] (default: the first vehicle heard; COMP defaults to 1).
    #[arg(long, value_parser = parse_target, global = true)]
    target: Option<(SystemId, ComponentId)>,
    #[command(flatten)]
    signing: SigningArgs,
}

/// MAVLink 2 signing options, shared by the daemon and the client commands.
#[derive(Clone, Args, Default)]
pub struct SigningArgs {
    /// MAVLink 2 signing with the key SHA-256(TEXT), as MAVProxy's `signing setup TEXT`: sign
    /// what we send, read only rightly signed, fresh frames (RADIO_STATUS excepted). Also read
    /// from the environment variable VTOL_GCS_SIGNING_PASSPHRASE, which other users cannot see
    /// in `ps` as they can see a command line.
    #[arg(
        long,
        value_name = "TEXT",
        env = "VTOL_GCS_SIGNING_PASSPHRASE",
        hide_env_values = true,
        conflicts_with = "signing_key_file",
        global = true
    )]
    pub signing_passphrase: Option<String>,
    /// MAVLink 2 signing with the key in FILE (64 hex characters); as --signing-passphrase.
    #[arg(long, value_name = "FILE", global = true)]
    pub signing_key_file: Option<PathBuf>,
    /// Where the signing timestamp is kept (default $XDG_STATE_HOME/vtol-gcs/signing.toml,
    /// else ~/.local/state/vtol-gcs/signing.toml).
    #[arg(long, value_name = "FILE", global = true)]
    pub signing_state: Option<PathBuf>,
}

// The passphrase is a secret: never printed, not even by `{:?}`.
impl std::fmt::Debug for SigningArgs {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("SigningArgs")
            .field(
                "signing_passphrase",
                &self.signing_passphrase.as_ref().map(|_| "<secret>"),
            )
            .field("signing_key_file", &self.signing_key_file)
            .field("signing_state", &self.signing_state)
            .finish()
    }
}

impl SigningArgs {
    /// The key the options give, if any.
    ///
    /// # Errors
    /// A key file that cannot be read or holds no key (the message never quotes it).
    pub fn key(&self) -> Result<Option<SigningKey>, vtol_link::SigningFileError> {
        Ok(match (&self.signing_passphrase, &self.signing_key_file) {
            (Some(text), _) => Some(SigningKey::from_passphrase(text)),
            (None, Some(file)) => Some(SigningKey::from_key_file(file)?),
            (None, None) => None,
        })
    }

    /// The client's signing, when a key is given: state in --signing-state or the default
    /// state file.
    fn client_signing(&self) -> Result<Option<DaemonSigning>, Failure> {
        let Some(key) = self.key().map_err(|e| usage(e.to_string()))? else {
            return Ok(None);
        };
        let file = match &self.signing_state {
            Some(f) => f.clone(),
            None => {
                let f = default_state_file().ok_or_else(|| {
                    usage("no place for the signing state: give --signing-state FILE")
                })?;
                if let Some(dir) = f.parent() {
                    std::fs::create_dir_all(dir)
                        .map_err(|e| usage(format!("cannot create {}: {e}", dir.display())))?;
                }
                f
            }
        };
        DaemonSigning::start(key, Some(file), true, system_clock())
            .map(Some)
            .map_err(|e| usage(e.to_string()))
    }
}

fn parse_target(s: &str) -> Result<(SystemId, ComponentId), String> {
    let (sys, comp) = s.split_once(':').unwrap_or((s, "1"));
    match (sys.parse::<u8>(), comp.parse::<u8>()) {
        (Ok(sys), Ok(comp)) if sys > 0 => Ok((SystemId(sys), ComponentId(comp))),
        _ => Err(format!(
            "'{s}' is not SYS[:COMP] with SYS 1-255 and COMP 0-255"
        )),
    }
}

/// `vtol-gcs arm|disarm`.
#[derive(Debug, Args)]
pub struct ArmArgs {
    /// Skip the pre-arm checks (arm) or allow disarming in flight (disarm).
    #[arg(long)]
    force: bool,
    #[command(flatten)]
    link: LinkArgs,
}

/// `vtol-gcs mode NAME`.
#[derive(Debug, Args)]
pub struct ModeArgs {
    /// Mode name as the vehicle names it (ArduPlane: QSTABILIZE, QHOVER, QLOITER, QLAND, ...;
    /// ArduCopter: LOITER, GUIDED, ...; PX4: POSCTL, MISSION, ...) or its number (an unknown
    /// name lists the vehicle's modes).
    name: String,
    #[command(flatten)]
    link: LinkArgs,
}

/// A failed command: its exit status and one line for standard error.
struct Failure {
    code: u8,
    message: String,
}

impl From<ClientError> for Failure {
    fn from(e: ClientError) -> Self {
        let code = match e {
            ClientError::Refused { .. } => EXIT_REFUSED,
            ClientError::Usage(_) => EXIT_USAGE,
            ClientError::Timeout(_) | ClientError::Link(_) | ClientError::NoVehicle => EXIT_LINK,
        };
        // A command runs only once the vehicle was heard: silence to it while its telemetry
        // flows is most often a served endpoint that takes nothing from its clients.
        let hint = if matches!(e, ClientError::Timeout(_)) {
            " (the vehicle's telemetry arrives but nothing answers: if this link is a vtol-gcs \
             serve port with ?trust=read-only, the daemon drops everything its clients send; \
             use a trusted or signed endpoint)"
        } else {
            ""
        };
        Failure {
            code,
            // A crash is cleared by a reboot: every refusal that names one says so.
            message: format!("{}{hint}", vtol_gcs::vitals::with_recovery(&e.to_string())),
        }
    }
}

fn usage(message: impl Into<String>) -> Failure {
    Failure {
        code: EXIT_USAGE,
        message: message.into(),
    }
}

fn link_failure(message: impl Into<String>) -> Failure {
    Failure {
        code: EXIT_LINK,
        message: message.into(),
    }
}

/// The component id of a command-line run: one of MAV_COMP_ID_USER1..USER75 (25..=99) picked
/// by the process id, so that each run's sequence numbers are counted apart from the daemon's
/// own client (255:190) and from other runs. `RUST_LOG=debug` prints it.
fn run_component() -> ComponentId {
    let n = u8::try_from(std::process::id() % 75).unwrap_or(0);
    ComponentId(25 + n)
}

fn list(systems: &std::collections::BTreeSet<u8>) -> String {
    systems
        .iter()
        .map(u8::to_string)
        .collect::<Vec<_>>()
        .join(", ")
}

/// Opens the client's link. A `tcp:` link connects here, once: a refused connection fails at
/// once instead of being retried in the background until the vehicle search gives up.
async fn open(
    link: &LinkArgs,
    config: ClientConfig,
    signing: Option<DaemonSigning>,
    cancel: CancellationToken,
) -> Result<ClientHandle, Failure> {
    if let LinkUrl::Tcp { host, port } = &link.link {
        let stream = tokio::net::TcpStream::connect((host.as_str(), *port))
            .await
            .map_err(|e| {
                link_failure(format!(
                    "cannot connect to {}: {e} (is the daemon or vehicle running there?)",
                    link.link
                ))
            })?;
        // MAVLink frames are small: latency matters more than packet count.
        let _ = stream.set_nodelay(true);
        return Ok(ClientHandle::over_own_stream(
            stream,
            &format!("tcp {host}:{port}"),
            config,
            signing,
            cancel,
        ));
    }
    Ok(ClientHandle::connect_signed(&link.link, config, signing, cancel).await?)
}

/// Finds the vehicle the command goes to: `--target`, or the first vehicle on the link (see
/// [`only_vehicle`]). When none is found, says what was heard instead.
async fn find_vehicle(
    c: &ClientHandle,
    link: &LinkArgs,
    keyed: bool,
    started: std::time::Instant,
) -> Result<(), Failure> {
    let find = vtol_gcs::client::FIND_VEHICLE_TIMEOUT;
    let target = link.target.map(|(sys, _)| sys.0);
    let found = |h: &vtol_gcs::client::Heard| match target {
        Some(sys) => h.vehicles.contains(&sys),
        None => !h.vehicles.is_empty(),
    };
    // Frames that fail verification end the wait early: one more heartbeat period for a
    // rightly signed vehicle, and then the diagnosis. So do other vehicles than the target,
    // once every vehicle on the link has had a heartbeat period to be heard.
    let mut heard = c
        .wait_heard(VEHICLES_SETTLE, |h| found(h) || !h.bad_signature.is_empty())
        .await;
    let others_only = target.is_some() && !found(&heard) && !heard.vehicles.is_empty();
    if !found(&heard) && heard.bad_signature.is_empty() && !others_only {
        heard = c
            .wait_heard(find.saturating_sub(started.elapsed()), |h| {
                found(h) || !h.bad_signature.is_empty()
            })
            .await;
    }
    if !found(&heard) && !heard.bad_signature.is_empty() {
        heard = c.wait_heard(VEHICLES_SETTLE, found).await;
    }
    if !found(&heard) {
        return Err(no_vehicle(link, &heard, keyed));
    }
    Ok(())
}

/// Without `--target`: the vehicle found must be the only one on the link, which every vehicle
/// there has had a heartbeat period since `started` to show.
async fn only_vehicle(c: &ClientHandle, started: std::time::Instant) -> Result<(), Failure> {
    let settle = VEHICLES_SETTLE.saturating_sub(started.elapsed());
    let heard = c.wait_heard(settle, |h| h.vehicles.len() > 1).await;
    if heard.vehicles.len() > 1 {
        // The wait ends at the second vehicle: one more heartbeat period names them all.
        let heard = c.wait_heard(VEHICLES_SETTLE, |_| false).await;
        return Err(usage(format!(
            "several vehicles answer ({}): give --target",
            list(&heard.vehicles)
        )));
    }
    Ok(())
}

/// Why no vehicle was found, from what was heard.
fn no_vehicle(link: &LinkArgs, heard: &vtol_gcs::client::Heard, keyed: bool) -> Failure {
    if keyed && !heard.bad_signature.is_empty() {
        return usage(format!(
            "frames from system {} arrive but fail signature verification (wrong key?)",
            list(&heard.bad_signature)
        ));
    }
    if keyed && !heard.unsigned.is_empty() && heard.vehicles.is_empty() {
        return usage(format!(
            "frames from system {} arrive unsigned and a key was given (does the vehicle sign?)",
            list(&heard.unsigned)
        ));
    }
    match link.target {
        Some((sys, _)) if !heard.vehicles.is_empty() => link_failure(format!(
            "no vehicle {} among the vehicles heard: {}",
            sys.0,
            list(&heard.vehicles)
        )),
        _ => link_failure(format!(
            "no vehicle heard on {} within {} s (is the daemon or vehicle running there?)",
            link.link,
            vtol_gcs::client::FIND_VEHICLE_TIMEOUT.as_secs()
        )),
    }
}

/// Runs `f` with a client on `link`, on a single-threaded runtime, and turns the outcome into
/// an exit status.
fn with_client<F, Fut>(link: &LinkArgs, f: F) -> ExitCode
where
    F: FnOnce(ClientHandle) -> Fut,
    Fut: std::future::Future<Output = Result<(), Failure>>,
{
    let runtime = match tokio::runtime::Builder::new_current_thread()
        .enable_all()
        .build()
    {
        Ok(r) => r,
        Err(e) => {
            eprintln!("error: cannot start the async runtime: {e}");
            return ExitCode::from(EXIT_USAGE);
        }
    };
    let result = runtime.block_on(async {
        let cancel = CancellationToken::new();
        let config = ClientConfig {
            target: link.target,
            component_id: run_component(),
            ..ClientConfig::default()
        };
        tracing::debug!(
            "speaking as {}:{}",
            config.system_id.0,
            config.component_id.0
        );
        let signing = link.signing.client_signing()?;
        let keyed = signing.is_some();
        let client = open(link, config, signing, cancel.clone()).await?;
        let r = async {
            let t0 = std::time::Instant::now();
            // The round trip is probed, and the vehicle's capabilities (whether it serves its
            // parameters over FTP) asked, alongside each other: knowing them costs one round
            // trip. When the target is named they go at once, and the probe's answer finds the
            // vehicle as its telemetry would: a vehicle that streams nothing until asked is
            // not waited for until its next 1 Hz heartbeat.
            let first_contact = async {
                let (probe, caps) = tokio::join!(client.probe_rtt(), client.capabilities());
                tracing::debug!(
                    "round trip {probe:?}, capabilities {}, at {:?}",
                    if caps.as_ref().is_ok_and(Option::is_some) { "known" } else { "unknown" },
                    t0.elapsed()
                );
                probe
            };
            let probe = if link.target.is_some() {
                // A vehicle not found ends the command at once, the probe with it.
                let ((), probe) =
                    tokio::try_join!(find_vehicle(&client, link, keyed, t0), async {
                        Ok(first_contact.await)
                    })?;
                probe
            } else {
                // The first vehicle heard is probed (a TIMESYNC, a request for its
                // AUTOPILOT_VERSION) while the link is watched for others: a second one ends
                // the command before the command's own request goes to either.
                find_vehicle(&client, link, keyed, t0).await?;
                let ((), probe) = tokio::try_join!(only_vehicle(&client, t0), async {
                    Ok(first_contact.await)
                })?;
                probe
            };
            // Without an answer the timeouts start generous and adapt; but a vehicle that signs
            // and hears only unsigned frames never answers anything.
            if let Ok(None) = probe
                && !keyed
                && client
                    .target()
                    .is_some_and(|(sys, _)| client.heard().signed.contains(&sys.0))
            {
                return Err(usage(
                    "frames from the vehicle are signed and no key was given \
                     (give --signing-passphrase, VTOL_GCS_SIGNING_PASSPHRASE or --signing-key-file)",
                ));
            }
            f(client.clone()).await
        }
        .await;
        cancel.cancel();
        // The signing state is saved as the session ends.
        let _ = tokio::time::timeout(std::time::Duration::from_secs(2), client.stopped()).await;
        r
    });
    match result {
        Ok(()) => ExitCode::from(EXIT_OK),
        Err(f) => {
            if !f.message.is_empty() {
                eprintln!("error: {}", f.message);
            }
            ExitCode::from(f.code)
        }
    }
}

/// `arm` (`true`) or `disarm`.
pub fn arm(args: ArmArgs, arm: bool) -> ExitCode {
    let force = args.force;
    with_client(&args.link, |c| async move {
        if !arm {
            c.disarm(force).await?;
            println!("disarmed");
            return Ok(());
        }
        let mut beats = c.heartbeats();
        c.arm(force).await?;
        // The mode it armed in: in AUTO (a vehicle left there after a mission) it flies at once.
        let hb = match c.target() {
            Some(t) => {
                beats
                    .latest(t, std::time::Duration::from_millis(1500))
                    .await
            }
            None => None,
        };
        match hb {
            Some(h) => {
                let mode =
                    vtol_gcs::modes::mode_name(h.autopilot as u8, h.mavtype as u8, h.custom_mode);
                if mode == "AUTO" {
                    println!("armed in AUTO: the vehicle flies its mission now");
                } else {
                    println!("armed in {mode}");
                }
            }
            None => println!("armed"),
        }
        Ok(())
    })
}

/// `vtol-gcs reboot`.
#[derive(Debug, Args)]
pub struct RebootArgs {
    #[command(flatten)]
    link: LinkArgs,
}

/// `reboot`: restarts the vehicle's autopilot (disarmed only), which clears a crash.
pub fn reboot(args: RebootArgs) -> ExitCode {
    with_client(&args.link, |c| async move {
        vtol_gcs::reboot::reboot(&c).await?;
        println!("rebooting");
        Ok(())
    })
}

/// `mode NAME|NUMBER`.
pub fn mode(args: ModeArgs) -> ExitCode {
    // The vehicle's heartbeat tells which table its mode names come from.
    with_client(&args.link, |c| async move {
        let name = c.change_mode(&args.name).await?;
        println!("mode {name}");
        Ok(())
    })
}
