//! The `vtol-gcs` binary: parses the command line, sets up logging, and runs the daemon until
//! Ctrl-C or SIGTERM, or one client command (`params`, `arm`, `disarm`, `mode`). It owns the
//! terminal: the start-up and status lines are printed here, never by the library.

mod client_cli;

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
    /// Parameters: pull, push, get, set, diff, save.
    Params(client_cli::ParamsArgs),
    /// Arm the vehicle.
    Arm(client_cli::ArmArgs),
    /// Disarm the vehicle.
    Disarm(client_cli::ArmArgs),
    /// Change the flight mode (QSTABILIZE, QHOVER, QLOITER, QLAND, ...).
    Mode(client_cli::ModeArgs),
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
    tracing_subscriber::fmt()
        .with_env_filter(
            tracing_subscriber::EnvFilter::try_from_default_env().unwrap_or_else(|_| "warn".into()),
        )
        .with_writer(std::io::stderr)
        .init();
    let cli = match Cli::try_parse() {
        Ok(cli) => cli,
        Err(e) if !e.use_stderr() => {
            let _ = e.print();
            return std::process::ExitCode::SUCCESS;
        }
        Err(e) => {
            // Usage errors exit 2, like every other link or usage error of the client commands.
            let _ = e.print();
            return std::process::ExitCode::from(client_cli::EXIT_USAGE);
        }
    };
    let result = match cli.command {
        Some(Command::Params(a)) => return client_cli::params(a),
        Some(Command::Arm(a)) => return client_cli::arm(a, true),
        Some(Command::Disarm(a)) => return client_cli::arm(a, false),
        Some(Command::Mode(a)) => return client_cli::mode(a),
        Some(Command::Log(cmd)) => log_cli::run(cmd),
        Some(Command::Run(args)) => run(args),
        None => run(RunArgs::default()),
    };
    match result {
        Ok(()) => std::process::ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {}", vtol_link::error_line(e.as_ref()));
            std::process::ExitCode::FAILURE
        }
    }
}

fn run(args: RunArgs) -> anyhow::Result<()> {
    let config = build_config(args)?;
    let runtime = tokio::runtime::Runtime::new().context("cannot start the async runtime")?;
    runtime.block_on(async move {
        let cancel = CancellationToken::new();
        let signal_cancel = cancel.clone();
        tokio::spawn(async move {
            wait_for_shutdown_signal().await;
            signal_cancel.cancel();
        });
        run_daemon(config, cancel).await
    })
}

/// The daemon with status lines. Headless or not, status lines are what the binary shows
/// until the terminal UI takes the non-headless path.
async fn run_daemon(config: Config, cancel: CancellationToken) -> anyhow::Result<()> {
    let mut tasks = tokio::task::JoinSet::new();
    let running = vtol_gcs::daemon::start(&config, &cancel, &mut tasks).await?;
    println!("vehicle {}", config.vehicle);
    for (url, addr) in &running.serving {
        println!("serving {}", vtol_gcs::daemon::describe(url, *addr));
    }
    if let Some(p) = &running.tlog_path {
        println!("logging {}", p.display());
    }
    // The terminal UI replaces this when not headless; until it exists both print status lines.
    print_status_lines(&running, config.status_interval, &cancel).await;
    while tasks.join_next().await.is_some() {}
    Ok(())
}

/// One status line per `interval` until `cancel` fires.
async fn print_status_lines(
    running: &vtol_gcs::daemon::Running,
    interval: std::time::Duration,
    cancel: &CancellationToken,
) {
    let mut tick = tokio::time::interval(interval);
    tick.tick().await;
    loop {
        tokio::select! {
            () = cancel.cancelled() => return,
            _ = tick.tick() => {
                let state = running.state.borrow().clone();
                let links = running.router.links.borrow().clone();
                let records = running
                    .tlog_stats
                    .as_ref()
                    .map(|s| s.records.load(std::sync::atomic::Ordering::Relaxed));
                println!("{}", vtol_gcs::status::line(&state, &links, records, std::time::Instant::now()));
            }
        }
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
