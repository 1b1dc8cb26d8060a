//! The `vtol-gcs` binary: parses the command line, sets up logging, and runs the daemon until
//! Ctrl-C or SIGTERM.

use std::path::PathBuf;

use anyhow::Context;
use clap::{Args, Parser, Subcommand};
use tokio_util::sync::CancellationToken;
use vtol_gcs::config::{Config, FileConfig, VehicleSource};
use vtol_link::LinkUrl;

mod log_cli;

/// Terminal ground station and MAVLink bridge for the two-rotor convertible VTOL.
#[derive(Debug, Parser)]
#[command(version, about)]
struct Cli {
    #[command(subcommand)]
    command: Option<Command>,
}

#[derive(Debug, Subcommand)]
enum Command {
    /// Run the daemon: vehicle link, client endpoints, router, tlog, status.
    Run(RunArgs),
    /// Look at flight logs: stats, export (CSV, MCAP), plot (PNG).
    #[command(subcommand)]
    Log(log_cli::LogCommand),
}

#[derive(Debug, Args, Default)]
struct RunArgs {
    /// Vehicle link: `embedded` (default), a URL (tcp:H:P, udpin:H:P, udpout:H:P,
    /// serial:DEV[:BAUD]) or a tlog played back as the vehicle: replay:FILE[?speed=N].
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
    /// A serial device that does not exist yet is waited for (default: an error at start).
    #[arg(long)]
    wait_for_device: bool,
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
    if args.wait_for_device {
        config.link.wait_for_device = true;
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
    tracing_subscriber::fmt()
        .with_env_filter(
            tracing_subscriber::EnvFilter::try_from_default_env().unwrap_or_else(|_| "warn".into()),
        )
        .with_writer(std::io::stderr)
        .init();
    let cli = Cli::parse();
    let args = match cli.command {
        Some(Command::Run(args)) => args,
        Some(Command::Log(cmd)) => return log_cli::run(cmd),
        None => RunArgs::default(),
    };
    let config = build_config(args)?;
    let runtime = tokio::runtime::Runtime::new().context("cannot start the async runtime")?;
    runtime.block_on(async move {
        let cancel = CancellationToken::new();
        let signal_cancel = cancel.clone();
        tokio::spawn(async move {
            wait_for_shutdown_signal().await;
            signal_cancel.cancel();
        });
        vtol_gcs::daemon::run(config, cancel)
            .await
            .map_err(anyhow::Error::from)
    })
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
