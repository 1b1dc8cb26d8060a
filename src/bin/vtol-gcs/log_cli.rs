//! `vtol-gcs log stats|export|plot`: the command line of the log tools. The library does the
//! work; this prints the reports and draws the progress bar (on stderr, only on a terminal).

use std::path::{Path, PathBuf};

use anyhow::Context;
use clap::{Args, Subcommand};
use indicatif::{ProgressBar, ProgressStyle};
use vtol_gcs::log::export::{self, ExportReport, Selection};
use vtol_gcs::log::plot::{self, Frame, Kind, PlotOptions};
use vtol_gcs::log::{open_tlog, stats};

/// `log` subcommands.
#[derive(Debug, Subcommand)]
pub enum LogCommand {
    /// Duration, frames and rate per message type, sources with sequence loss, damage.
    Stats {
        /// The tlog.
        file: PathBuf,
        /// Print the report as JSON.
        #[arg(long)]
        json: bool,
    },
    /// Messages as CSV (one file per type, or one table with --rate) or as MCAP.
    Export(ExportArgs),
    /// PNG figures in the paper's layout, from a tlog or a `firmware-sim simulate` CSV.
    Plot(PlotArgs),
}

/// Flags of `log export`.
#[derive(Debug, Args)]
pub struct ExportArgs {
    /// The tlog.
    file: PathBuf,
    /// CSV output: a directory (one NAME.csv per message type), or with --rate one file.
    #[arg(long, required_unless_present = "mcap")]
    csv: Option<PathBuf>,
    /// MCAP output file (JSON messages with a JSON schema per type).
    #[arg(long)]
    mcap: Option<PathBuf>,
    /// Only these message types, e.g. ATTITUDE,SERVO_OUTPUT_RAW.
    #[arg(long, value_delimiter = ',')]
    messages: Vec<String>,
    /// One wide CSV table resampled at this rate (latest value at or before each row's time).
    #[arg(long, requires = "csv")]
    rate: Option<f64>,
}

/// Flags of `log plot`.
#[derive(Debug, Args)]
pub struct PlotArgs {
    /// A tlog or a `firmware-sim simulate` CSV.
    file: PathBuf,
    /// Output PNG.
    #[arg(short = 'o', long = "output")]
    output: PathBuf,
    /// Which figure.
    #[arg(long, value_enum, default_value_t = Kind::All)]
    kind: Kind,
    /// A second source drawn on the same axes (e.g. an offline flight against a logged one).
    #[arg(long)]
    compare: Option<PathBuf>,
    /// Picture size WIDTHxHEIGHT in pixels (default: by figure).
    #[arg(long, value_parser = parse_size)]
    size: Option<(u32, u32)>,
    /// Axes: ned (North, East, Down; roll, pitch, yaw in degrees, as the UI shows them) or
    /// paper (x = −North, y = East, z up; φ = −roll, θ = pitch, ψ = −yaw in rad).
    #[arg(long, value_enum, default_value_t = Frame::Ned)]
    frame: Frame,
    /// A constant position setpoint to draw, three numbers in m in the --frame's axes (e.g.
    /// 0,0,1 for z = 1 m up with --frame paper). A tlog's own position target is drawn anyway.
    #[arg(long, value_parser = parse_setpoint)]
    setpoint: Option<[f64; 3]>,
    /// Figure title (default: the figure and the file names).
    #[arg(long)]
    title: Option<String>,
}

fn parse_size(s: &str) -> Result<(u32, u32), String> {
    let (w, h) = s
        .split_once('x')
        .ok_or("expected WIDTHxHEIGHT, e.g. 1200x900")?;
    let px = |v: &str| {
        v.parse::<u32>()
            .ok()
            .filter(|p| (200..=10_000).contains(p))
            .ok_or(format!("'{v}' is not a size between 200 and 10000 px"))
    };
    Ok((px(w)?, px(h)?))
}

fn parse_setpoint(s: &str) -> Result<[f64; 3], String> {
    let v: Vec<f64> = s
        .split(',')
        .map(|x| x.trim().parse::<f64>().ok().filter(|v| v.is_finite()))
        .collect::<Option<_>>()
        .ok_or(format!("'{s}' is not three finite numbers x,y,z"))?;
    v.try_into()
        .map_err(|_| format!("'{s}' is not three numbers x,y,z"))
}

fn progress_bar(path: &Path) -> ProgressBar {
    let size = std::fs::metadata(path).map_or(0, |m| m.len());
    let bar = ProgressBar::new(size);
    if let Ok(style) =
        ProgressStyle::with_template("{bar:40} {bytes}/{total_bytes} {bytes_per_sec} {eta}")
    {
        bar.set_style(style);
    }
    bar
}

fn damage_line(skipped: u64, tail: u64) -> Option<String> {
    let mut parts = Vec::new();
    if skipped > 0 {
        parts.push(format!(
            "{skipped} bytes skipped as garbage or damaged records"
        ));
    }
    if tail > 0 {
        parts.push(format!("truncated last record ({tail} bytes)"));
    }
    (!parts.is_empty()).then(|| format!("damage: {}", parts.join(", ")))
}

fn print_export(r: &ExportReport) {
    // An export to standard output (`-`) keeps it for the data: the report goes to stderr.
    let to_stdout = r.files.iter().any(|f| f.as_os_str() == "-");
    let say = |line: String| {
        if to_stdout {
            eprintln!("{line}");
        } else {
            println!("{line}");
        }
    };
    for (name, rows) in &r.rows {
        say(format!("{name}: {rows}"));
    }
    for f in &r.files {
        say(format!("wrote {}", f.display()));
    }
    if r.undecodable > 0 {
        eprintln!(
            "{} frames the dialect cannot decode were not exported",
            r.undecodable
        );
    }
    if let Some(d) = damage_line(r.skipped_bytes, r.truncated_tail_bytes) {
        eprintln!("{d}");
    }
}

/// Runs one `log` subcommand.
///
/// # Errors
/// Unreadable input, unwritable output, or a request the input cannot honour.
pub fn run(cmd: LogCommand) -> anyhow::Result<()> {
    match cmd {
        LogCommand::Stats { file, json } => {
            let directions = vtol_gcs::log::directions(&file)?;
            let (mut reader, size) = open_tlog(&file)?;
            let bar = progress_bar(&file);
            let s = stats::scan(&mut reader, size, directions, &mut |n| {
                bar.set_position(n);
            });
            bar.finish_and_clear();
            vtol_gcs::log::finish_read(&mut reader, &file)?;
            // A file with no record at all is no log: say so and fail, instead of a table of
            // zeros that looks like an answer.
            if s.frames == 0 {
                anyhow::bail!(
                    "{}: no tlog record in {} bytes (not a tlog, or empty)",
                    file.display(),
                    s.file_bytes
                );
            }
            if json {
                println!("{}", serde_json::to_string_pretty(&s)?);
            } else {
                print!("{}", stats::render(&s));
            }
        }
        LogCommand::Export(a) => {
            let selection = if a.messages.is_empty() {
                Selection::all()
            } else {
                Selection::only(&a.messages)?
            };
            if let Some(out) = &a.csv {
                let bar = progress_bar(&a.file);
                let r = match a.rate {
                    Some(rate) => export::csv_wide(&a.file, out, &selection, rate, &mut |n| {
                        bar.set_position(n);
                    }),
                    None => export::csv_per_type(&a.file, out, &selection, &mut |n| {
                        bar.set_position(n);
                    }),
                };
                bar.finish_and_clear();
                print_export(&r?);
            }
            if let Some(out) = &a.mcap {
                let bar = progress_bar(&a.file);
                let r = export::mcap(&a.file, out, &selection, &mut |n| bar.set_position(n));
                bar.finish_and_clear();
                print_export(&r?);
            }
        }
        LogCommand::Plot(a) => {
            let main = plot::load(&a.file)?;
            let compare = a.compare.as_deref().map(plot::load).transpose()?;
            let opts = PlotOptions {
                kind: a.kind,
                frame: a.frame,
                size: a.size,
                setpoint: a.setpoint,
                title: a.title,
            };
            let figure = plot::draw(&main, compare.as_ref(), &a.output, &opts)
                .map_err(anyhow::Error::from)
                .with_context(|| format!("plotting {}", a.file.display()))?;
            let line = format!(
                "wrote {} ({} panels)",
                a.output.display(),
                figure.panels.len()
            );
            if a.output.as_os_str() == "-" {
                eprintln!("{line}");
            } else {
                println!("{line}");
            }
        }
    }
    Ok(())
}
