//! `vtol-fuzz`: runs the fuzz targets on stable Rust.
//!
//! ```text
//! vtol-fuzz list
//! vtol-fuzz run [TARGET]... [--seconds N | --inputs N] [--seed N] [--max-len N]
//! ```
//!
//! Each target starts from `fuzz/corpus/TARGET/` and its regressions. An input that panics is
//! written to `fuzz/regressions/TARGET/crash-HASH`, its message printed, and the exit status is
//! 1; the test suite then replays it on every run.

use std::process::ExitCode;
use std::time::Duration;

use anyhow::Context;
use clap::{Parser, Subcommand};
use vtol_fuzz::runner::{self, Budget};

/// Fuzz targets for vtol-gcs, the twin and vtol-link (stable Rust, seeded mutations).
#[derive(Debug, Parser)]
#[command(version, about)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Debug, Subcommand)]
enum Command {
    /// The targets and what each feeds.
    List,
    /// Fuzz some targets (all when none is named), one after the other.
    Run {
        /// Target names (see `list`).
        targets: Vec<String>,
        /// Wall time per target.
        #[arg(long, default_value_t = 60.0, conflicts_with = "inputs")]
        seconds: f64,
        /// A number of inputs per target instead of a time (repeatable on any machine).
        #[arg(long)]
        inputs: Option<u64>,
        /// Seed of the mutations.
        #[arg(long, default_value_t = 1)]
        seed: u64,
        /// Longest input tried, bytes.
        #[arg(long, default_value_t = 4096)]
        max_len: usize,
    },
}

fn main() -> ExitCode {
    match run() {
        Ok(true) => ExitCode::SUCCESS,
        Ok(false) => ExitCode::FAILURE,
        Err(e) => {
            eprintln!("error: {e:#}");
            ExitCode::from(2)
        }
    }
}

fn run() -> anyhow::Result<bool> {
    match Cli::parse().command {
        Command::List => {
            for t in vtol_fuzz::TARGETS {
                println!("{:<16} {}", t.name, t.about);
            }
            Ok(true)
        }
        Command::Run {
            targets,
            seconds,
            inputs,
            seed,
            max_len,
        } => {
            if !(seconds.is_finite() && seconds > 0.0) {
                anyhow::bail!("--seconds must be a positive number, got {seconds}");
            }
            let chosen: Vec<_> = if targets.is_empty() {
                vtol_fuzz::TARGETS.iter().collect()
            } else {
                targets
                    .iter()
                    .map(|n| {
                        vtol_fuzz::target(n).with_context(|| {
                            format!("no target '{n}' (`vtol-fuzz list` shows them)")
                        })
                    })
                    .collect::<anyhow::Result<_>>()?
            };
            let budget = inputs.map_or(
                Budget::Time(Duration::from_secs_f64(seconds)),
                Budget::Inputs,
            );
            // Panics are the findings: report them here, not as the default hook's backtrace.
            std::panic::set_hook(Box::new(|_| {}));
            let dir = runner::fuzz_dir();
            let mut clean = true;
            for t in chosen {
                let mut corpus = Vec::new();
                for sub in ["corpus", "regressions"] {
                    let d = dir.join(sub).join(t.name);
                    corpus.extend(
                        runner::load_dir(&d)
                            .with_context(|| format!("reading {}", d.display()))?
                            .into_iter()
                            .map(|(_, data)| data),
                    );
                }
                let report = runner::fuzz(t, &corpus, seed, budget, max_len);
                let rate = report.inputs as f64 / report.elapsed.as_secs_f64().max(1e-9);
                match report.crash {
                    None => println!(
                        "{:<16} {} inputs in {:.1} s ({rate:.0}/s), no crash",
                        t.name,
                        report.inputs,
                        report.elapsed.as_secs_f64()
                    ),
                    Some(c) => {
                        clean = false;
                        let out = dir.join("regressions").join(t.name);
                        std::fs::create_dir_all(&out)
                            .with_context(|| format!("creating {}", out.display()))?;
                        let path = out.join(runner::crash_name(&c.input));
                        std::fs::write(&path, &c.input)
                            .with_context(|| format!("writing {}", path.display()))?;
                        println!(
                            "{:<16} CRASH after {} inputs: {}\n  input kept as {}",
                            t.name,
                            report.inputs,
                            c.message,
                            path.display()
                        );
                    }
                }
            }
            Ok(clean)
        }
    }
}
