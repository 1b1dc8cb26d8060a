//! The `vtol-gcs` binary end to end: the daemon on the embedded twin, a TCP client that sees
//! the vehicle, and a clean SIGTERM shutdown that leaves a complete tlog behind.

use std::io::{BufRead, BufReader, Read, Write};
use std::net::TcpStream;
use std::process::{Child, Command, Stdio};
use std::sync::mpsc;
use std::time::{Duration, Instant};

use vtol_gcs::tlog::TlogReader;
use vtol_link::FrameDecoder;

struct Daemon {
    child: Child,
    lines: mpsc::Receiver<String>,
}

impl Daemon {
    fn start(args: &[&str]) -> Self {
        let mut child = Command::new(env!("CARGO_BIN_EXE_vtol-gcs"))
            .args(args)
            .stdout(Stdio::piped())
            .stderr(Stdio::inherit())
            .spawn()
            .expect("start vtol-gcs");
        let out = child.stdout.take().unwrap();
        let (tx, lines) = mpsc::channel();
        std::thread::spawn(move || {
            for line in BufReader::new(out).lines().map_while(Result::ok) {
                if tx.send(line).is_err() {
                    break;
                }
            }
        });
        Self { child, lines }
    }

    /// The first stdout line starting with `prefix`, waiting at most 20 s.
    fn line_starting(&self, prefix: &str) -> String {
        let deadline = Instant::now() + Duration::from_secs(20);
        loop {
            let left = deadline.saturating_duration_since(Instant::now());
            let line = self
                .lines
                .recv_timeout(left)
                .unwrap_or_else(|_| panic!("no '{prefix}' line"));
            if let Some(rest) = line.strip_prefix(prefix) {
                return rest.trim().to_owned();
            }
        }
    }
}

impl Daemon {
    /// SIGTERM, then waits (at most 20 s) for a successful exit.
    fn terminate(&mut self) {
        let status = Command::new("kill")
            .args(["-TERM", &self.child.id().to_string()])
            .status()
            .unwrap();
        assert!(status.success());
        let deadline = Instant::now() + Duration::from_secs(20);
        let exit = loop {
            if let Some(s) = self.child.try_wait().unwrap() {
                break s;
            }
            assert!(Instant::now() < deadline, "daemon did not exit on SIGTERM");
            std::thread::sleep(Duration::from_millis(20));
        };
        assert!(exit.success(), "exit status {exit}");
    }
}

/// Runs the binary expecting it to fail at start; returns its one line of standard error.
fn failing_start(args: &[&str]) -> String {
    let out = Command::new(env!("CARGO_BIN_EXE_vtol-gcs"))
        .args(args)
        .env_remove("RUST_BACKTRACE")
        .output()
        .unwrap();
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    let lines: Vec<&str> = err.lines().filter(|l| !l.trim().is_empty()).collect();
    assert_eq!(lines.len(), 1, "{err}");
    lines[0].to_owned()
}

impl Drop for Daemon {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

#[test]
fn serves_the_embedded_twin_and_shuts_down_cleanly_on_sigterm() {
    let dir = tempfile::tempdir().unwrap();
    let log_dir = dir.path().to_str().unwrap();
    let mut d = Daemon::start(&[
        "run",
        "--serve",
        "tcpin:127.0.0.1:0",
        "--log-dir",
        log_dir,
        "--headless",
    ]);
    let serving = d.line_starting("serving tcpin:");
    let tlog = d.line_starting("logging ");
    let mut sock = TcpStream::connect(serving.as_str()).expect("connect to the serve port");
    sock.set_read_timeout(Some(Duration::from_secs(10)))
        .unwrap();
    // Read until a vehicle heartbeat (system 1, not the daemon's own 255) arrives.
    let mut dec = FrameDecoder::new();
    let mut buf = [0u8; 4096];
    let deadline = Instant::now() + Duration::from_secs(20);
    let mut vehicle_frames = 0;
    while Instant::now() < deadline && vehicle_frames < 20 {
        let n = sock.read(&mut buf).expect("read from the daemon");
        assert!(n > 0, "daemon closed the connection");
        dec.push(&buf[..n]);
        vehicle_frames += dec.frames().filter(|f| f.system_id() == 1).count();
    }
    assert!(vehicle_frames >= 20, "only {vehicle_frames} vehicle frames");
    // A client's own heartbeat, as a script through the daemon sends it.
    let beat = vtol_link::Frame::encode_v2(
        vtol_link::SystemId(255),
        vtol_link::ComponentId(0),
        0,
        &vtol_link::gcs_heartbeat(),
    );
    sock.write_all(beat.as_bytes()).unwrap();
    sock.write_all(b"\xfe\x00garbage that is not mavlink")
        .unwrap();
    // Until the heartbeat is routed (the tlog writes within 100 ms): a SIGTERM sent at once
    // could come before the daemon has read it from its socket.
    let client_beat = |records: &[(u64, vtol_link::Frame)]| {
        records
            .iter()
            .any(|(t, f)| t & 3 == 3 && (f.system_id(), f.component_id()) == (255, 0))
    };
    let deadline = Instant::now() + Duration::from_secs(10);
    while Instant::now() < deadline {
        let records: Vec<_> = TlogReader::open(std::path::Path::new(&tlog))
            .unwrap()
            .collect();
        if client_beat(&records) {
            break;
        }
        std::thread::sleep(Duration::from_millis(20));
    }

    d.terminate();
    let mut reader = TlogReader::open(std::path::Path::new(&tlog)).unwrap();
    let records: Vec<_> = reader.by_ref().collect();
    assert_eq!(
        reader.skipped_bytes, 0,
        "a clean shutdown leaves no torn record"
    );
    assert!(
        records
            .iter()
            .any(|(t, f)| t & 3 == 0 && f.system_id() == 1),
        "vehicle frames logged"
    );
    assert!(client_beat(&records), "the client's heartbeat logged");
    // Headless, no operator is present: the daemon's own client (255, 190) sends no heartbeat.
    assert!(
        !records
            .iter()
            .any(|(_, f)| (f.system_id(), f.component_id()) == (255, 190)),
        "the daemon sent a heartbeat with no operator present"
    );
}

#[test]
fn a_broken_config_file_is_one_clear_error() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("bad.toml");
    std::fs::write(&path, "serve = [\"tcpin:127.0.0.1:0\"\nheadless = tru\n").unwrap();
    let out = Command::new(env!("CARGO_BIN_EXE_vtol-gcs"))
        .args(["run", "--config", path.to_str().unwrap()])
        .output()
        .unwrap();
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        err.contains("invalid config") && err.contains("bad.toml"),
        "{err}"
    );
}

#[test]
fn a_serve_port_in_use_is_one_clear_line() {
    let taken = std::net::TcpListener::bind("127.0.0.1:0").unwrap();
    let port = taken.local_addr().unwrap().port();
    let line = failing_start(&[
        "run",
        "--no-log",
        "--serve",
        &format!("tcpin:127.0.0.1:{port}"),
    ]);
    assert!(
        line.starts_with("error: cannot open tcpin:") && line.contains("in use"),
        "{line}"
    );
}

#[test]
fn two_daemons_sharing_a_log_dir_keep_two_whole_logs() {
    let dir = tempfile::tempdir().unwrap();
    let log_dir = dir.path().to_str().unwrap();
    let args = [
        "run",
        "--serve",
        "tcpin:127.0.0.1:0",
        "--log-dir",
        log_dir,
        "--headless",
    ];
    // Started together, they ask for the same name within the same second: that is the case
    // under test, so a pair that straddled a second boundary is started again (at most 5
    // times; each try is a few milliseconds wide, so one almost always does).
    let second_of = |p: &str| {
        let name = std::path::Path::new(p)
            .file_stem()
            .unwrap()
            .to_string_lossy()
            .into_owned();
        name[..19].to_owned() // YYYY-MM-DD_HH-MM-SS, without a -N suffix
    };
    let mut tries = 0;
    let (mut daemons, paths) = loop {
        tries += 1;
        let mut daemons = [Daemon::start(&args), Daemon::start(&args)];
        let paths: Vec<String> = daemons
            .iter()
            .map(|d| d.line_starting("logging "))
            .collect();
        if second_of(&paths[0]) == second_of(&paths[1]) || tries == 5 {
            break (daemons, paths);
        }
        for d in &mut daemons {
            d.terminate();
        }
    };
    assert_eq!(
        second_of(&paths[0]),
        second_of(&paths[1]),
        "five pairs straddled a second"
    );
    assert_ne!(paths[0], paths[1], "both daemons were given one file");
    // The second name is the first one's with a suffix: the collision happened and was solved.
    assert!(
        paths.iter().any(|p| p.ends_with("-2.tlog")),
        "no -2 suffix: {paths:?}"
    );
    // Wait (at most 20 s) until each log holds a run of the vehicle's frames.
    let deadline = Instant::now() + Duration::from_secs(20);
    for p in &paths {
        while TlogReader::open(std::path::Path::new(p))
            .unwrap()
            .filter(|(_, f)| f.system_id() == 1)
            .count()
            < 50
        {
            assert!(Instant::now() < deadline, "{p} stays short");
            std::thread::sleep(Duration::from_millis(20));
        }
    }
    for d in &mut daemons {
        d.terminate();
    }
    // Each file is one daemon's log: it reads cleanly and the embedded twin's sequence numbers
    // run on without a jump (two runs interleaved in one file would break both).
    for p in &paths {
        let mut reader = TlogReader::open(std::path::Path::new(p)).unwrap();
        let seqs: Vec<u8> = reader
            .by_ref()
            .filter(|(t, f)| t & 3 == 0 && f.system_id() == 1)
            .map(|(_, f)| f.seq())
            .collect();
        assert_eq!(reader.skipped_bytes, 0, "{p} has torn records");
        assert!(seqs.len() >= 50, "{p}: {} vehicle frames", seqs.len());
        for w in seqs.windows(2) {
            assert_eq!(w[1], w[0].wrapping_add(1), "{p}: sequence jumps");
        }
    }
}

#[test]
fn a_serial_vehicle_that_does_not_exist_is_one_clear_line() {
    let dir = tempfile::tempdir().unwrap();
    let device = dir.path().join("ttyUSB-missing");
    let line = failing_start(&[
        "run",
        "--no-log",
        "--serve",
        "tcpin:127.0.0.1:0",
        "--vehicle",
        &format!("serial:{}:57600", device.display()),
    ]);
    assert!(
        line.contains("ttyUSB-missing") && line.contains("does not exist"),
        "{line}"
    );
}

#[test]
fn a_closed_standard_output_ends_the_status_lines_not_the_daemon() {
    let dir = tempfile::tempdir().unwrap();
    let mut child = Command::new(env!("CARGO_BIN_EXE_vtol-gcs"))
        .args(["run", "--serve", "tcpin:127.0.0.1:0", "--headless"])
        .args(["--log-dir", dir.path().to_str().unwrap()])
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("start vtol-gcs");
    let (tx, stderr_lines) = mpsc::channel();
    let err = child.stderr.take().unwrap();
    std::thread::spawn(move || {
        for line in BufReader::new(err).lines().map_while(Result::ok) {
            let _ = tx.send(line);
        }
    });
    // Read the start-up lines, then go away as `vtol-gcs run | head` does.
    let mut out = BufReader::new(child.stdout.take().unwrap());
    let serving = loop {
        let mut line = String::new();
        assert!(out.read_line(&mut line).unwrap() > 0, "stdout ended early");
        if let Some(rest) = line.strip_prefix("serving tcpin:") {
            break rest.trim().to_owned();
        }
    };
    drop(out);
    // The next status line finds the pipe closed: one line on stderr says so.
    let deadline = Instant::now() + Duration::from_secs(20);
    loop {
        let left = deadline.saturating_duration_since(Instant::now());
        let line = stderr_lines
            .recv_timeout(left)
            .expect("no line on stderr about the closed standard output");
        assert!(!line.contains("panicked"), "{line}");
        if line.contains("status lines stopped") {
            break;
        }
    }
    // The daemon still serves the vehicle.
    let mut sock = TcpStream::connect(serving.as_str()).expect("connect to the serve port");
    sock.set_read_timeout(Some(Duration::from_secs(10)))
        .unwrap();
    let mut dec = FrameDecoder::new();
    let mut buf = [0u8; 4096];
    let mut vehicle_frames = 0;
    while Instant::now() < deadline && vehicle_frames < 20 {
        let n = sock.read(&mut buf).expect("read from the daemon");
        assert!(n > 0, "daemon closed the connection");
        dec.push(&buf[..n]);
        vehicle_frames += dec.frames().filter(|f| f.system_id() == 1).count();
    }
    assert!(vehicle_frames >= 20, "only {vehicle_frames} vehicle frames");
    assert!(child.try_wait().unwrap().is_none(), "the daemon exited");
    let mut d = Daemon {
        child,
        lines: mpsc::channel().1,
    };
    d.terminate();
}

#[test]
fn a_listening_vehicle_url_is_printed_with_its_real_port() {
    let mut d = Daemon::start(&[
        "run",
        "--vehicle",
        "udpin:127.0.0.1:0",
        "--serve",
        "tcpin:127.0.0.1:0",
        "--no-log",
    ]);
    let vehicle = d.line_starting("vehicle udpin:");
    let serving = d.line_starting("serving tcpin:");
    let addr: std::net::SocketAddr = vehicle.parse().expect("a real address");
    assert_ne!(addr.port(), 0, "port 0 printed");
    // The printed port is the vehicle link: a vehicle's heartbeat sent there reaches a client.
    let mut client = TcpStream::connect(serving.as_str()).unwrap();
    client
        .set_read_timeout(Some(Duration::from_millis(200)))
        .unwrap();
    let vehicle_sock = std::net::UdpSocket::bind("127.0.0.1:0").unwrap();
    let beat = vtol_link::Frame::encode_v2(
        vtol_link::SystemId(7),
        vtol_link::ComponentId(1),
        0,
        &vtol_link::gcs_heartbeat(),
    );
    let mut dec = FrameDecoder::new();
    let mut buf = [0u8; 4096];
    let deadline = Instant::now() + Duration::from_secs(20);
    let mut heard = false;
    while !heard && Instant::now() < deadline {
        vehicle_sock.send_to(beat.as_bytes(), addr).unwrap();
        if let Ok(n) = client.read(&mut buf) {
            assert!(n > 0, "daemon closed the connection");
            dec.push(&buf[..n]);
            heard = dec.frames().any(|f| f.system_id() == 7);
        }
    }
    assert!(heard, "the vehicle's heartbeat never reached the client");
    d.terminate();
}
