//! The twin as a running vehicle: `serve` over a real tcpin socket (port 0), the in-memory
//! embedding, and the `firmware-sim serve` command line. Every wait is a message awaited under
//! `tokio::time::timeout`; nothing sleeps to let state settle.

use std::time::Duration;

use firmware_sim::clock::ClockMode;
use firmware_sim::serve::{ServeConfig, Twin};
use mavlink::dialects::ardupilotmega as apm;
use mavlink::types::CharArray;
use tokio::io::{AsyncRead, AsyncReadExt, AsyncWrite, AsyncWriteExt};
use tokio::net::TcpStream;
use tokio_util::sync::CancellationToken;
use vtol_link::{Frame, FrameDecoder};

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
    seq: u8,
}

impl<S: AsyncRead + AsyncWrite + Unpin> Gcs<S> {
    fn new(stream: S) -> Self {
        Self {
            stream,
            decoder: FrameDecoder::new(),
            seq: 0,
        }
    }

    async fn send(&mut self, msg: &apm::MavMessage) {
        let f = Frame::encode_v2(255, 190, self.seq, msg);
        self.seq = self.seq.wrapping_add(1);
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
    assert_eq!(hb.mavtype as u8, 19);
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
    let count = firmware_sim::params::TABLE.len();
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
    let raw = Frame::encode_raw_v2(255, 190, 9, 76, &payload, 152).unwrap();
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
    assert!(saved.contains("ALT_KD           2.000000\n"), "{saved}");
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
