//! `firmware-sim`: the twin's command line. Thin: parse the flags (clap), call the library,
//! report errors in one line (anyhow at the edge).

use std::io::Write;
use std::process::ExitCode;

use anyhow::Context as _;
use clap::{Parser, Subcommand};
use firmware_sim::simulate::{self, InitialArg, Push, SimulateConfig};
use firmware_sim::{FlightMode, ModelMode};
use nalgebra::Vector3;

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
    Serve(firmware_sim::serve::ServeArgs),
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
    /// Flight mode (QSTABILIZE, QHOVER, QLOITER, QLAND).
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
            // One clear line: clap's first line names the flag and the problem.
            let text = e.to_string();
            let line = text
                .lines()
                .find(|l| !l.trim().is_empty())
                .unwrap_or("invalid arguments");
            eprintln!("{line}");
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
        Command::Serve(args) => Ok(firmware_sim::serve::run_cli(&args)?),
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
    if args.csv.as_deref() == Some("-") {
        eprintln!("{line}");
    } else {
        writeln!(std::io::stdout(), "{line}")?;
    }
    Ok(())
}
