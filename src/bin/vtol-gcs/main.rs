//! The `vtol-gcs` binary: parses the command line, sets up logging, and runs the terminal UI
//! (no arguments, or `tui`), the headless daemon (`run`) until Ctrl-C or SIGTERM, or one client
//! command (`params`, `mission`, `arm`, `disarm`, `mode`). It owns the terminal: the start-up
//! and status lines and the UI are drawn here, never by the library.

mod client_cli;

use std::io::Write as _;
use std::path::PathBuf;

use anyhow::Context;
use clap::{Args, Parser, Subcommand};
use tokio_util::sync::CancellationToken;
use vtol_gcs::config::{Config, FileConfig, VehicleSource};
use vtol_gcs::trust::policy::ServeSpec;
use vtol_link::LinkUrl;

mod log_cli;

/// Terminal ground station and MAVLink bridge for the two-rotor convertible VTOL.
///
/// With no subcommand it runs the terminal UI and takes exactly the options of `vtol-gcs tui`
/// (`vtol-gcs --vehicle tcp:127.0.0.1:5760` is `vtol-gcs tui --vehicle tcp:127.0.0.1:5760`).
///
/// Exit status (every subcommand): 0 done; 1 refused by the vehicle (or `params diff`: the
/// vehicle differs); 2 usage or input error; 3 no vehicle, or a link failure; 4 a rollback that
/// could not complete. See docs/cli.md.
#[derive(Debug, Parser)]
#[command(version, about, args_conflicts_with_subcommands = true)]
struct Cli {
    /// The terminal UI's options (as `vtol-gcs tui`).
    #[command(flatten)]
    tui: TuiArgs,
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
    /// Parameters: pull, push, get, set, diff, save.
    Params(client_cli::ParamsArgs),
    /// Missions, fences and rally points: upload, download, clear, start, set-current, show.
    Mission(client_cli::MissionArgs),
    /// Arm the vehicle.
    Arm(client_cli::ArmArgs),
    /// Disarm the vehicle.
    Disarm(client_cli::ArmArgs),
    /// Change the flight mode (QSTABILIZE, QHOVER, QLOITER, QLAND, ...).
    Mode(client_cli::ModeArgs),
    /// Reboot the vehicle's autopilot (disarmed only); clears a crash.
    Reboot(client_cli::RebootArgs),
    /// Look at flight logs: stats, export (CSV, MCAP), plot (PNG).
    #[command(subcommand)]
    Log(log_cli::LogCommand),
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
    /// Vehicle link: `embedded` (default), a URL (tcp:H:P, udpin:H:P, udpout:H:P,
    /// serial:DEV[:BAUD]), a fleet over Zenoh (zenoh:FLEET/* or zenoh:FLEET/VEHICLE) or a tlog
    /// played back as the vehicle: replay:FILE[?speed=N].
    #[arg(long)]
    vehicle: Option<VehicleSource>,
    /// Client endpoint (repeatable): tcpin:H:P, udpin:H:P, udpout:H:P, tcp:H:P, serial:DEV[:BAUD],
    /// or zenoh:FLEET/VEHICLE (this vehicle's end of a fleet), with options in a query: ?trust=trusted|sign|read-only&rate=MSGS_PER_S&burst=N.
    /// Replaces the defaults (tcpin:127.0.0.1:5770 and udpout:127.0.0.1:14550).
    #[arg(long = "serve")]
    serve: Vec<ServeSpec>,
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
    /// Download the vehicle's parameters when it is first heard and again after each reboot.
    #[arg(long)]
    fetch_params: bool,
    #[command(flatten)]
    signing: client_cli::SigningArgs,
    /// Zenoh endpoint to connect to for zenoh: links (repeatable), e.g. tcp/127.0.0.1:7447.
    #[arg(long, value_name = "ENDPOINT", value_parser = zenoh_endpoint)]
    zenoh_connect: Vec<String>,
    /// Zenoh endpoint to listen on for zenoh: links (repeatable), e.g. tcp/0.0.0.0:7447.
    #[arg(long, value_name = "ENDPOINT", value_parser = zenoh_endpoint)]
    zenoh_listen: Vec<String>,
    /// Zenoh session mode: peer (default), client (through a router) or router.
    #[arg(long, value_name = "MODE")]
    zenoh_mode: Option<vtol_link::ZenohMode>,
}

fn zenoh_endpoint(s: &str) -> Result<String, String> {
    vtol_gcs::config::check_zenoh_endpoint(s).map(|()| s.to_string())
}

impl RunArgs {
    fn zenoh_flags_given(&self) -> bool {
        self.zenoh_mode.is_some() || !self.zenoh_connect.is_empty() || !self.zenoh_listen.is_empty()
    }
}

/// `--zenoh-*` flags with no `zenoh:` link to use them would be silently ignored: refuse them.
fn refuse_unused_zenoh_flags(config: &Config, given: bool) -> anyhow::Result<()> {
    let is_zenoh = |u: &LinkUrl| matches!(u, LinkUrl::Zenoh { .. });
    let used = matches!(&config.vehicle, VehicleSource::Url(u) if is_zenoh(u))
        || config.serve.iter().any(|s| is_zenoh(&s.url));
    if given && !used {
        anyhow::bail!(
            "--zenoh-mode, --zenoh-connect and --zenoh-listen need a zenoh: link \
             (--vehicle 'zenoh:FLEET/*' or --serve zenoh:FLEET/VEHICLE)"
        );
    }
    Ok(())
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
    if args.fetch_params {
        config.fetch_params = true;
    }
    if let Some(key) = args.signing.key()? {
        config.signing = Some(key);
    }
    if let Some(f) = args.signing.signing_state {
        config.signing_state = Some(f);
    }
    if let Some(m) = args.zenoh_mode {
        config.link.zenoh.mode = m;
    }
    if !args.zenoh_connect.is_empty() {
        config.link.zenoh.connect = args.zenoh_connect;
    }
    if !args.zenoh_listen.is_empty() {
        config.link.zenoh.listen = args.zenoh_listen;
    }
    Ok(config)
}

fn main() -> std::process::ExitCode {
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
    if !matches!(cli.command, None | Some(Command::Tui(_))) {
        init_stderr_tracing();
    }
    let result = match cli.command {
        Some(Command::Params(a)) => return client_cli::params(a),
        Some(Command::Mission(a)) => return client_cli::mission(a),
        Some(Command::Arm(a)) => return client_cli::arm(a, true),
        Some(Command::Disarm(a)) => return client_cli::arm(a, false),
        Some(Command::Mode(a)) => return client_cli::mode(a),
        Some(Command::Reboot(a)) => return client_cli::reboot(a),
        Some(Command::Log(cmd)) => log_cli::run(cmd),
        Some(Command::Run(args)) => run(args),
        Some(Command::Tui(t)) => ui(t.run, t.connect),
        None => ui(cli.tui.run, cli.tui.connect),
    };
    match result {
        Ok(()) => std::process::ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {}", vtol_link::error_line(e.as_ref()));
            std::process::ExitCode::from(exit_code(&e))
        }
    }
}

/// The exit status of a failed UI, daemon or log command (docs/cli.md): a link that cannot be
/// opened is a link failure (3); everything else stopped at start on what it was given (2).
fn exit_code(e: &anyhow::Error) -> u8 {
    match e.downcast_ref::<vtol_gcs::daemon::DaemonError>() {
        Some(vtol_gcs::daemon::DaemonError::Link { .. }) => client_cli::EXIT_LINK,
        _ => client_cli::EXIT_USAGE,
    }
}

fn env_filter() -> tracing_subscriber::EnvFilter {
    // Zenoh warns about what it then returns as an error: the error line says it once.
    tracing_subscriber::EnvFilter::try_from_default_env()
        .unwrap_or_else(|_| "warn,zenoh=error".into())
}

fn init_stderr_tracing() {
    // Colour codes only for a terminal: a pipe or a file gets plain text.
    tracing_subscriber::fmt()
        .with_env_filter(env_filter())
        .with_ansi(std::io::IsTerminal::is_terminal(&std::io::stderr()))
        .with_writer(std::io::stderr)
        .init();
}

/// Log lines under the UI, which owns the terminal: to `vtol-gcs.log` beside the tlogs, or
/// nowhere when not logging.
fn init_ui_tracing(log_dir: Option<&std::path::Path>) -> anyhow::Result<()> {
    let builder = tracing_subscriber::fmt().with_env_filter(env_filter());
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

/// The terminal UI on the daemon in this process: the embedded twin (or `--vehicle`), or
/// `connect` as the vehicle link. `--headless` falls back to status lines.
fn ui(args: RunArgs, connect: Option<LinkUrl>) -> anyhow::Result<()> {
    let explicit_log = args.log_dir.is_some();
    let explicit_serve = !args.serve.is_empty();
    let zenoh_flags = args.zenoh_flags_given();
    let mut config = build_config(args)?;
    if config.headless {
        refuse_unused_zenoh_flags(&config, zenoh_flags)?;
        init_stderr_tracing();
        return run_config(config);
    }
    if let Some(url) = connect {
        config.vehicle = VehicleSource::Url(url);
        if !explicit_serve {
            config.serve.clear();
        }
        if !explicit_log {
            config.log_dir = None;
        }
    }
    refuse_unused_zenoh_flags(&config, zenoh_flags)?;
    init_ui_tracing(config.log_dir.as_deref())?;
    let embedded = matches!(config.vehicle, VehicleSource::Embedded);
    let result = until_shutdown(|cancel| async move {
        let mut tasks = tokio::task::JoinSet::new();
        let running = vtol_gcs::daemon::start(&config, &cancel, &mut tasks).await?;
        let result = vtol_gcs::tui::run(
            &running,
            vtol_gcs::tui::client_control::ClientControl::new(running.client.clone()),
            cancel.clone(),
        )
        .await;
        cancel.cancel();
        while tasks.join_next().await.is_some() {}
        result.context("terminal")
    });
    if embedded {
        // The twin lived in this process: say so once the screen is back, so nobody expects the
        // parameters they set to be there next time.
        eprintln!(
            "the embedded twin's parameters were kept in memory only and are gone with it \
             (keep them with `vtol-gcs params save FILE` before quitting; see docs/cli.md)"
        );
    }
    result
}

fn run(args: RunArgs) -> anyhow::Result<()> {
    let zenoh_flags = args.zenoh_flags_given();
    let config = build_config(args)?;
    refuse_unused_zenoh_flags(&config, zenoh_flags)?;
    run_config(config)
}

fn run_config(config: Config) -> anyhow::Result<()> {
    until_shutdown(|cancel| async move { run_daemon(config, cancel).await })
}

/// The headless daemon: start-up lines, then a status line per interval.
async fn run_daemon(mut config: Config, cancel: CancellationToken) -> anyhow::Result<()> {
    // No screen to refresh fifty times a second.
    config.tracker_period = vtol_gcs::tracker::HEADLESS_PERIOD;
    let mut tasks = tokio::task::JoinSet::new();
    let running = vtol_gcs::daemon::start(&config, &cancel, &mut tasks).await?;
    let mut out = StatusOut::default();
    let vehicle = match (&config.vehicle, running.vehicle_addr) {
        (VehicleSource::Url(url), Some(addr)) => vtol_gcs::daemon::describe(url, Some(addr)),
        (source, _) => source.to_string(),
    };
    out.line(&format!("vehicle {vehicle}"));
    for (url, addr, policy) in &running.serving {
        out.line(&format!(
            "serving {}{}",
            vtol_gcs::daemon::describe(url, *addr),
            policy.query()
        ));
    }
    if let Some(p) = &running.signing_state {
        out.line(&format!("signing state {}", p.display()));
    }
    if let Some(p) = &running.tlog_path {
        out.line(&format!("logging {}", p.display()));
    }
    if out.open {
        print_status_lines(&running, config.status_interval, &cancel, &mut out).await;
    }
    while tasks.join_next().await.is_some() {}
    Ok(())
}

/// Standard output of the headless daemon. A reader that goes away (`vtol-gcs run | head`, a
/// closed log pipe) ends the status lines, with one line on standard error, and nothing else:
/// the daemon goes on routing and logging.
struct StatusOut {
    open: bool,
}

impl Default for StatusOut {
    fn default() -> Self {
        Self { open: true }
    }
}

impl StatusOut {
    fn line(&mut self, line: &str) {
        if !self.open {
            return;
        }
        let mut stdout = std::io::stdout().lock();
        if let Err(e) = writeln!(stdout, "{line}").and_then(|()| stdout.flush()) {
            self.open = false;
            eprintln!("status lines stopped: standard output failed ({e}); the daemon goes on");
        }
    }
}

/// One status line per `interval` until `cancel` fires.
async fn print_status_lines(
    running: &vtol_gcs::daemon::Running,
    interval: std::time::Duration,
    cancel: &CancellationToken,
    out: &mut StatusOut,
) {
    let mut tick = tokio::time::interval(interval);
    tick.tick().await;
    loop {
        tokio::select! {
            () = cancel.cancelled() => return,
            _ = tick.tick() => {
                let state = running.state.borrow().clone();
                let links = running.router.links.borrow().clone();
                let unroutable = running
                    .router
                    .stats
                    .unroutable
                    .load(std::sync::atomic::Ordering::Relaxed);
                let signing = running.router.signing.as_ref().map(|s| s.snapshot());
                let mut line = vtol_gcs::status::line(
                    &state,
                    &links,
                    running.tlog_stats.as_deref(),
                    &running.param_fetches.status(),
                    unroutable,
                    vtol_gcs::tracker::now(),
                );
                line.push_str(&vtol_gcs::status::fit_part(
                    running.link_fit.borrow().as_ref(),
                ));
                line.push_str(&vtol_gcs::status::policy_part(&links, signing.as_ref()));
                line.push_str(&vtol_gcs::status::fleet_part(
                    &state,
                    &running.router.conflicts.borrow(),
                    vtol_gcs::tracker::now(),
                ));
                out.line(&line);
                if !out.open {
                    return;
                }
            }
        }
    }
}

/// Runs `body` on a new runtime with a cancellation token that Ctrl-C or SIGTERM fires.
fn until_shutdown<F, Fut>(body: F) -> anyhow::Result<()>
where
    F: FnOnce(CancellationToken) -> Fut,
    Fut: std::future::Future<Output = anyhow::Result<()>>,
{
    let runtime = tokio::runtime::Runtime::new().context("cannot start the async runtime")?;
    runtime.block_on(async move {
        let cancel = CancellationToken::new();
        let signal_cancel = cancel.clone();
        tokio::spawn(async move {
            wait_for_shutdown_signal().await;
            signal_cancel.cancel();
        });
        body(cancel).await
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
