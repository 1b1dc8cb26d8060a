//! Log tools benchmark: frames/s of `log stats` against pymavlink's `mavlogdump.py -q` on the
//! same 1-million-frame tlog, and the time of `log plot --kind all` on a one-hour flight log.
//!
//! ```text
//! cargo bench --bench log_tools            # full run: 1 M frames, pymavlink, a 1 h log (~2 min)
//! cargo test  --bench log_tools            # smoke run: 20 k frames, a 60 s log, no pymavlink
//! ```
//! (`LOG_TOOLS_QUICK=1` also selects the smoke run.) pymavlink is run from the venv of
//! `tests/run.sh` (`$VENV`, default `.venv`; `/work/main/.venv` style paths work too).
//!
//! The logs are generated here, deterministically, with the twin's message mix and rates
//! (ATTITUDE 20 Hz, LOCAL_POSITION_NED and SERVO_OUTPUT_RAW 10 Hz, RC_CHANNELS 4 Hz, SCALED_IMU
//! and RAW_IMU 2 Hz, HEARTBEAT, SYS_STATUS, SYSTEM_TIME, EXTENDED_SYS_STATE 1 Hz, plus the
//! ground station's 1 Hz HEARTBEAT) by this project's tlog writer, into a temporary directory
//! that is removed afterwards (the 1 M-frame file is about 50 MB). CPU time is utime + stime
//! from `/proc/self/stat` (this process) and the children's fields after `wait` (pymavlink).

use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::Instant;

use vtol_gcs::log::plot::{self, Kind, PlotOptions};
use vtol_gcs::log::{open_tlog, stats};
use vtol_gcs::tlog::{Direction, Record, TlogWriter};
use vtol_link::Frame;
use vtol_link::dialect as apm;

/// Clock ticks per second of /proc times (Linux's USER_HZ).
const TICKS_HZ: f64 = 100.0;

/// (own utime + stime, children's utime + stime) in seconds.
fn cpu_s() -> (f64, f64) {
    let stat = std::fs::read_to_string("/proc/self/stat").unwrap_or_default();
    // Fields after the command name (which is in parentheses and may hold spaces).
    let rest = stat.rsplit_once(')').map_or("", |(_, r)| r);
    let f: Vec<f64> = rest
        .split_whitespace()
        .map(|x| x.parse().unwrap_or(0.0))
        .collect();
    // rest[0] is field 3 (state): utime 14, stime 15, cutime 16, cstime 17.
    let get = |field: usize| f.get(field - 3).copied().unwrap_or(0.0) / TICKS_HZ;
    (get(14) + get(15), get(16) + get(17))
}

/// The twin's streams over one second, 20 slots of 50 ms: (slot set, message).
fn second_of_flight(i: u32) -> Vec<(u8, u8, apm::MavMessage)> {
    let t = f64::from(i);
    let ms = i * 1000;
    let mut out = Vec::new();
    for k in 0..20u32 {
        let tk = t + f64::from(k) * 0.05;
        let ms = ms + k * 50;
        out.push((
            1,
            1,
            apm::MavMessage::ATTITUDE(apm::ATTITUDE_DATA {
                time_boot_ms: ms,
                roll: (0.05 * (tk * 0.7).sin()) as f32,
                pitch: (0.03 * (tk * 0.4).cos()) as f32,
                yaw: (0.2 * (tk * 0.05).sin()) as f32,
                ..Default::default()
            }),
        ));
        if k % 2 == 0 {
            out.push((
                1,
                1,
                apm::MavMessage::LOCAL_POSITION_NED(apm::LOCAL_POSITION_NED_DATA {
                    time_boot_ms: ms,
                    x: (0.02 * (tk * 0.3).sin()) as f32,
                    y: (0.02 * (tk * 0.2).cos()) as f32,
                    z: -1.0,
                    ..Default::default()
                }),
            ));
            out.push((
                1,
                1,
                apm::MavMessage::SERVO_OUTPUT_RAW(apm::SERVO_OUTPUT_RAW_DATA {
                    time_usec: ms.wrapping_mul(1000),
                    servo1_raw: 1681 + (k % 5) as u16,
                    servo2_raw: 1680,
                    servo3_raw: 1500 + (k % 3) as u16,
                    servo4_raw: 1500,
                    servo5_raw: 1502,
                    ..Default::default()
                }),
            ));
        }
        if k % 5 == 0 {
            out.push((
                1,
                1,
                apm::MavMessage::RC_CHANNELS(apm::RC_CHANNELS_DATA {
                    time_boot_ms: ms,
                    chancount: 8,
                    chan3_raw: 1500,
                    ..Default::default()
                }),
            ));
        }
        if k % 10 == 0 {
            out.push((
                1,
                1,
                apm::MavMessage::SCALED_IMU(apm::SCALED_IMU_DATA {
                    time_boot_ms: ms,
                    ..Default::default()
                }),
            ));
            out.push((
                1,
                1,
                apm::MavMessage::RAW_IMU(apm::RAW_IMU_DATA {
                    time_usec: u64::from(ms) * 1000,
                    ..Default::default()
                }),
            ));
        }
    }
    out.push((1, 1, firmware_heartbeat()));
    out.push((255, 190, vtol_link::gcs_heartbeat()));
    out.push((
        1,
        1,
        apm::MavMessage::SYSTEM_TIME(apm::SYSTEM_TIME_DATA {
            time_unix_usec: 0,
            time_boot_ms: ms,
        }),
    ));
    out.push((
        1,
        1,
        apm::MavMessage::SYS_STATUS(apm::SYS_STATUS_DATA::default()),
    ));
    out.push((
        1,
        1,
        apm::MavMessage::EXTENDED_SYS_STATE(apm::EXTENDED_SYS_STATE_DATA::default()),
    ));
    out
}

fn firmware_heartbeat() -> apm::MavMessage {
    apm::MavMessage::HEARTBEAT(apm::HEARTBEAT_DATA {
        custom_mode: 18,
        mavtype: apm::MavType::MAV_TYPE_VTOL_TAILSITTER_DUOROTOR,
        autopilot: apm::MavAutopilot::MAV_AUTOPILOT_GENERIC,
        base_mode: apm::MavModeFlag::MAV_MODE_FLAG_CUSTOM_MODE_ENABLED,
        system_status: apm::MavState::MAV_STATE_ACTIVE,
        mavlink_version: 3,
    })
}

/// Writes seconds of flight until `frames` records (or `seconds`) are written; returns frames.
fn write_log(path: &Path, max_frames: u64, seconds: u32) -> u64 {
    let mut w = TlogWriter::create(path).expect("create bench log");
    let t0 = 1_795_346_880_000_000u64;
    let mut n = 0u64;
    let mut seq = [0u8; 2];
    'outer: for s in 0..seconds {
        let msgs = second_of_flight(s);
        let per = msgs.len() as u64;
        for (j, (sys, comp, m)) in msgs.into_iter().enumerate() {
            if n == max_frames {
                break 'outer;
            }
            let idx = usize::from(sys != 1);
            let frame = Frame::encode_v2(
                vtol_link::SystemId(sys),
                vtol_link::ComponentId(comp),
                seq[idx],
                &m,
            );
            seq[idx] = seq[idx].wrapping_add(1);
            let t_us = t0 + u64::from(s) * 1_000_000 + j as u64 * 1_000_000 / per;
            let direction = if sys == 1 {
                Direction::FromVehicle
            } else {
                Direction::ToVehicle
            };
            w.write(&Record {
                t_us,
                direction,
                frame,
            })
            .expect("write bench log");
            n += 1;
        }
    }
    w.flush().expect("flush bench log");
    n
}

fn venv_python() -> Option<(PathBuf, PathBuf)> {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let venv = std::env::var_os("VENV").map_or_else(|| root.join(".venv"), PathBuf::from);
    let venv = if venv.is_absolute() {
        venv
    } else {
        root.join(venv)
    };
    let py = venv.join("bin/python");
    let dump = venv.join("bin/mavlogdump.py");
    (py.exists() && dump.exists()).then_some((py, dump))
}

fn main() {
    let quick =
        std::env::var_os("LOG_TOOLS_QUICK").is_some() || !std::env::args().any(|a| a == "--bench");
    let (frames_target, plot_seconds) = if quick {
        (20_000, 60)
    } else {
        (1_000_000, 3600)
    };
    let dir = tempfile::tempdir().expect("temp dir");

    // --- log stats vs mavlogdump.py ----------------------------------------------------------
    let path = dir.path().join("bench.tlog");
    let frames = write_log(&path, frames_target, u32::MAX);
    let size = std::fs::metadata(&path).map_or(0, |m| m.len());
    println!("log stats: {frames} frames, {:.1} MB", size as f64 / 1e6);
    let (cpu0, _) = cpu_s();
    let t = Instant::now();
    let (mut reader, size) = open_tlog(&path).expect("open");
    let directions = vtol_gcs::log::directions(&path).expect("open");
    let s = stats::scan(&mut reader, size, directions, &mut |_| {});
    let wall = t.elapsed().as_secs_f64();
    let cpu = cpu_s().0 - cpu0;
    assert_eq!(s.frames, frames, "stats must see every frame");
    let ours = frames as f64 / wall;
    println!(
        "  vtol-gcs log stats: {wall:.3} s wall, {cpu:.2} s CPU, {:.2} M frames/s, {:.0} ns CPU/frame",
        ours / 1e6,
        cpu / frames as f64 * 1e9
    );
    if quick {
        println!("  (smoke run: pymavlink skipped)");
    } else if let Some((py, dump)) = venv_python() {
        let (_, child0) = cpu_s();
        let t = Instant::now();
        let status = Command::new(&py)
            .arg(&dump)
            .arg("-q")
            .arg(&path)
            .stdout(std::process::Stdio::null())
            .status()
            .expect("run mavlogdump.py");
        let wall_py = t.elapsed().as_secs_f64();
        let cpu_py = cpu_s().1 - child0;
        assert!(status.success(), "mavlogdump.py failed: {status}");
        let theirs = frames as f64 / wall_py;
        println!(
            "  pymavlink mavlogdump.py -q: {wall_py:.1} s wall, {cpu_py:.1} s CPU, {:.0} k frames/s, {:.0} µs CPU/frame",
            theirs / 1e3,
            cpu_py / frames as f64 * 1e6
        );
        println!(
            "  ratio: {:.0}x by wall time, {:.0}x by CPU time (target >= 50x)",
            ours / theirs,
            cpu_py / cpu.max(0.01)
        );
    } else {
        println!("  pymavlink venv not found (set VENV): comparison skipped");
    }

    // --- log plot of a long flight -----------------------------------------------------------
    let long = dir.path().join("hour.tlog");
    let n = write_log(&long, u64::MAX, plot_seconds);
    println!(
        "log plot --kind all: {plot_seconds} s flight, {n} frames, {:.1} MB",
        std::fs::metadata(&long).map_or(0, |m| m.len()) as f64 / 1e6
    );
    let out = dir.path().join("hour.png");
    let (cpu0, _) = cpu_s();
    let t = Instant::now();
    let data = plot::load(&long).expect("load");
    let t_load = t.elapsed().as_secs_f64();
    let panels = plot::draw(
        &data,
        None,
        &out,
        &PlotOptions {
            kind: Kind::All,
            frame: plot::Frame::Ned,
            size: None,
            setpoint: None,
            title: None,
        },
    )
    .expect("draw")
    .panels
    .len();
    let wall = t.elapsed().as_secs_f64();
    let cpu = cpu_s().0 - cpu0;
    println!(
        "  {panels} panels: {wall:.3} s wall (read {t_load:.3} s, draw + PNG {:.3} s), {cpu:.2} s CPU (target < 2 s)",
        wall - t_load
    );
}
