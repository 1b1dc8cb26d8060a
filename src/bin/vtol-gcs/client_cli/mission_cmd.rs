//! `vtol-gcs mission upload|download|clear|start|set-current|show`, for the mission, fence or
//! rally list (`--type`). A file is read and checked before any link is opened: a bad item
//! sends nothing. An upload is verified by downloading the list again.

use std::path::{Path, PathBuf};
use std::process::ExitCode;

use clap::{Args, Subcommand, ValueEnum};
use vtol_gcs::client::ClientHandle;
use vtol_gcs::client::mission::{UploadOutcome, result_words};
use vtol_gcs::mission::file::{self, Format};
use vtol_gcs::mission::verify::{difference, load};
use vtol_gcs::mission::{Item, Kind, command_name, frame_name};
use vtol_link::dialect::MavMissionResult;
use vtol_link::text_file;

use super::{EXIT_REFUSED, EXIT_USAGE, Failure, LinkArgs, usage, with_client};

/// `vtol-gcs mission ...`.
#[derive(Debug, Args)]
pub struct MissionArgs {
    #[command(subcommand)]
    command: MissionCommand,
    /// Which list: mission, fence or rally.
    #[arg(long = "type", default_value = "mission", value_parser = parse_kind, global = true)]
    kind: Kind,
    #[command(flatten)]
    link: LinkArgs,
}

fn parse_kind(s: &str) -> Result<Kind, String> {
    s.parse()
}

/// A file format for standard output.
#[derive(Debug, Clone, Copy, ValueEnum)]
enum FormatArg {
    /// QGC WPL 110 text.
    Wpl,
    /// QGroundControl .plan JSON.
    Plan,
}

#[derive(Debug, Subcommand)]
enum MissionCommand {
    /// Check a file (QGC WPL 110 or .plan), upload it, and verify it by downloading it again.
    Upload {
        /// The file; its content decides the format.
        file: PathBuf,
    },
    /// Download the list into FILE (.plan, else QGC WPL), or print it.
    Download {
        /// The file; `-` or none for standard output.
        file: Option<PathBuf>,
        /// Format on standard output (a file's extension decides otherwise).
        #[arg(long, value_enum, default_value = "wpl")]
        format: FormatArg,
    },
    /// Remove the list from the vehicle.
    Clear,
    /// Start the mission (MAV_CMD_MISSION_START: ArduPlane switches to AUTO; it does not arm),
    /// or with SEQ: make SEQ current, then switch to AUTO.
    Start {
        /// The item to start at.
        seq: Option<u16>,
    },
    /// Make SEQ the item the mission flies next.
    SetCurrent {
        /// The item.
        seq: u16,
    },
    /// A table of the vehicle's list, or of FILE's without a link.
    Show {
        /// A mission file to show instead of the vehicle's list.
        file: Option<PathBuf>,
    },
}

/// `mission ...`.
pub fn mission(args: MissionArgs) -> ExitCode {
    let kind = args.kind;
    // Files are read and checked before any link is opened: a bad item sends nothing.
    let loaded = match &args.command {
        MissionCommand::Upload { file } | MissionCommand::Show { file: Some(file) } => {
            match load(file, kind) {
                Ok(items) => Some(items),
                Err(problems) => {
                    for p in &problems {
                        eprintln!("error: {p}");
                    }
                    if matches!(args.command, MissionCommand::Upload { .. }) {
                        eprintln!("error: nothing was sent");
                    }
                    return ExitCode::from(EXIT_USAGE);
                }
            }
        }
        _ => None,
    };
    if let (MissionCommand::Show { .. }, Some(items)) = (&args.command, &loaded) {
        print!("{}", table(items, kind));
        return ExitCode::SUCCESS;
    }
    let command = args.command;
    with_client(&args.link, |c| async move {
        match command {
            MissionCommand::Upload { file } => {
                let items = loaded.unwrap_or_default();
                upload(&c, &items, kind, &file).await
            }
            MissionCommand::Download { file, format } => {
                let t0 = std::time::Instant::now();
                let items = c.mission_download(kind, |_, _| {}).await?;
                let took = t0.elapsed();
                match file.filter(|f| f.as_os_str() != "-") {
                    Some(path) => {
                        let text = file::write(&items, kind, Format::for_path(&path));
                        text_file::write_text(&path, &text).map_err(|e| usage(e.to_string()))?;
                        eprintln!(
                            "{} {} items written to {} (download {:.0} ms)",
                            items.len(),
                            kind.name(),
                            path.display(),
                            took.as_secs_f64() * 1e3
                        );
                    }
                    None => {
                        let format = match format {
                            FormatArg::Wpl => Format::Wpl,
                            FormatArg::Plan => Format::Plan,
                        };
                        print!("{}", file::write(&items, kind, format));
                    }
                }
                Ok(())
            }
            MissionCommand::Clear => {
                c.mission_clear(kind).await?;
                println!("{} cleared", kind.name());
                Ok(())
            }
            MissionCommand::Start { seq } => {
                match seq {
                    // ArduPilot denies MISSION_START with a first item: make it current, then
                    // AUTO flies from it.
                    Some(seq) => {
                        c.mission_set_current(seq).await?;
                        c.set_mode("AUTO").await?;
                    }
                    None => c.mission_start(None).await?,
                }
                match seq {
                    Some(s) => println!("mission started at item {s}"),
                    None => println!("mission started"),
                }
                Ok(())
            }
            MissionCommand::SetCurrent { seq } => {
                c.mission_set_current(seq).await?;
                println!("current item {seq}");
                Ok(())
            }
            MissionCommand::Show { .. } => {
                let items = c.mission_download(kind, |_, _| {}).await?;
                print!("{}", table(&items, kind));
                Ok(())
            }
        }
    })
}

/// Uploads, then downloads and compares.
async fn upload(c: &ClientHandle, items: &[Item], kind: Kind, path: &Path) -> Result<(), Failure> {
    let t0 = std::time::Instant::now();
    let outcome = c.mission_upload(items, kind, |_, _| {}).await?;
    let took = t0.elapsed();
    let ack_lost = match outcome {
        UploadOutcome::Acked {
            result: MavMissionResult::MAV_MISSION_ACCEPTED,
            ..
        } => false,
        UploadOutcome::Acked { result, reason } => {
            return Err(Failure {
                code: EXIT_REFUSED,
                message: format!(
                    "refused by the vehicle: {}{}",
                    result_words(result),
                    reason.map(|r| format!(": {r}")).unwrap_or_default(),
                ),
            });
        }
        UploadOutcome::NoAck { .. } => true,
    };
    let t1 = std::time::Instant::now();
    let back = c.mission_download(kind, |_, _| {}).await?;
    let verify = t1.elapsed();
    let diff = difference(items, &back, kind);
    if let (Some(diff), UploadOutcome::NoAck { requested, total }) = (&diff, &outcome) {
        return Err(super::link_failure(format!(
            "no MISSION_ACK from the vehicle (it asked for {requested} of {total} items) and it \
             holds another {}: {diff}",
            kind.name()
        )));
    }
    if let Some(diff) = diff {
        return Err(Failure {
            code: EXIT_REFUSED,
            message: format!(
                "the vehicle {} the upload{} but holds another {}: {diff}",
                if ack_lost {
                    "did not acknowledge"
                } else {
                    "acknowledged"
                },
                if ack_lost {
                    ""
                } else {
                    " (MAV_MISSION_ACCEPTED)"
                },
                kind.name()
            ),
        });
    }
    println!(
        "uploaded {} {} items from {} (verified by download; upload {:.0} ms, verify {:.0} ms)",
        items.len(),
        kind.name(),
        path.display(),
        took.as_secs_f64() * 1e3,
        verify.as_secs_f64() * 1e3
    );
    Ok(())
}

/// The meaning of a command's first four parameters, where it is well known.
fn param_names(command: u16) -> [&'static str; 4] {
    use num_traits::FromPrimitive;
    use vtol_link::dialect::MavCmd as C;
    match C::from_u16(command) {
        Some(C::MAV_CMD_NAV_WAYPOINT) => ["hold s", "accept m", "pass m", "yaw deg"],
        Some(C::MAV_CMD_NAV_LOITER_TIME) => ["time s", "", "radius m", "xtrack"],
        Some(C::MAV_CMD_NAV_LOITER_UNLIM) => ["", "", "radius m", "yaw deg"],
        Some(C::MAV_CMD_NAV_LAND | C::MAV_CMD_NAV_VTOL_LAND) => {
            ["abort alt m", "land mode", "", "yaw deg"]
        }
        Some(C::MAV_CMD_NAV_TAKEOFF | C::MAV_CMD_NAV_VTOL_TAKEOFF) => {
            ["pitch deg", "transition", "", "yaw deg"]
        }
        Some(C::MAV_CMD_DO_JUMP) => ["to item", "repeat", "", ""],
        Some(C::MAV_CMD_DO_CHANGE_SPEED) => ["speed type", "speed m/s", "throttle %", ""],
        Some(C::MAV_CMD_DO_VTOL_TRANSITION) => ["state", "", "", ""],
        Some(
            C::MAV_CMD_NAV_FENCE_POLYGON_VERTEX_INCLUSION
            | C::MAV_CMD_NAV_FENCE_POLYGON_VERTEX_EXCLUSION,
        ) => ["vertices", "", "", ""],
        Some(C::MAV_CMD_NAV_FENCE_CIRCLE_INCLUSION | C::MAV_CMD_NAV_FENCE_CIRCLE_EXCLUSION) => {
            ["radius m", "", "", ""]
        }
        _ => ["p1", "p2", "p3", "p4"],
    }
}

/// The list as a table in words.
fn table(items: &[Item], kind: Kind) -> String {
    if items.is_empty() {
        return format!("no {} items\n", kind.name());
    }
    let mut rows = vec![[
        "seq".to_owned(),
        "command".to_owned(),
        "frame".to_owned(),
        "position".to_owned(),
        "altitude".to_owned(),
        "parameters".to_owned(),
    ]];
    for (seq, i) in items.iter().enumerate() {
        let mut command = command_name(i.command);
        if kind == Kind::Mission && seq == 0 {
            command.push_str(" (home)");
        }
        let position = if vtol_gcs::mission::is_global(i.frame) {
            if i.has_position() {
                format!("{:.7}, {:.7}", i.x, i.y)
            } else {
                "here".to_owned()
            }
        } else if i.x != 0.0 || i.y != 0.0 {
            format!("{}, {}", i.x, i.y)
        } else {
            "-".to_owned()
        };
        let params: Vec<String> = param_names(i.command)
            .iter()
            .zip(i.params)
            .enumerate()
            .filter(|(_, (_, v))| *v != 0.0)
            .map(|(k, (name, v))| {
                let name = if name.is_empty() {
                    format!("p{}", k + 1)
                } else {
                    (*name).to_owned()
                };
                format!("{name} {v}")
            })
            .collect();
        rows.push([
            seq.to_string(),
            command,
            frame_name(i.frame),
            position,
            format!("{} m", i.z),
            params.join(", "),
        ]);
    }
    let mut widths = [0usize; 6];
    for r in &rows {
        for (w, cell) in widths.iter_mut().zip(r) {
            *w = (*w).max(cell.chars().count());
        }
    }
    let mut out = String::new();
    for r in &rows {
        let mut line = String::new();
        for (k, (w, cell)) in widths.iter().zip(r).enumerate() {
            if k == 5 {
                line.push_str(cell);
            } else {
                line.push_str(&format!("{cell:<w$}  "));
            }
        }
        out.push_str(line.trim_end());
        out.push('\n');
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_table_names_commands_frames_and_parameters() {
        let text = "QGC WPL 110\n0\t1\t0\t16\t0\t0\t0\t0\t-35.363262\t149.165237\t584.09\t1\n\
                    1\t0\t3\t84\t0\t0\t0\t0\t0\t0\t30\t1\n\
                    2\t0\t3\t16\t5\t2\t0\t0\t-35.361\t149.165\t60\t1\n";
        let items: Vec<Item> = file::read(text, Kind::Mission)
            .expect("reads")
            .into_iter()
            .map(|l| l.item)
            .collect();
        let t = table(&items, Kind::Mission);
        let lines: Vec<&str> = t.lines().collect();
        assert!(lines[0].starts_with("seq  command"), "{t}");
        assert!(
            lines[1].contains("NAV_WAYPOINT (home)") && lines[1].contains("GLOBAL "),
            "{t}"
        );
        assert!(lines[1].contains("-35.3632620, 149.1652370") && lines[1].contains("584.09 m"));
        assert!(
            lines[2].contains("NAV_VTOL_TAKEOFF") && lines[2].contains("here"),
            "{t}"
        );
        assert!(lines[3].ends_with("hold s 5, accept m 2"), "{t}");
        assert_eq!(table(&[], Kind::Fence), "no fence items\n");
    }
}
