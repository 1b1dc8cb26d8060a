//! `firmware-sim`: the twin's command line. Thin: parse the flags (clap), build the library's
//! configuration, own the runtime, the terminal and the signals, report errors in one line
//! (anyhow at the edge).

use std::io::Write;
use std::process::ExitCode;

use anyhow::Context as _;
use clap::{Parser, Subcommand};
use firmware_sim::endpoint::EndpointConfig;
use firmware_sim::nav::params::Params;
use firmware_sim::shell::clock::ClockMode;
use firmware_sim::shell::fleet::{Fleet, FleetError};
use firmware_sim::shell::serve::{DEFAULT_LISTEN, Impairment, ServeConfig, ServeError};
use firmware_sim::shell::simulate::{self, InitialArg, Push, SimulateConfig};
use firmware_sim::{FlightMode, ModelMode};
use nalgebra::Vector3;
use tokio_util::sync::CancellationToken;
use vtol_link::{LinkOptions, LinkUrl, SigningKey};

/// The simulated twin of the two-rotor convertible VTOL (Escareño, Salazar & Lozano, CDC 2006).
#[derive(Debug, Parser)]
#[command(name = "firmware-sim", version, about)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

/// One variant per subcommand; each carries its own flags.
#[derive(Debug, Subcommand)]
enum Command {
    /// Offline closed-loop flight in fast time, written as CSV.
    Simulate(SimulateArgs),
    /// The twin as a MAVLink vehicle: prints `listening <url>` per endpoint, runs until Ctrl-C.
    Serve(ServeArgs),
}

/// Flags of `simulate` (the library takes a [`SimulateConfig`]).
#[derive(Debug, Clone, clap::Args)]
struct SimulateArgs {
    /// Simulated duration, s (up to 86400).
    #[arg(long, default_value_t = 25.0)]
    duration: f64,
    /// Initial state: phi=..,theta=..,psi=..,x=..,y=..,z=.. (rad, m; paper frame, z up).
    #[arg(long, default_value = "", value_parser = simulate::parse_initial)]
    initial: InitialArg,
    /// QLOITER's position setpoint x=..,y=..,z=.. (m, z up); default (0, 0, HOVER_ALT).
    #[arg(long, value_parser = simulate::parse_setpoint)]
    setpoint: Option<Vector3<f64>>,
    /// Model: paper or physical.
    #[arg(long, default_value = "physical")]
    model: ModelMode,
    /// Flight mode (QSTABILIZE, QHOVER, QLOITER, QLAND; GUIDED, AUTO and QRTL need `serve`).
    #[arg(long, default_value = "QLOITER")]
    mode: FlightMode,
    /// Perfect sensing: no noise, bias or quantisation, and the controller reads the true state.
    #[arg(long)]
    ideal_sensors: bool,
    /// Seed of every random draw.
    #[arg(long, default_value_t = 1)]
    seed: u64,
    /// Parameter NAME=VALUE (repeatable), checked as one set by the vehicle's table.
    #[arg(long = "param", value_parser = simulate::parse_param)]
    params: Vec<(String, f64)>,
    /// A push AXIS=N.m@SECONDS[:MS] (repeatable), e.g. roll=0.1@5:200 (FRD axes).
    #[arg(long = "push", value_parser = simulate::parse_push)]
    pushes: Vec<Push>,
    /// CSV output file (`-` = stdout).
    #[arg(long)]
    csv: Option<String>,
    /// CSV rows per simulated second.
    #[arg(long, default_value_t = 100.0)]
    rate: f64,
    /// Physics steps per simulated second (1000 to 10000, whole µs per step).
    #[arg(long, default_value_t = 1000.0)]
    physics_rate: f64,
}

impl SimulateArgs {
    fn config(&self) -> SimulateConfig {
        SimulateConfig {
            duration_s: self.duration,
            initial: self.initial,
            setpoint_m: self.setpoint,
            model: self.model,
            mode: self.mode,
            ideal_sensors: self.ideal_sensors,
            seed: self.seed,
            params: self.params.clone(),
            rate_hz: self.rate,
            physics_rate_hz: self.physics_rate,
            pushes: self.pushes.clone(),
        }
    }
}

fn main() -> ExitCode {
    let cli = match Cli::try_parse() {
        Ok(cli) => cli,
        Err(e) if !e.use_stderr() => {
            // --help and --version.
            let _ = e.print();
            return ExitCode::SUCCESS;
        }
        Err(e) => {
            // One clear line: clap's first line names the flag and the problem, or ends in a
            // colon before the line that names it ("required arguments were not provided:").
            let text = e.to_string();
            let mut lines = text.lines().map(str::trim).filter(|l| !l.is_empty());
            let first = lines.next().unwrap_or("invalid arguments");
            match lines.next() {
                Some(next) if first.ends_with(':') => eprintln!("{first} {next}"),
                _ => eprintln!("{first}"),
            }
            return ExitCode::from(2);
        }
    };
    match run(cli) {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {}", vtol_link::error_line(e.as_ref()));
            ExitCode::FAILURE
        }
    }
}

fn run(cli: Cli) -> anyhow::Result<()> {
    match cli.command {
        Command::Simulate(args) => run_simulate(&args),
        Command::Serve(args) => run_serve(&args),
    }
}

fn run_simulate(args: &SimulateArgs) -> anyhow::Result<()> {
    let cfg = args.config();
    // Checked before any file is created, so a refused flight leaves nothing behind.
    simulate::vehicle_config(&cfg)?;
    let summary = match args.csv.as_deref() {
        None => simulate::run(&cfg, None)?,
        Some("-") => {
            let stdout = std::io::stdout();
            let mut w = std::io::BufWriter::new(stdout.lock());
            simulate::run(&cfg, Some(&mut w))?
        }
        Some(path) => {
            let file = std::fs::File::create(path)
                .with_context(|| format!("cannot create CSV file '{path}'"))?;
            let mut w = std::io::BufWriter::new(file);
            simulate::run(&cfg, Some(&mut w))?
        }
    };
    let t = &summary.last;
    let line = format!(
        "t={:.3}s pos=({:.4},{:.4},{:.4}) m error={:.4} m phi={:.4} theta={:.4} psi={:.4} rad \
state={:?} armed={} landed={}",
        t.t_us as f64 * 1e-6,
        t.pos_m.x,
        t.pos_m.y,
        t.pos_m.z,
        summary.pos_error_m,
        t.euler.phi,
        t.euler.theta,
        t.euler.psi,
        t.state,
        t.armed,
        t.landed,
    );
    match args.csv.as_deref() {
        Some("-") => eprintln!("{line}"),
        Some(_) => writeln!(std::io::stdout(), "{line}")?,
        None => {
            writeln!(std::io::stdout(), "{line}")?;
            eprintln!("no CSV written (give --csv FILE, or --csv - for standard output)");
        }
    }
    Ok(())
}

/// Flags of `firmware-sim serve` (see the module docs for the stdout contract).
#[derive(Debug, Clone, clap::Args)]
struct ServeArgs {
    /// Where GCSs connect (repeatable): tcpin:HOST:PORT, udpin:HOST:PORT, udpout:HOST:PORT,
    /// tcp:HOST:PORT, serial:DEVICE[:BAUD]. Port 0 = pick a free port.
    #[arg(long = "listen", value_name = "URL", default_value = DEFAULT_LISTEN)]
    listen: Vec<LinkUrl>,
    /// Sim time per wall time (2 = twice real time).
    #[arg(long, default_value_t = 1.0, value_parser = parse_speed, conflicts_with_all = ["fast", "lockstep"])]
    speed: f64,
    /// Run as fast as the CPU allows (tests).
    #[arg(long, conflicts_with = "lockstep")]
    fast: bool,
    /// Sim time moves only when the control channel says `advance SECONDS`: a test gets the
    /// same telemetry on every run. Needs --control.
    #[arg(long, requires = "control", conflicts_with = "latency")]
    lockstep: bool,
    /// The harness channel (tcpin:HOST:PORT; port 0 = pick one): advance, state, param.
    #[arg(long, value_name = "URL")]
    control: Option<LinkUrl>,
    /// Log every frame in both directions to FILE (a new file; never overwritten).
    #[arg(long, value_name = "FILE")]
    tlog: Option<std::path::PathBuf>,
    /// Where the vehicle stands at start: x=..,y=..,psi=.. (m, rad; paper frame, on the ground).
    #[arg(long, default_value = "", value_parser = parse_ground_start)]
    initial: InitialArg,
    /// Calibrate the gyros for 1 s of sim time after start, as the hardware does (arming is
    /// refused until then). Without it the twin starts calibrated, ready to arm.
    #[arg(long)]
    boot_calibration: bool,
    /// Parameter file (.parm): loaded at start, rewritten atomically on every change. The
    /// mission is kept beside it (NAME.waypoints, QGC WPL 110).
    #[arg(long, value_name = "FILE")]
    param_file: Option<std::path::PathBuf>,
    /// Seed of every random draw (sensor noise, gusts).
    #[arg(long, default_value_t = 1)]
    seed: u64,
    /// Model mode: physical or paper (PHYSICS.md §0).
    #[arg(long, default_value = "physical")]
    model: ModelMode,
    /// Perfect sensing: no noise, bias or quantisation, and the controller reads the true state.
    #[arg(long)]
    ideal_sensors: bool,
    /// MAVLink system id (overrides SYSID_THISMAV), 1–255; with --count, the first twin's.
    #[arg(long, value_parser = clap::value_parser!(u8).range(1..))]
    sysid: Option<u8>,
    /// Run N twins (system ids --sysid (default 1) to --sysid + N - 1) on the same endpoints;
    /// each keeps its files as NAME-sysS.EXT beside --param-file and --tlog.
    #[arg(long, default_value_t = 1, value_parser = clap::value_parser!(u16).range(1..=255))]
    count: u16,
    /// Fraction of frames dropped in each direction (0 to 1, seeded by --seed).
    #[arg(long, default_value_t = 0.0, value_parser = parse_loss)]
    loss: f64,
    /// Delay of every frame in each direction, milliseconds.
    #[arg(long, default_value_t = 0, value_name = "MS")]
    latency: u64,
    /// A SiK telemetry radio at this baud on each link: a 2 KiB transmit buffer that drains at
    /// BAUD / 10 bytes a second and loses what does not fit, and RADIO_STATUS once a second
    /// (system 51, component 68) with the buffer's free percentage in `txbuf`.
    #[arg(long, value_name = "BAUD")]
    radio_baud: Option<u32>,
    /// MAVLink 2 signing with the key SHA-256(TEXT), as MAVProxy's `signing setup TEXT`: the
    /// twin signs what it sends and ignores unsigned (except RADIO_STATUS), wrongly signed and
    /// replayed frames. Key and timestamp are kept beside --param-file (NAME.signing); without
    /// a key flag the key saved there is used. SETUP_SIGNING is taken only when signed with the
    /// current key or sent on a serial link.
    #[arg(long, value_name = "TEXT", conflicts_with = "signing_key_file")]
    signing_passphrase: Option<String>,
    /// MAVLink 2 signing with the key in FILE (64 hex characters); as --signing-passphrase.
    #[arg(long, value_name = "FILE")]
    signing_key_file: Option<std::path::PathBuf>,
}

/// `--initial` of `serve`: a start on the ground, so x, y and psi only.
fn parse_ground_start(s: &str) -> Result<InitialArg, String> {
    let a = simulate::parse_initial(s)?;
    if a.pos_m.z != 0.0 || a.euler.phi != 0.0 || a.euler.theta != 0.0 {
        return Err(
            "serve --initial takes x, y and psi: the twin starts on the ground, level".into(),
        );
    }
    Ok(a)
}

fn parse_loss(s: &str) -> Result<f64, String> {
    match s.parse::<f64>() {
        Ok(v) if (0.0..1.0).contains(&v) => Ok(v),
        _ => Err(format!("loss must be a fraction in [0, 1), got '{s}'")),
    }
}

fn parse_speed(s: &str) -> Result<f64, String> {
    match s.parse::<f64>() {
        Ok(v) if v.is_finite() && v > 0.0 && v <= 1000.0 => Ok(v),
        _ => Err(format!("speed must be a number in (0, 1000], got '{s}'")),
    }
}

impl ServeArgs {
    /// The configuration these flags describe, parameter file loaded.
    ///
    /// The configuration these flags describe (parameter files are loaded by the fleet, one
    /// per twin).
    ///
    /// # Errors
    /// [`ServeError::Signing`] for an unusable key file.
    fn to_config(&self) -> Result<ServeConfig, ServeError> {
        let config = ServeConfig {
            listen: self.listen.clone(),
            clock: if self.lockstep {
                ClockMode::Lockstep
            } else if self.fast {
                ClockMode::AsFastAsPossible
            } else {
                ClockMode::Scaled { speed: self.speed }
            },
            endpoint: EndpointConfig {
                vehicle: firmware_sim::VehicleConfig {
                    model: self.model,
                    // Perfect sensing: no noise, and the controller reads the true state.
                    ideal_sensors: self.ideal_sensors,
                    perfect_state: self.ideal_sensors,
                    seed: self.seed,
                    initial: firmware_sim::model::vehicle::InitialState {
                        pos_m: self.initial.pos_m,
                        euler: self.initial.euler,
                    },
                    // Ready to arm at once unless the hardware's power-up calibration is asked for.
                    calibrated: !self.boot_calibration,
                    ..Default::default()
                },
                params: Params::new(),
                param_file: self.param_file.clone(),
                sysid: self.sysid,
                mission: firmware_sim::nav::mission::Mission::default(),
            },
            link_options: LinkOptions::default(),
            impairment: Impairment {
                loss: self.loss,
                latency: std::time::Duration::from_millis(self.latency),
                seed: self.seed,
                radio_baud: self.radio_baud,
            },
            control: self.control.clone(),
            tlog: self.tlog.clone(),
            signing: match (&self.signing_passphrase, &self.signing_key_file) {
                (Some(text), _) => Some(SigningKey::from_passphrase(text)),
                (None, Some(file)) => Some(SigningKey::from_key_file(file)?),
                (None, None) => None,
            },
        };
        Ok(config)
    }
}

/// `firmware-sim serve`: builds a runtime, opens the endpoints, prints one `listening <url>`
/// line per endpoint on stdout, and runs until Ctrl-C or SIGTERM.
///
/// # Errors
/// Startup failures (bad parameter file, address in use); I/O errors of the runtime.
fn run_serve(args: &ServeArgs) -> anyhow::Result<()> {
    // Logs go to stderr so stdout carries only the `listening` lines. A subscriber the caller
    // installed first wins.
    let _ = tracing_subscriber::fmt()
        .with_writer(std::io::stderr)
        .with_ansi(std::io::IsTerminal::is_terminal(&std::io::stderr()))
        .with_env_filter(
            tracing_subscriber::EnvFilter::try_from_default_env()
                .unwrap_or_else(|_| tracing_subscriber::EnvFilter::new("info")),
        )
        .try_init();
    let config = args.to_config()?;
    let runtime = tokio::runtime::Builder::new_multi_thread()
        .enable_all()
        .build()
        .map_err(ServeError::Runtime)?;
    runtime.block_on(async {
        let cancel = CancellationToken::new();
        let fleet = Fleet::start(config, args.count, cancel.clone()).await?;
        {
            use std::io::Write as _;
            let mut out = std::io::stdout().lock();
            for b in fleet.bound() {
                let _ = writeln!(out, "listening {}", b.resolved_url());
            }
            if let Some(url) = fleet.control_url() {
                let _ = writeln!(out, "control {url}");
            }
            let _ = out.flush();
        }
        shutdown_signal().await;
        tracing::info!("shutting down");
        cancel.cancel();
        fleet.join().await;
        Ok::<(), FleetError>(())
    })?;
    Ok(())
}

/// Resolves on Ctrl-C or (on Unix) SIGTERM.
async fn shutdown_signal() {
    let ctrl_c = async {
        if tokio::signal::ctrl_c().await.is_err() {
            std::future::pending::<()>().await;
        }
    };
    #[cfg(unix)]
    let term = async {
        match tokio::signal::unix::signal(tokio::signal::unix::SignalKind::terminate()) {
            Ok(mut s) => {
                s.recv().await;
            }
            Err(_) => std::future::pending::<()>().await,
        }
    };
    #[cfg(not(unix))]
    let term = std::future::pending::<()>();
    tokio::select! {
        () = ctrl_c => {}
        () = term => {}
    }
}
