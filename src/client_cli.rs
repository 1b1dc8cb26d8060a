//! The client commands of the binary: `params pull|push|get|set|diff|save`, `arm`, `disarm`,
//! `mode`, each on its own link (`--link`, default the daemon's serve port).
//!
//! Exit status: 0 done; 1 refused by the vehicle (nothing left changed); 2 a link or usage
//! error (bad file, unknown parameter, no vehicle, no answer); 3 a rollback that could not
//! complete (the message names what the vehicle now holds).

use std::io::{IsTerminal, Write};
use std::path::PathBuf;
use std::process::ExitCode;

use clap::{Args, Subcommand};
use tokio::sync::watch;
use tokio_util::sync::CancellationToken;
use vtol_gcs::client::{ClientConfig, ClientError, ClientHandle};
use vtol_gcs::params::file::{self, ParamFile};
use vtol_gcs::params::plan::{ParamOutcome, PushReport, PushResult};
use vtol_gcs::params::{self as params, Format, Param, ParamSet, Rules as _};
use vtol_gcs::trust::signing::{DaemonSigning, default_state_file, system_clock};
use vtol_link::{ComponentId, LinkUrl, SigningKey, SystemId};

/// Done.
pub const EXIT_OK: u8 = 0;
/// Refused by the vehicle; nothing left changed.
pub const EXIT_REFUSED: u8 = 1;
/// Link or usage error.
pub const EXIT_USAGE: u8 = 2;
/// A rollback that could not complete.
pub const EXIT_ROLLBACK: u8 = 3;

/// The daemon's default serve port.
const DEFAULT_LINK: &str = "tcp:127.0.0.1:5770";

/// Where and to whom.
#[derive(Debug, Clone, Args)]
pub struct LinkArgs {
    /// The vehicle or a daemon's serve port: tcp:H:P, udpout:H:P, udpin:H:P, serial:DEV[:BAUD].
    #[arg(long, default_value = DEFAULT_LINK, global = true)]
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
    /// what we send, read only rightly signed, fresh frames (RADIO_STATUS excepted).
    #[arg(
        long,
        value_name = "TEXT",
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

/// `vtol-gcs params ...`.
#[derive(Debug, Args)]
pub struct ParamsArgs {
    #[command(subcommand)]
    command: ParamsCommand,
    #[command(flatten)]
    link: LinkArgs,
}

#[derive(Debug, Subcommand)]
enum ParamsCommand {
    /// Download the whole table; print it, or write it with -o.
    Pull {
        /// Write to this file instead of standard output.
        #[arg(short = 'o', long = "output")]
        output: Option<PathBuf>,
        /// File format.
        #[arg(long, value_enum, default_value = "qgc")]
        format: Format,
    },
    /// Upload a file as one transaction: only what differs, verified, rolled back on failure.
    Push {
        /// MAVProxy, Mission Planner or QGroundControl file (detected).
        file: PathBuf,
        /// Show the changes and the planned order; write nothing.
        #[arg(long)]
        dry_run: bool,
    },
    /// Read parameters by name.
    Get {
        /// Names.
        #[arg(required = true)]
        names: Vec<String>,
    },
    /// Write parameters: NAME VALUE [NAME VALUE ...], as one transaction.
    Set {
        /// Name and value pairs.
        #[arg(required = true, num_args = 2..)]
        pairs: Vec<String>,
    },
    /// Show how the vehicle differs from a file.
    Diff {
        /// The file.
        file: PathBuf,
    },
    /// Download the whole table into a file.
    Save {
        /// The file.
        file: PathBuf,
        /// File format.
        #[arg(long, value_enum, default_value = "qgc")]
        format: Format,
    },
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
    /// ArduPlane mode name: QSTABILIZE, QHOVER, QLOITER, QLAND, ...
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
            _ => EXIT_USAGE,
        };
        Failure {
            code,
            message: e.to_string(),
        }
    }
}

fn usage(message: impl Into<String>) -> Failure {
    Failure {
        code: EXIT_USAGE,
        message: message.into(),
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
    let result =
        runtime.block_on(async {
            let cancel = CancellationToken::new();
            let config = ClientConfig {
                target: link.target,
                ..ClientConfig::default()
            };
            let signing = link.signing.client_signing()?;
            let client =
                ClientHandle::connect_signed(&link.link, config, signing, cancel.clone()).await?;
            client.wait_target(vtol_gcs::client::FIND_VEHICLE_TIMEOUT).await.map_err(|e| match e {
            ClientError::NoVehicle => usage(format!(
                "no vehicle heard on {} within {} s (is the daemon or vehicle running there?)",
                link.link,
                vtol_gcs::client::FIND_VEHICLE_TIMEOUT.as_secs()
            )),
            other => other.into(),
        })?;
            // Best effort: without an answer the timeouts start generous and adapt.
            let _ = client.probe_rtt().await;
            let r = f(client.clone()).await;
            cancel.cancel();
            // The signing state is saved as the session ends.
            let _ = tokio::time::timeout(std::time::Duration::from_secs(2), client.stopped()).await;
            r
        });
    match result {
        Ok(()) => ExitCode::from(EXIT_OK),
        Err(f) => {
            eprintln!("error: {}", f.message);
            ExitCode::from(f.code)
        }
    }
}

/// `arm` (`true`) or `disarm`.
pub fn arm(args: ArmArgs, arm: bool) -> ExitCode {
    let force = args.force;
    with_client(&args.link, |c| async move {
        if arm {
            c.arm(force).await?
        } else {
            c.disarm(force).await?
        }
        println!("{}", if arm { "armed" } else { "disarmed" });
        Ok(())
    })
}

/// `mode NAME`.
pub fn mode(args: ModeArgs) -> ExitCode {
    let name = args.name;
    if !vtol_gcs::client::MODES
        .iter()
        .any(|(n, _)| n.eq_ignore_ascii_case(&name))
    {
        let e = ClientError::Usage(format!("unknown mode '{name}'"));
        eprintln!("error: {e}");
        return ExitCode::from(EXIT_USAGE);
    }
    with_client(&args.link, |c| async move {
        c.set_mode(&name).await?;
        println!("mode {}", name.to_ascii_uppercase());
        Ok(())
    })
}

/// `params ...`.
pub fn params(args: ParamsArgs) -> ExitCode {
    // Files are read before any link is opened: a bad file sends nothing.
    let wanted = match &args.command {
        ParamsCommand::Push { file, .. } | ParamsCommand::Diff { file } => {
            match ParamFile::load(file) {
                Ok(f) => Some(f),
                Err(e) => {
                    eprintln!("error: {e}");
                    return ExitCode::from(EXIT_USAGE);
                }
            }
        }
        ParamsCommand::Set { pairs } => match parse_pairs(pairs) {
            Ok(f) => Some(f),
            Err(e) => {
                eprintln!("error: {e}");
                return ExitCode::from(EXIT_USAGE);
            }
        },
        _ => None,
    };
    let command = args.command;
    with_client(&args.link, |c| async move {
        match command {
            ParamsCommand::Pull { output, format } => {
                let t0 = std::time::Instant::now();
                let set = pull(&c).await?;
                let took = t0.elapsed();
                let vehicle = c.target().unwrap_or((SystemId(1), ComponentId(1)));
                match output {
                    Some(path) => {
                        file::save(&path, &set, format, vehicle)
                            .map_err(|e| usage(e.to_string()))?;
                        eprintln!(
                            "{} parameters written to {} (download {:.1} ms)",
                            set.len(),
                            path.display(),
                            took.as_secs_f64() * 1e3
                        );
                    }
                    None => print!("{}", file::render(&set, format, vehicle)),
                }
                Ok(())
            }
            ParamsCommand::Save { file: path, format } => {
                let set = pull(&c).await?;
                file::save(
                    &path,
                    &set,
                    format,
                    c.target().unwrap_or((SystemId(1), ComponentId(1))),
                )
                .map_err(|e| usage(e.to_string()))?;
                println!("{} parameters written to {}", set.len(), path.display());
                Ok(())
            }
            ParamsCommand::Get { names } => {
                for name in names {
                    let p = c.param_get(&name).await?;
                    println!("{name} {}", file::format_value(p.value));
                }
                Ok(())
            }
            ParamsCommand::Diff { .. } => {
                let wanted = wanted.ok_or_else(|| usage("no file loaded"))?;
                let current = pull(&c).await?;
                check_names(&current, &wanted)?;
                let changes = params::diff(&current, &wanted.params);
                for ch in &changes {
                    println!(
                        "{} {} -> {}",
                        ch.name,
                        file::format_value(ch.old),
                        file::format_value(ch.new)
                    );
                }
                println!("{} differ", changes.len());
                Ok(())
            }
            ParamsCommand::Push { dry_run, .. } => {
                let wanted = wanted.ok_or_else(|| usage("no file loaded"))?;
                push(&c, &wanted, dry_run).await
            }
            ParamsCommand::Set { .. } => {
                let wanted = wanted.ok_or_else(|| usage("no values given"))?;
                push(&c, &wanted, false).await
            }
        }
    })
}

fn parse_pairs(pairs: &[String]) -> Result<ParamFile, String> {
    if !pairs.len().is_multiple_of(2) {
        return Err("set takes NAME VALUE pairs".into());
    }
    let mut set = ParamSet::new();
    for pair in pairs.chunks(2) {
        let (name, text) = (&pair[0], &pair[1]);
        if !params::valid_name(name) {
            return Err(format!("'{name}' is not a parameter name"));
        }
        let value: f32 = text
            .parse()
            .map_err(|_| format!("{name}: '{text}' is not a number"))?;
        if !value.is_finite() {
            return Err(format!("{name}: {text} is not finite"));
        }
        if set
            .insert(
                name.clone(),
                Param {
                    value,
                    ty: params::MavParamType::MAV_PARAM_TYPE_REAL32,
                },
            )
            .is_some()
        {
            return Err(format!("{name} given twice"));
        }
    }
    Ok(ParamFile {
        params: set,
        // Values from the command line have no lines to point at.
        lines: std::collections::BTreeMap::new(),
        format: Format::Mavproxy,
        typed: false,
    })
}

/// Names the vehicle does not have, each with its line, as one usage error.
fn check_names(current: &ParamSet, wanted: &ParamFile) -> Result<(), Failure> {
    let unknown = params::unknown_names(current, &wanted.params);
    if unknown.is_empty() {
        return Ok(());
    }
    let list: Vec<String> = unknown
        .iter()
        .map(|n| match wanted.lines.get(n) {
            Some(l) => format!("line {l}: the vehicle has no parameter {n}"),
            None => format!("the vehicle has no parameter {n}"),
        })
        .collect();
    Err(usage(format!("{}; nothing sent", list.join("; "))))
}

fn progress_bar(total: u64, what: &str) -> Option<indicatif::ProgressBar> {
    if !std::io::stderr().is_terminal() {
        return None;
    }
    let bar = indicatif::ProgressBar::new(total);
    bar.set_message(what.to_owned());
    Some(bar)
}

/// A progress sender and the task drawing it (both `None` when standard error is no terminal).
type Progress = (
    Option<watch::Sender<(usize, usize)>>,
    Option<tokio::task::JoinHandle<()>>,
);

/// Feeds a progress bar from a watch channel until the sender goes away.
fn show_progress(what: &'static str) -> Progress {
    let Some(bar) = progress_bar(0, what) else {
        return (None, None);
    };
    let (tx, mut rx) = watch::channel((0, 0));
    let task = tokio::spawn(async move {
        while rx.changed().await.is_ok() {
            let (done, total) = *rx.borrow();
            bar.set_length(total as u64);
            bar.set_position(done as u64);
        }
        bar.finish_and_clear();
    });
    (Some(tx), Some(task))
}

async fn pull(c: &ClientHandle) -> Result<ParamSet, Failure> {
    let (tx, task) = show_progress("parameters");
    let r = c.params_pull(tx).await;
    if let Some(t) = task {
        let _ = t.await;
    }
    Ok(r?)
}

async fn push(c: &ClientHandle, wanted: &ParamFile, dry_run: bool) -> Result<(), Failure> {
    let current = pull(c).await?;
    check_names(&current, wanted)?;
    let changes = params::diff(&current, &wanted.params);
    let order = params::order_writes(&current, &changes, &params::TwinRules);
    let mut out = std::io::stdout().lock();
    for ch in &order {
        let _ = writeln!(
            out,
            "{} {} -> {}",
            ch.name,
            file::format_value(ch.old),
            file::format_value(ch.new)
        );
    }
    if dry_run {
        // What the twin's rules predict for this order; the vehicle has the last word.
        let mut state = current.clone();
        for ch in &order {
            match params::TwinRules.refusal(&state, &ch.name, ch.new) {
                Some(reason) => {
                    let _ = writeln!(out, "{}: likely refused: {reason}", ch.name);
                }
                None => {
                    if let Some(p) = state.get_mut(&ch.name) {
                        p.value = ch.new;
                    }
                }
            }
        }
        let _ = writeln!(
            out,
            "{} would change (dry run: nothing written)",
            order.len()
        );
        return Ok(());
    }
    drop(out);
    let (tx, task) = show_progress("writing");
    let report = c
        .push_onto(&current, &wanted.params, &params::TwinRules, tx)
        .await;
    if let Some(t) = task {
        let _ = t.await;
    }
    report_push(&report?)
}

fn report_push(r: &PushReport) -> Result<(), Failure> {
    let v = file::format_value;
    match &r.result {
        PushResult::Applied => {
            println!("{} changed", r.changed);
            Ok(())
        }
        PushResult::RolledBack { cause } => {
            for (name, o) in &r.outcomes {
                match o {
                    ParamOutcome::Refused { reason, .. } => eprintln!("{name}: refused: {reason}"),
                    ParamOutcome::RolledBack { old, written } => {
                        eprintln!(
                            "{name}: written {} then restored to {}",
                            v(*written),
                            v(*old)
                        );
                    }
                    ParamOutcome::NotWritten { .. } => eprintln!("{name}: not written"),
                    _ => {}
                }
            }
            Err(Failure {
                code: EXIT_REFUSED,
                message: format!("push refused, vehicle left as it was (0 changed): {cause}"),
            })
        }
        PushResult::RollbackIncomplete { cause } => {
            let mut holds = Vec::new();
            for (name, o) in &r.outcomes {
                if let ParamOutcome::RollbackFailed {
                    old,
                    holds: h,
                    reason,
                } = o
                {
                    let now = h.map_or_else(|| "an unknown value".to_owned(), v);
                    eprintln!("{name}: restore to {} failed: {reason}", v(*old));
                    holds.push(format!("{name} = {now} (was {})", v(*old)));
                }
            }
            Err(Failure {
                code: EXIT_ROLLBACK,
                message: format!(
                    "push failed ({cause}) and the rollback did not complete: the vehicle now holds {}",
                    holds.join(", ")
                ),
            })
        }
    }
}

#[cfg(test)]
mod tests {
    use std::collections::BTreeMap;

    use super::*;

    fn report(result: PushResult, outcomes: &[(&str, ParamOutcome)]) -> PushReport {
        PushReport {
            result,
            outcomes: outcomes
                .iter()
                .map(|(n, o)| ((*n).to_owned(), o.clone()))
                .collect::<BTreeMap<_, _>>(),
            changed: 0,
        }
    }

    #[test]
    fn exit_status_follows_the_push_result() {
        let ok = PushReport {
            result: PushResult::Applied,
            outcomes: BTreeMap::new(),
            changed: 0,
        };
        assert!(report_push(&ok).is_ok());
        let refused = report(
            PushResult::RolledBack {
                cause: "LAT_SAT_B refused".into(),
            },
            &[(
                "LAT_SAT_B",
                ParamOutcome::Refused {
                    old: 0.6,
                    reason: "needs a > b + c + d".into(),
                },
            )],
        );
        let f = report_push(&refused).expect_err("refused");
        assert_eq!(f.code, EXIT_REFUSED);
        assert!(f.message.contains("LAT_SAT_B"), "{}", f.message);
        let stuck = report(
            PushResult::RollbackIncomplete {
                cause: "LAT_SAT_B refused".into(),
            },
            &[(
                "LAT_SAT_D",
                ParamOutcome::RollbackFailed {
                    old: 0.3,
                    holds: Some(0.15),
                    reason: "refused".into(),
                },
            )],
        );
        let f = report_push(&stuck).expect_err("incomplete");
        assert_eq!(f.code, EXIT_ROLLBACK);
        assert!(
            f.message.contains("now holds LAT_SAT_D = 0.15 (was 0.3)"),
            "{}",
            f.message
        );
    }
}
