//! The twin as a running vehicle: `serve` over a real tcpin socket (port 0), the in-memory
//! embedding, and the `firmware-sim serve` command line. Every wait is a message awaited under
//! `tokio::time::timeout`; nothing sleeps to let state settle.

use std::time::Duration;

use firmware_sim::shell::clock::ClockMode;
use firmware_sim::shell::harness::HarnessError;
use firmware_sim::shell::serve::{ServeConfig, Twin};
use mavlink::dialects::ardupilotmega as apm;
use mavlink::types::CharArray;
use tokio::io::{AsyncRead, AsyncReadExt, AsyncWrite, AsyncWriteExt};
use tokio::net::TcpStream;
use tokio_util::sync::CancellationToken;
use vtol_link::{Frame, FrameDecoder, FrameSource};

const BOUND: Duration = Duration::from_secs(10);

/// Kills the child process if the test fails before it is stopped.
struct KillOnDrop(Option<std::process::Child>);

impl Drop for KillOnDrop {
    fn drop(&mut self) {
        if let Some(c) = self.0.as_mut() {
            let _ = c.kill();
            let _ = c.wait();
        }
    }
}

/// A minimal GCS over any byte stream, sysid 255 / compid 190.
struct Gcs<S> {
    stream: S,
    decoder: FrameDecoder,
    out: FrameSource,
}

impl<S: AsyncRead + AsyncWrite + Unpin> Gcs<S> {
    fn new(stream: S) -> Self {
        Self {
            stream,
            decoder: FrameDecoder::new(),
            out: FrameSource::new(vtol_link::SystemId(255), vtol_link::ComponentId(190)),
        }
    }

    async fn send(&mut self, msg: &apm::MavMessage) {
        let f = self.out.encode_v2(msg);
        self.stream.write_all(f.as_bytes()).await.unwrap();
    }

    async fn send_raw(&mut self, frame: &Frame) {
        self.stream.write_all(frame.as_bytes()).await.unwrap();
    }

    async fn next_frame(&mut self) -> Frame {
        loop {
            if let Some(f) = self.decoder.next_frame() {
                return f;
            }
            let mut buf = [0u8; 4096];
            let n = self.stream.read(&mut buf).await.unwrap();
            assert!(n > 0, "vehicle closed the stream");
            self.decoder.push(&buf[..n]);
        }
    }

    /// The first frame satisfying `pred`, within [`BOUND`].
    async fn wait_for<T>(&mut self, what: &str, mut pred: impl FnMut(&Frame) -> Option<T>) -> T {
        let fut = async {
            loop {
                let f = self.next_frame().await;
                assert_eq!(f.as_bytes()[0], 0xFD, "the vehicle always sends MAVLink 2");
                if let Some(t) = pred(&f) {
                    return t;
                }
            }
        };
        tokio::time::timeout(BOUND, fut)
            .await
            .unwrap_or_else(|_| panic!("timed out waiting for {what}"))
    }

    async fn heartbeat(&mut self) -> apm::HEARTBEAT_DATA {
        self.wait_for("HEARTBEAT", |f| match f.decode() {
            Ok(apm::MavMessage::HEARTBEAT(h)) => Some(h),
            _ => None,
        })
        .await
    }

    /// (command, result) of the next COMMAND_ACK, read raw so unknown command ids work.
    async fn ack(&mut self) -> (u16, u8) {
        self.wait_for("COMMAND_ACK", |f| {
            (f.message_id() == 77).then(|| {
                let mut p = f.payload().to_vec();
                p.resize(10, 0);
                (u16::from_le_bytes([p[0], p[1]]), p[2])
            })
        })
        .await
    }
}

fn command_long(command: apm::MavCmd, p1: f32, p2: f32) -> apm::MavMessage {
    apm::MavMessage::COMMAND_LONG(apm::COMMAND_LONG_DATA {
        param1: p1,
        param2: p2,
        command,
        target_system: 1,
        target_component: 0,
        ..Default::default()
    })
}

fn config(listen: &[&str]) -> ServeConfig {
    let mut c = ServeConfig {
        listen: listen.iter().map(|u| u.parse().unwrap()).collect(),
        clock: ClockMode::Scaled { speed: 4.0 },
        ..ServeConfig::default()
    };
    c.endpoint.vehicle.ideal_sensors = true;
    c
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn serve_over_tcp_heartbeat_params_commands() {
    let cancel = CancellationToken::new();
    let twin = Twin::start(config(&["tcpin:127.0.0.1:0"]), cancel.clone())
        .await
        .unwrap();
    let addr = twin.bound()[0]
        .local_addr
        .expect("tcpin has a local address");
    assert_ne!(addr.port(), 0);
    assert_eq!(
        twin.bound()[0].resolved_url(),
        format!("tcpin:127.0.0.1:{}", addr.port())
    );
    let mut gcs = Gcs::new(TcpStream::connect(addr).await.unwrap());

    let hb = gcs.heartbeat().await;
    assert_eq!(hb.mavtype as u8, 1, "MAV_TYPE_FIXED_WING, as ArduPlane");
    assert_eq!(
        hb.base_mode.bits() & 0x81,
        0x01,
        "custom mode enabled, not armed"
    );

    // The whole parameter table.
    gcs.send(&apm::MavMessage::PARAM_REQUEST_LIST(
        apm::PARAM_REQUEST_LIST_DATA {
            target_system: 1,
            target_component: 0,
        },
    ))
    .await;
    let count = firmware_sim::nav::params::TABLE.len();
    let mut seen = vec![false; count];
    while seen.iter().any(|s| !s) {
        let v = gcs
            .wait_for("PARAM_VALUE", |f| match f.decode() {
                Ok(apm::MavMessage::PARAM_VALUE(v)) => Some(v),
                _ => None,
            })
            .await;
        assert_eq!(usize::from(v.param_count), count);
        seen[usize::from(v.param_index)] = true;
    }

    // PARAM_SET echo.
    gcs.send(&apm::MavMessage::PARAM_SET(apm::PARAM_SET_DATA {
        param_value: 1.5,
        target_system: 1,
        target_component: 1,
        param_id: CharArray::from("HOVER_ALT"),
        param_type: apm::MavParamType::MAV_PARAM_TYPE_REAL32,
    }))
    .await;
    let echo = gcs
        .wait_for("PARAM_VALUE echo", |f| match f.decode() {
            Ok(apm::MavMessage::PARAM_VALUE(v)) if v.param_id.to_str() == Ok("HOVER_ALT") => {
                Some(v)
            }
            _ => None,
        })
        .await;
    assert_eq!(echo.param_value, 1.5);

    // A command id the dialect does not know, sent raw: ACK UNSUPPORTED.
    let mut payload = [0u8; 33];
    payload[28..30].copy_from_slice(&65000u16.to_le_bytes());
    payload[30] = 1;
    let raw = Frame::encode_raw_v2(
        vtol_link::SystemId(255),
        vtol_link::ComponentId(190),
        9,
        76,
        &payload,
        152,
    )
    .unwrap();
    gcs.send_raw(&raw).await;
    assert_eq!(gcs.ack().await, (65000, 3));

    // Arm: ACK ACCEPTED, then a heartbeat with bit 128.
    gcs.send(&command_long(
        apm::MavCmd::MAV_CMD_COMPONENT_ARM_DISARM,
        1.0,
        0.0,
    ))
    .await;
    assert_eq!(gcs.ack().await, (400, 0));
    let hb = gcs.heartbeat().await;
    assert_eq!(hb.base_mode.bits() & 128, 128, "armed after the ACK");

    // A second client on the same listener is served too.
    let mut second = Gcs::new(TcpStream::connect(addr).await.unwrap());
    let hb = second.heartbeat().await;
    assert_eq!(hb.base_mode.bits() & 128, 128);

    cancel.cancel();
    let endpoint = tokio::time::timeout(BOUND, twin.join())
        .await
        .expect("clean stop");
    assert!(endpoint.is_some_and(|e| e.stats().frames_in >= 4));
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn embedded_twin_over_duplex() {
    let cancel = CancellationToken::new();
    let twin = Twin::start(config(&[]), cancel.clone()).await.unwrap();
    let (ours, theirs) = tokio::io::duplex(64 * 1024);
    twin.attach_stream(theirs, "test duplex");
    let mut gcs = Gcs::new(ours);
    let hb = gcs.heartbeat().await;
    assert_eq!(hb.custom_mode, 17);
    gcs.send(&command_long(apm::MavCmd::MAV_CMD_DO_SET_MODE, 1.0, 18.0))
        .await;
    assert_eq!(gcs.ack().await, (176, 0));
    let mode = gcs
        .wait_for("QHOVER heartbeat", |f| match f.decode() {
            Ok(apm::MavMessage::HEARTBEAT(h)) if h.custom_mode == 18 => Some(h.custom_mode),
            _ => None,
        })
        .await;
    assert_eq!(mode, 18);
    cancel.cancel();
    tokio::time::timeout(BOUND, twin.join())
        .await
        .expect("clean stop");
}

/// `firmware-sim serve`: the stdout address line, a heartbeat on it, and a persisted change.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn cli_prints_bound_address_and_persists_params() {
    let dir = tempfile::tempdir().unwrap();
    let param_file = dir.path().join("twin.parm");
    let mut child = std::process::Command::new(env!("CARGO_BIN_EXE_firmware-sim"))
        .args([
            "serve",
            "--listen",
            "tcpin:127.0.0.1:0",
            "--speed",
            "4",
            "--param-file",
        ])
        .arg(&param_file)
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::null())
        .spawn()
        .unwrap();
    let stdout = child.stdout.take().unwrap();
    let mut guard = KillOnDrop(Some(child));
    let line = tokio::time::timeout(
        BOUND,
        tokio::task::spawn_blocking(move || {
            let mut line = String::new();
            std::io::BufRead::read_line(&mut std::io::BufReader::new(stdout), &mut line)
                .map(|_| line)
        }),
    )
    .await
    .expect("address line")
    .unwrap()
    .unwrap();
    let url = line
        .trim()
        .strip_prefix("listening ")
        .unwrap_or_else(|| panic!("{line:?}"));
    let port: u16 = url.rsplit(':').next().unwrap().parse().unwrap();
    assert_ne!(port, 0);
    let mut gcs = Gcs::new(TcpStream::connect(("127.0.0.1", port)).await.unwrap());
    gcs.heartbeat().await;
    gcs.send(&apm::MavMessage::PARAM_SET(apm::PARAM_SET_DATA {
        param_value: 2.0,
        target_system: 1,
        target_component: 1,
        param_id: CharArray::from("ALT_KD"),
        param_type: apm::MavParamType::MAV_PARAM_TYPE_REAL32,
    }))
    .await;
    gcs.wait_for("echo", |f| match f.decode() {
        Ok(apm::MavMessage::PARAM_VALUE(v)) if v.param_id.to_str() == Ok("ALT_KD") => Some(()),
        _ => None,
    })
    .await;
    // The echo follows the save, so the file is complete now.
    let saved = std::fs::read_to_string(&param_file).unwrap();
    assert!(saved.contains("ALT_KD           2\n"), "{saved}");
    // SIGTERM: a clean exit with status 0.
    let child = guard.0.take().unwrap();
    let pid = child.id().to_string();
    assert!(
        std::process::Command::new("kill")
            .args(["-TERM", &pid])
            .status()
            .unwrap()
            .success()
    );
    let status = tokio::time::timeout(
        BOUND,
        tokio::task::spawn_blocking(move || {
            let mut child = child;
            child.wait()
        }),
    )
    .await
    .expect("exits after SIGTERM")
    .unwrap()
    .unwrap();
    assert!(status.success(), "{status:?}");

    // A corrupt file is a clear startup error, never replaced.
    std::fs::write(&param_file, "ALT_KD banana\n").unwrap();
    let bad_file = param_file.clone();
    let out = tokio::time::timeout(
        BOUND,
        tokio::task::spawn_blocking(move || {
            std::process::Command::new(env!("CARGO_BIN_EXE_firmware-sim"))
                .args(["serve", "--listen", "tcpin:127.0.0.1:0", "--param-file"])
                .arg(&bad_file)
                .output()
        }),
    )
    .await
    .expect("exits at once")
    .unwrap()
    .unwrap();
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        err.contains("twin.parm:1") && err.contains("bad value"),
        "{err}"
    );
    assert_eq!(
        std::fs::read_to_string(&param_file).unwrap(),
        "ALT_KD banana\n"
    );
}

/// Every ATTITUDE's `time_boot_ms` up to (and including) the first at or after `end_ms`.
async fn attitude_times<S: AsyncRead + AsyncWrite + Unpin>(
    gcs: &mut Gcs<S>,
    end_ms: u32,
) -> Vec<u32> {
    let mut times = Vec::new();
    while times.last().is_none_or(|&t| t < end_ms) {
        let t = gcs
            .wait_for("ATTITUDE", |f| match f.decode() {
                Ok(apm::MavMessage::ATTITUDE(a)) => Some(a.time_boot_ms),
                _ => None,
            })
            .await;
        times.push(t);
    }
    times
}

/// Under lockstep sim time moves only on `advance`; replies come at once; streams count sim
/// time, so an advance brings exactly its share of telemetry; the harness reads the true state
/// and writes parameters.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn lockstep_flies_only_when_the_harness_advances() {
    let cancel = CancellationToken::new();
    let mut c = config(&[]);
    c.clock = ClockMode::Lockstep;
    c.endpoint.vehicle.ideal_sensors = false;
    c.endpoint.vehicle.calibrated = true;
    let twin = Twin::start(c, cancel.clone()).await.unwrap();
    let harness = twin.harness();
    let (ours, theirs) = tokio::io::duplex(64 * 1024);
    twin.attach_stream(theirs, "test duplex");
    let mut gcs = Gcs::new(ours);

    let hb = gcs.heartbeat().await;
    assert_eq!(
        hb.system_status,
        apm::MavState::MAV_STATE_STANDBY,
        "ready to arm at t = 0"
    );
    gcs.send(&command_long(apm::MavCmd::MAV_CMD_DO_SET_MODE, 1.0, 18.0))
        .await;
    assert_eq!(gcs.ack().await, (176, 0));
    gcs.send(&command_long(
        apm::MavCmd::MAV_CMD_COMPONENT_ARM_DISARM,
        1.0,
        0.0,
    ))
    .await;
    assert_eq!(gcs.ack().await, (400, 0));
    let s = harness.state().await.unwrap();
    assert_eq!((s.t_us, s.armed, s.mode), (0, true, "QHOVER"));

    assert_eq!(harness.advance(2.0).await, Ok(2_000_000));
    // 20 Hz of sim time: 50, …, 2000 ms, each once (t = 0 came at connection, read above).
    let times = attitude_times(&mut gcs, 2000).await;
    assert_eq!(times, (50..=2000).step_by(50).collect::<Vec<u32>>());
    let s = harness.state().await.unwrap();
    assert_eq!(s.t_us, 2_000_000);
    assert!(s.altitude_m > 0.3 && !s.landed, "climbing in QHOVER: {s:?}");

    assert_eq!(harness.set_param("hover_alt", 2.0).await, Ok(2.0));
    let v = gcs
        .wait_for("PARAM_VALUE of the harness's write", |f| match f.decode() {
            Ok(apm::MavMessage::PARAM_VALUE(v)) if v.param_id.to_str() == Ok("HOVER_ALT") => {
                Some(v.param_value)
            }
            _ => None,
        })
        .await;
    assert_eq!(v, 2.0);
    assert_eq!(
        harness.set_param("NOPE", 1.0).await,
        Err(HarnessError::Refused("unknown parameter NOPE".into()))
    );
    assert_eq!(harness.advance(0.0).await, Ok(2_000_000));
    cancel.cancel();
    tokio::time::timeout(BOUND, twin.join())
        .await
        .expect("clean stop");
    assert_eq!(harness.state().await, Err(HarnessError::Stopped));
}

/// The twin runs on tokio's clock: under a paused clock 30 s of flight at 10× pass in no wall
/// time, and streams count that clock, not sim time (1 Hz heartbeats, 20 Hz ATTITUDE).
#[tokio::test(start_paused = true)]
async fn a_paused_clock_runs_the_twin_and_streams_keep_wall_rates() {
    let cancel = CancellationToken::new();
    let mut c = config(&[]);
    c.clock = ClockMode::Scaled { speed: 10.0 };
    let twin = Twin::start(c, cancel.clone()).await.unwrap();
    let (ours, theirs) = tokio::io::duplex(64 * 1024);
    twin.attach_stream(theirs, "test duplex");
    let mut gcs = Gcs::new(ours);
    let start = tokio::time::Instant::now();
    let mut heartbeats = 0;
    let mut attitudes = Vec::new();
    while attitudes.last().is_none_or(|&t| t < 30_000) {
        let f = gcs.next_frame().await;
        match f.decode() {
            Ok(apm::MavMessage::HEARTBEAT(_)) => heartbeats += 1,
            Ok(apm::MavMessage::ATTITUDE(a)) => attitudes.push(a.time_boot_ms),
            _ => {}
        }
    }
    let clock_s = start.elapsed().as_secs_f64();
    assert!((2.9..3.2).contains(&clock_s), "{clock_s} s of tokio time");
    assert!((3..=4).contains(&heartbeats), "{heartbeats} heartbeats");
    assert!((59..=62).contains(&attitudes.len()), "{attitudes:?}");
    // Each ATTITUDE carries the latest sample: half a second of sim time apart at 10×.
    let gaps: Vec<u32> = attitudes.windows(2).map(|w| w[1] - w[0]).collect();
    assert!(gaps.iter().all(|g| (495..=505).contains(g)), "{gaps:?}");
    assert!(
        matches!(twin.harness().advance(1.0).await, Err(HarnessError::Refused(e)) if e.contains("lockstep"))
    );
    cancel.cancel();
    twin.join().await;
}

/// A reader that leaves a flood of telemetry unread: the twin sheds telemetry and keeps the
/// parameter list waiting in order, so the whole list still arrives once the reader reads.
#[tokio::test(start_paused = true)]
async fn replies_are_never_lost_behind_telemetry() {
    let cancel = CancellationToken::new();
    let mut c = config(&[]);
    c.clock = ClockMode::REAL_TIME;
    c.link_options.queue_len = 16;
    let twin = Twin::start(c, cancel.clone()).await.unwrap();
    let (ours, theirs) = tokio::io::duplex(512);
    twin.attach_stream(theirs, "slow reader");
    let mut gcs = Gcs::new(ours);
    gcs.heartbeat().await;
    // Every stream at every batch.
    for msgid in [1u32, 2, 26, 27, 30, 31, 32, 36, 65, 245, 251] {
        let mut set = command_long(apm::MavCmd::MAV_CMD_SET_MESSAGE_INTERVAL, msgid as f32, 1.0);
        if let apm::MavMessage::COMMAND_LONG(c) = &mut set {
            c.target_component = 1;
        }
        gcs.send(&set).await;
        assert_eq!(gcs.ack().await, (511, 0), "interval of {msgid}");
    }
    gcs.send(&apm::MavMessage::PARAM_REQUEST_LIST(
        apm::PARAM_REQUEST_LIST_DATA {
            target_system: 1,
            target_component: 0,
        },
    ))
    .await;
    // A second of the (paused) clock passes with nothing read: 200 batches of telemetry and
    // the whole list meet a full queue.
    tokio::time::sleep(Duration::from_secs(1)).await;
    let count = firmware_sim::nav::params::TABLE.len();
    let mut seen = vec![false; count];
    while seen.iter().any(|s| !s) {
        let v = gcs
            .wait_for("PARAM_VALUE", |f| match f.decode() {
                Ok(apm::MavMessage::PARAM_VALUE(v)) => Some(v),
                _ => None,
            })
            .await;
        seen[usize::from(v.param_index)] = true;
    }
    // And the telemetry goes on once the replies are through.
    attitude_times(&mut gcs, 0).await;
    cancel.cancel();
    twin.join().await;
}

/// Impossible `serve` flags: one line on stderr each, exit status 2, nothing started.
#[test]
fn cli_refuses_impossible_serve_flags() {
    for (args, says) in [
        (&["--lockstep"][..], "--control"),
        (
            &["--lockstep", "--control", "tcpin:127.0.0.1:0", "--fast"][..],
            "--fast",
        ),
        (
            &["--control", "udpin:127.0.0.1:0"][..],
            "--control takes a tcpin",
        ),
        (&["--initial", "z=2"][..], "on the ground"),
        (
            &[
                "--lockstep",
                "--control",
                "tcpin:127.0.0.1:0",
                "--latency",
                "5",
            ][..],
            "--latency",
        ),
    ] {
        let out = std::process::Command::new(env!("CARGO_BIN_EXE_firmware-sim"))
            .args(["serve", "--listen", "tcpin:127.0.0.1:0"])
            .args(args)
            .output()
            .unwrap();
        let err = String::from_utf8_lossy(&out.stderr);
        assert!(!out.status.success(), "{args:?} started");
        assert!(out.stdout.is_empty(), "{args:?} printed {:?}", out.stdout);
        assert!(err.contains(says), "{args:?}: {err}");
        assert_eq!(err.trim().lines().count(), 1, "{args:?}: {err}");
    }
}

/// A `--param-file` the twin could never save is refused at start, in one line, before any
/// PARAM_SET can be accepted and then fail to persist. The places fail for root too: a path
/// under a regular file, a directory in the file's place, and /proc.
#[test]
fn cli_refuses_a_param_file_that_cannot_be_written() {
    let dir = tempfile::tempdir().unwrap();
    let plain = dir.path().join("plain-file");
    std::fs::write(&plain, b"not a directory").unwrap();
    let under_file = plain.join("params.parm");
    let a_dir = dir.path().join("a-dir");
    std::fs::create_dir(&a_dir).unwrap();
    for path in [
        under_file.as_path(),
        a_dir.as_path(),
        std::path::Path::new("/proc/vtol-twin.parm"),
    ] {
        let out = std::process::Command::new(env!("CARGO_BIN_EXE_firmware-sim"))
            .args(["serve", "--listen", "tcpin:127.0.0.1:0", "--param-file"])
            .arg(path)
            .output()
            .unwrap();
        let err = String::from_utf8_lossy(&out.stderr);
        assert!(!out.status.success(), "{} accepted", path.display());
        assert!(
            out.stdout.is_empty(),
            "{}: started: {:?}",
            path.display(),
            out.stdout
        );
        assert!(
            err.contains("cannot be written") && err.contains(&*path.to_string_lossy()),
            "{}: {err}",
            path.display()
        );
        assert_eq!(err.trim().lines().count(), 1, "{err}");
    }
}
