//! The `vtol-gcs` binary: parses the command line, sets up logging, and runs the terminal UI
//! (no arguments, or `tui`) or the headless daemon (`run`) until `q`, Ctrl-C or SIGTERM.

use std::path::PathBuf;

use anyhow::Context;
use clap::{Args, Parser, Subcommand};
use tokio_util::sync::CancellationToken;
use vtol_gcs::config::{Config, FileConfig, VehicleSource};
use vtol_link::LinkUrl;

/// Terminal ground station and MAVLink bridge for the two-rotor convertible VTOL.
#[derive(Debug, Parser)]
#[command(version, about)]
struct Cli {
    #[command(subcommand)]
    command: Option<Command>,
}

#[derive(Debug, Subcommand)]
enum Command {
    /// Run the daemon headless: vehicle link, client endpoints, router, tlog, status lines.
    Run(RunArgs),
    /// The terminal UI on a daemon in this process (as with no arguments), or attached to a
    /// running daemon's serve port or straight to a vehicle with `--connect`.
    Tui(TuiArgs),
}

#[derive(Debug, Args, Default)]
struct TuiArgs {
    /// Attach to this URL (a daemon's serve port, e.g. tcp:127.0.0.1:5770, or a vehicle)
    /// instead of running the embedded twin; nothing is served and no tlog is written unless
    /// --serve or --log-dir ask for it.
    #[arg(long)]
    connect: Option<LinkUrl>,
    #[command(flatten)]
    run: RunArgs,
}

#[derive(Debug, Args, Default)]
struct RunArgs {
    /// Vehicle link: `embedded` (default) or a URL (tcp:H:P, udpin:H:P, udpout:H:P, serial:DEV[:BAUD]).
    #[arg(long)]
    vehicle: Option<VehicleSource>,
    /// Client endpoint (repeatable): tcpin:H:P, udpin:H:P, udpout:H:P, tcp:H:P, serial:DEV[:BAUD].
    /// Replaces the defaults (tcpin:127.0.0.1:5770 and udpout:127.0.0.1:14550).
    #[arg(long = "serve")]
    serve: Vec<LinkUrl>,
    /// Directory for .tlog files (one per run).
    #[arg(long)]
    log_dir: Option<PathBuf>,
    /// Do not write a tlog.
    #[arg(long, conflicts_with = "log_dir")]
    no_log: bool,
    /// Status lines instead of the terminal UI.
    #[arg(long)]
    headless: bool,
    /// TOML configuration file (see config/vtol-gcs.toml); flags override it.
    #[arg(long)]
    config: Option<PathBuf>,
}

fn build_config(args: RunArgs) -> anyhow::Result<Config> {
    let mut config = Config::default();
    if let Some(path) = &args.config {
        FileConfig::load(path)?.apply(&mut config)?;
    }
    if let Some(v) = args.vehicle {
        config.vehicle = v;
    }
    if !args.serve.is_empty() {
        config.serve = args.serve;
    }
    if let Some(d) = args.log_dir {
        config.log_dir = Some(d);
    }
    if args.no_log {
        config.log_dir = None;
    }
    if args.headless {
        config.headless = true;
    }
    Ok(config)
}

fn main() -> std::process::ExitCode {
    match run() {
        Ok(()) => std::process::ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {}", vtol_link::error_line(e.as_ref()));
            std::process::ExitCode::FAILURE
        }
    }
}

fn run() -> anyhow::Result<()> {
    let cli = Cli::parse();
    let (args, ui) = match cli.command {
        Some(Command::Run(args)) => (args, None),
        Some(Command::Tui(t)) => (t.run, Some(t.connect)),
        None => (RunArgs::default(), Some(None)),
    };
    let explicit_log = args.log_dir.is_some();
    let explicit_serve = !args.serve.is_empty();
    let mut config = build_config(args)?;
    let ui = match ui {
        Some(_) if config.headless => None,
        other => other,
    };
    if let Some(Some(url)) = &ui {
        config.vehicle = VehicleSource::Url(url.clone());
        if !explicit_serve {
            config.serve.clear();
        }
        if !explicit_log {
            config.log_dir = None;
        }
    }
    init_tracing(ui.is_some(), config.log_dir.as_deref())?;
    let runtime = tokio::runtime::Runtime::new().context("cannot start the async runtime")?;
    runtime.block_on(async move {
        let cancel = CancellationToken::new();
        let signal_cancel = cancel.clone();
        tokio::spawn(async move {
            wait_for_shutdown_signal().await;
            signal_cancel.cancel();
        });
        if ui.is_none() {
            return vtol_gcs::daemon::run(config, cancel)
                .await
                .map_err(anyhow::Error::from);
        }
        // The UI owns the screen: no status lines.
        config.status_interval = std::time::Duration::ZERO;
        let mut tasks = tokio::task::JoinSet::new();
        let running = vtol_gcs::daemon::start(&config, &cancel, &mut tasks).await?;
        let result = vtol_gcs::tui::run(&running, Unavailable, cancel.clone()).await;
        cancel.cancel();
        while tasks.join_next().await.is_some() {}
        result.context("terminal")
    })
}

/// Log lines go to stderr, except under the UI, which owns the terminal: there they go to
/// `vtol-gcs.log` beside the tlogs (or nowhere when not logging).
fn init_tracing(ui: bool, log_dir: Option<&std::path::Path>) -> anyhow::Result<()> {
    let filter =
        tracing_subscriber::EnvFilter::try_from_default_env().unwrap_or_else(|_| "warn".into());
    let builder = tracing_subscriber::fmt().with_env_filter(filter);
    if !ui {
        builder.with_writer(std::io::stderr).init();
        return Ok(());
    }
    match log_dir {
        Some(dir) => {
            std::fs::create_dir_all(dir)
                .with_context(|| format!("cannot create {}", dir.display()))?;
            let path = dir.join("vtol-gcs.log");
            let file = std::fs::OpenOptions::new()
                .create(true)
                .append(true)
                .open(&path)
                .with_context(|| format!("cannot open {}", path.display()))?;
            builder
                .with_ansi(false)
                .with_writer(std::sync::Mutex::new(file))
                .init();
        }
        None => builder.with_writer(std::io::sink).init(),
    }
    Ok(())
}

/// Stands in for the client until it is wired: every request is answered "not available".
#[derive(Debug, Clone, Copy)]
struct Unavailable;

impl vtol_gcs::tui::Control for Unavailable {
    async fn execute(
        &self,
        request: vtol_gcs::tui::app::Request,
        out: tokio::sync::mpsc::Sender<vtol_gcs::tui::app::Outcome>,
    ) {
        let _ = out
            .send(vtol_gcs::tui::app::Outcome::Command {
                what: format!("{request:?}"),
                result: Err("commands are not available yet".into()),
            })
            .await;
    }
}

async fn wait_for_shutdown_signal() {
    let ctrl_c = tokio::signal::ctrl_c();
    #[cfg(unix)]
    {
        let mut term =
            match tokio::signal::unix::signal(tokio::signal::unix::SignalKind::terminate()) {
                Ok(s) => s,
                Err(_) => {
                    let _ = ctrl_c.await;
                    return;
                }
            };
        tokio::select! {
            _ = ctrl_c => {}
            _ = term.recv() => {}
        }
    }
    #[cfg(not(unix))]
    let _ = ctrl_c.await;
}
