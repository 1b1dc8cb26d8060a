//! `vtol-gcs params pull|push|get|set|diff|save`: files are read and checked before any link
//! is opened, a push or set is one transaction, and every outcome is one line (docs/cli.md).

use std::io::{IsTerminal, Write};
use std::path::PathBuf;
use std::process::ExitCode;

use clap::{Args, Subcommand};
use tokio::sync::watch;
use vtol_gcs::client::ClientHandle;
use vtol_gcs::params::file::{self, ParamFile};
use vtol_gcs::params::plan::{ParamOutcome, PushReport, PushResult};
use vtol_gcs::params::{self as params, Format, Param, ParamSet, Rules as _};
use vtol_link::{ComponentId, SystemId};

use super::{
    EXIT_DIFFERENT, EXIT_REFUSED, EXIT_ROLLBACK, EXIT_USAGE, Failure, LinkArgs, usage, with_client,
};

/// `vtol-gcs params ...`.
#[derive(Debug, Args)]
pub struct ParamsArgs {
    #[command(subcommand)]
    command: ParamsCommand,
    /// Read the table with the parameter protocol even when the vehicle offers it as a file
    /// over MAVLink FTP.
    #[arg(long, global = true)]
    no_ftp: bool,
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

/// `params ...`.
// Long: one arm per `params` subcommand, each a few client calls and its output, inside the
// one client session they share.
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
    let ftp = !args.no_ftp;
    with_client(&args.link, |c| async move {
        match command {
            ParamsCommand::Pull { output, format } => {
                let t0 = std::time::Instant::now();
                let set = pull(&c, ftp).await?;
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
                let set = pull(&c, ftp).await?;
                file::save(
                    &path,
                    &set,
                    format,
                    c.target().unwrap_or((SystemId(1), ComponentId(1))),
                )
                .map_err(|e| usage(e.to_string()))?;
                let line = format!("{} parameters written to {}", set.len(), path.display());
                // Saved to standard output (`-`): the file is the output, the report goes aside.
                if path.as_os_str() == "-" {
                    eprintln!("{line}");
                } else {
                    println!("{line}");
                }
                Ok(())
            }
            ParamsCommand::Get { names } => {
                for name in names {
                    let p = c.param_get(&name).await?;
                    println!("{name} {}", file::format_value(p.value));
                }
                Ok(())
            }
            ParamsCommand::Diff { file: path } => {
                let wanted = wanted.ok_or_else(|| usage("no file loaded"))?;
                let current = pull(&c, ftp).await?;
                check_names(&current, &wanted)?;
                let changes = params::diff(&current, &wanted.params);
                if !changes.is_empty() {
                    println!("NAME vehicle -> {}", path.display());
                }
                for ch in &changes {
                    println!(
                        "{} {} -> {}",
                        ch.name,
                        file::format_value(ch.old),
                        file::format_value(ch.new)
                    );
                }
                println!("{} differ", changes.len());
                if changes.is_empty() {
                    Ok(())
                } else {
                    // Like diff(1): 1 when they differ, with nothing on standard error.
                    Err(Failure {
                        code: EXIT_DIFFERENT,
                        message: String::new(),
                    })
                }
            }
            ParamsCommand::Push { dry_run, .. } => {
                let wanted = wanted.ok_or_else(|| usage("no file loaded"))?;
                push(&c, &wanted, dry_run, "push", ftp).await
            }
            ParamsCommand::Set { .. } => {
                let wanted = wanted.ok_or_else(|| usage("no values given"))?;
                push(&c, &wanted, false, "set", ftp).await
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

async fn pull(c: &ClientHandle, ftp: bool) -> Result<ParamSet, Failure> {
    let (tx, task) = show_progress("parameters");
    let r = c.params_pull_via(tx, ftp).await;
    if let Some(t) = task {
        let _ = t.await;
    }
    Ok(r?)
}

/// Whole numbers within their type's range for the vehicle's integer parameters: anything
/// else would be rounded or clamped by the vehicle without a word, so it is refused here,
/// before anything is sent.
fn check_integers(current: &ParamSet, wanted: &ParamFile) -> Result<(), Failure> {
    let rounded: Vec<String> = wanted
        .params
        .iter()
        .filter_map(|(name, p)| {
            let now = current.get(name)?;
            let stored = params::stored_value(now.ty, p.value);
            (params::is_integer(now.ty) && stored != p.value).then(|| {
                format!(
                    "{name} is an integer parameter: {} would be stored as {}",
                    file::format_value(p.value),
                    file::format_value(stored)
                )
            })
        })
        .collect();
    if rounded.is_empty() {
        return Ok(());
    }
    Err(usage(format!("{}; nothing sent", rounded.join("; "))))
}

fn print_changes(order: &[params::Change]) {
    let mut out = std::io::stdout().lock();
    for ch in order {
        let _ = writeln!(
            out,
            "{} {} -> {}",
            ch.name,
            file::format_value(ch.old),
            file::format_value(ch.new)
        );
    }
}

/// `params push FILE` (`what` = "push") or `params set NAME VALUE ...` ("set").
async fn push(
    c: &ClientHandle,
    wanted: &ParamFile,
    dry_run: bool,
    what: &str,
    ftp: bool,
) -> Result<(), Failure> {
    let mut current = pull(c, ftp).await?;
    // Parameters the vehicle has only once an enable parameter of the file is set (ArduPilot's
    // `Q_TILT_ENABLE 1` adds the `Q_TILT_*`): those enables are written first, then the table
    // is read again; if the rest then fails, they are restored too.
    let mut enables_before: Option<ParamSet> = None;
    if !dry_run && !params::unknown_names(&current, &wanted.params).is_empty() {
        let enables = changed_enables(&current, wanted);
        if !enables.is_empty() {
            let report = c
                .push_onto(&current, &enables, &params::TwinRules, None)
                .await?;
            if !matches!(report.result, PushResult::Applied) {
                return report_push(&report, what);
            }
            let before: ParamSet = enables
                .keys()
                .filter_map(|n| current.get(n).map(|p| (n.clone(), *p)))
                .collect();
            for (name, old) in &before {
                println!(
                    "{name} {} -> {} (written first: it adds parameters)",
                    file::format_value(old.value),
                    file::format_value(params::stored_value(old.ty, enables[name].value))
                );
            }
            enables_before = Some(before);
            current = pull(c, ftp).await?;
        }
    }
    let result = push_checked(c, &current, wanted, dry_run, what).await;
    if let (Err(_), Some(before)) = (&result, &enables_before) {
        // Put the enables back as they were (the table shrinks again).
        let restored = c
            .push_onto(&current, before, &params::TwinRules, None)
            .await;
        if !restored.is_ok_and(|r| matches!(r.result, PushResult::Applied)) {
            let names: Vec<&str> = before.keys().map(String::as_str).collect();
            return Err(Failure {
                code: EXIT_ROLLBACK,
                message: format!(
                    "{what} failed and {} could not be restored: {}",
                    names.join(", "),
                    result.err().map_or_else(String::new, |f| f.message)
                ),
            });
        }
    }
    result
}

/// The `*_ENABLE` parameters `wanted` changes.
fn changed_enables(current: &ParamSet, wanted: &ParamFile) -> ParamSet {
    wanted
        .params
        .iter()
        .filter(|(n, p)| {
            n.ends_with("_ENABLE")
                && current.get(*n).is_some_and(|c| {
                    !params::same_value(c.value, params::stored_value(c.ty, p.value))
                })
        })
        .map(|(n, p)| (n.clone(), *p))
        .collect()
}

/// [`push`] once every name of the file is on the vehicle.
async fn push_checked(
    c: &ClientHandle,
    current: &ParamSet,
    wanted: &ParamFile,
    dry_run: bool,
    what: &str,
) -> Result<(), Failure> {
    check_names(current, wanted)?;
    check_integers(current, wanted)?;
    let changes = params::diff(current, &wanted.params);
    let order = params::order_writes(current, &changes, &params::TwinRules);
    if dry_run {
        print_changes(&order);
        // What the twin's rules predict for this order; the vehicle has the last word.
        let mut state = current.clone();
        let mut refused = 0;
        for ch in &order {
            match params::TwinRules.refusal(&state, &ch.name, ch.new) {
                Some(reason) => {
                    refused += 1;
                    println!("{}: likely refused: {reason}", ch.name);
                }
                None => {
                    if let Some(p) = state.get_mut(&ch.name) {
                        p.value = ch.new;
                    }
                }
            }
        }
        println!("{} would change (dry run: nothing written)", order.len());
        if refused > 0 {
            return Err(Failure {
                code: EXIT_REFUSED,
                message: format!(
                    "{refused} of {} changes would likely be refused (dry run: nothing written)",
                    order.len()
                ),
            });
        }
        return Ok(());
    }
    let (tx, task) = show_progress("writing");
    let report = c
        .push_onto(current, &wanted.params, &params::TwinRules, tx)
        .await;
    if let Some(t) = task {
        let _ = t.await;
    }
    let report = report?;
    if matches!(report.result, PushResult::Applied) {
        print_changes(&order);
    }
    report_push(&report, what)
}

/// The outcome of a push or set: the changes made, or one error line saying what the vehicle
/// refused and what it holds now.
fn report_push(r: &PushReport, what: &str) -> Result<(), Failure> {
    let v = file::format_value;
    match &r.result {
        PushResult::Applied => {
            println!("{} changed", r.changed);
            Ok(())
        }
        PushResult::RolledBack { cause } => {
            let mut details = Vec::new();
            for (name, o) in &r.outcomes {
                match o {
                    ParamOutcome::Refused { reason, .. } => {
                        details.push(format!("{name} refused: {reason}"));
                    }
                    ParamOutcome::RolledBack { old, written } => details.push(format!(
                        "{name} written {} then restored to {}",
                        v(*written),
                        v(*old)
                    )),
                    _ => {}
                }
            }
            // What ended the push comes first, unless it is one of the refusals listed: a value
            // that went unanswered or read back changed undid writes the vehicle had taken.
            if !cause.is_empty() && !details.iter().any(|d| d.starts_with(cause.as_str())) {
                details.insert(0, cause.clone());
            }
            Err(Failure {
                code: EXIT_REFUSED,
                message: format!(
                    "{what} refused, vehicle left as it was (0 changed): {}",
                    details.join("; ")
                ),
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
                    holds.push(format!(
                        "{name} = {now} (was {}; restore failed: {reason})",
                        v(*old)
                    ));
                }
            }
            Err(Failure {
                code: EXIT_ROLLBACK,
                message: format!(
                    "{what} failed ({cause}) and the rollback did not complete: the vehicle now holds {}",
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
        assert!(report_push(&ok, "push").is_ok());
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
        let f = report_push(&refused, "set").expect_err("refused");
        assert_eq!(f.code, EXIT_REFUSED);
        assert!(
            f.message.starts_with("set refused") && f.message.contains("LAT_SAT_B refused"),
            "{}",
            f.message
        );
        assert!(!f.message.contains("refused; "), "{}", f.message);
        // Writes the vehicle took, undone because a read-back went unanswered: the cause first.
        let lost = report(
            PushResult::RolledBack {
                cause: "ALT_KP: read-back failed: no answer after 12 tries".into(),
            },
            &[(
                "ALT_KP",
                ParamOutcome::RolledBack {
                    old: 5.0,
                    written: 4.5,
                },
            )],
        );
        let f = report_push(&lost, "push").expect_err("rolled back");
        assert_eq!(f.code, EXIT_REFUSED);
        assert!(
            f.message.ends_with(
                "(0 changed): ALT_KP: read-back failed: no answer after 12 tries; \
                 ALT_KP written 4.5 then restored to 5"
            ),
            "{}",
            f.message
        );
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
        let f = report_push(&stuck, "push").expect_err("incomplete");
        assert_eq!(f.code, EXIT_ROLLBACK);
        assert!(
            f.message
                .contains("now holds LAT_SAT_D = 0.15 (was 0.3; restore failed"),
            "{}",
            f.message
        );
    }
}
