//! `firmware-sim`: the twin's command line. Thin: parse the flags (clap), call the library,
//! report errors in one line (anyhow at the edge).

use std::io::Write;
use std::process::ExitCode;

use anyhow::Context as _;
use clap::{Parser, Subcommand};
use firmware_sim::simulate::{self, SimulateArgs};

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
    let summary = match args.csv.as_deref() {
        None => simulate::run(args, None)?,
        Some("-") => {
            let stdout = std::io::stdout();
            let mut w = std::io::BufWriter::new(stdout.lock());
            simulate::run(args, Some(&mut w))?
        }
        Some(path) => {
            let file = std::fs::File::create(path)
                .with_context(|| format!("cannot create CSV file '{path}'"))?;
            let mut w = std::io::BufWriter::new(file);
            simulate::run(args, Some(&mut w))?
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
