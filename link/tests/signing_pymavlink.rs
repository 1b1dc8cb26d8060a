//! vtol-link's signing against real pymavlink, over real UDP sockets on loopback.
//!
//! pymavlink (`setup_signing` with the SHA-256 of a passphrase) signs a COMMAND_LONG and a
//! PARAM_SET, and a second connection signs one with another key; vtol-link must accept the
//! first two, refuse the third and refuse a replay. Then vtol-link signs STATUSTEXTs and
//! pymavlink must accept its signed ones and refuse a replay, a wrong key and an unsigned one.
//! Nothing expected is written down here: both sides compute signatures at test time.
//!
//! The Python is the project's venv: `PYMAVLINK_PYTHON`, else `$VENV/bin/python`, else
//! `.venv/bin/python` at the workspace root (what `tests/run.sh` creates).

use std::io::Read;
use std::net::{SocketAddr, UdpSocket};
use std::path::PathBuf;
use std::process::{Command, Stdio};
use std::time::{Duration, Instant, SystemTime};

use bytes::Bytes;
use mavlink::types::CharArray;
use vtol_link::Frame;
use vtol_link::dialect::{self as apm, MavMessage};
use vtol_link::protocol::id::COMMAND_LONG as MSG_ID_COMMAND_LONG;
use vtol_link::signing::{
    Accepted, Refusal, SignatureFields, Signing, SigningKey, TIMESTAMP_UNITS_PER_S, timestamp_at,
};

const PASSPHRASE: &str = "vtol signing test passphrase";

/// Python side: sends, then collects what vtol-link sends back until the "end" text.
const SCRIPT: &str = r#"
import hashlib, json, os, sys, time
os.environ["MAVLINK20"] = "1"
from pymavlink import mavutil

port, passphrase = int(sys.argv[1]), sys.argv[2]
key = hashlib.sha256(passphrase.encode()).digest()
url = "udpout:127.0.0.1:%d" % port
right = mavutil.mavlink_connection(url, source_system=255, source_component=190)
right.setup_signing(key, sign_outgoing=True, link_id=7)
wrong = mavutil.mavlink_connection(url, source_system=255, source_component=191)
wrong.setup_signing(hashlib.sha256(b"another passphrase").digest(), sign_outgoing=True, link_id=7)
right.mav.command_long_send(1, 1, 400, 0, 1, 0, 0, 0, 0, 0, 0)
wrong.mav.command_long_send(1, 1, 400, 0, 1, 0, 0, 0, 0, 0, 0)
right.mav.param_set_send(1, 1, b"SIM_RATE", 2.0, 9)
texts = []
deadline = time.monotonic() + 10
while time.monotonic() < deadline:
    m = right.recv_match(blocking=True, timeout=0.5)
    if m is None or m.get_type() != "STATUSTEXT":
        continue
    texts.append(m.text)
    if m.text == "end":
        break
s = right.mav.signing
streams = {"%d,%d,%d" % k: v for k, v in s.stream_timestamps.items()}
print(json.dumps({"texts": texts, "goodsig": s.goodsig_count, "badsig": s.badsig_count,
                  "streams": streams}), flush=True)
"#;

fn python() -> PathBuf {
    if let Some(p) = std::env::var_os("PYMAVLINK_PYTHON") {
        return PathBuf::from(p);
    }
    let root = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("..");
    let venv = std::env::var_os("VENV").map_or_else(|| root.join(".venv"), |v| root.join(v));
    let p = venv.join("bin/python");
    assert!(
        p.exists(),
        "no Python with pymavlink at {}: run tests/run.sh once (it creates the venv) or set \
         PYMAVLINK_PYTHON",
        p.display()
    );
    p
}

fn statustext(text: &str) -> Frame {
    let msg = MavMessage::STATUSTEXT(apm::STATUSTEXT_DATA {
        severity: apm::MavSeverity::MAV_SEVERITY_INFO,
        text: CharArray::from(text),
        id: 0,
        chunk_seq: 0,
    });
    Frame::encode_v2(vtol_link::SystemId(1), vtol_link::ComponentId(1), 0, &msg)
}

#[test]
fn pymavlink_and_vtol_link_accept_each_others_signatures() {
    let sock = UdpSocket::bind("127.0.0.1:0").unwrap();
    sock.set_read_timeout(Some(Duration::from_millis(200)))
        .unwrap();
    let port = sock.local_addr().unwrap().port();
    let mut child = Command::new(python())
        .args(["-c", SCRIPT, &port.to_string(), PASSPHRASE])
        .stdout(Stdio::piped())
        .spawn()
        .expect("start python");

    // Three frames from pymavlink: compid 190 COMMAND_LONG and PARAM_SET, compid 191 (wrong key).
    let mut frames: Vec<(Frame, SocketAddr)> = Vec::new();
    let deadline = Instant::now() + Duration::from_secs(20);
    let mut buf = [0u8; 512];
    while frames.len() < 3 {
        assert!(
            Instant::now() < deadline,
            "pymavlink sent {} frames of 3",
            frames.len()
        );
        if let Ok((n, from)) = sock.recv_from(&mut buf) {
            let frame = Frame::from_bytes(Bytes::copy_from_slice(&buf[..n])).unwrap();
            frames.push((frame, from));
        }
    }
    let find = |comp: u8, id: u32| {
        frames
            .iter()
            .find(|(f, _)| f.component_id() == comp && f.message_id() == id)
            .cloned()
            .unwrap_or_else(|| panic!("no message {id} from component {comp}"))
    };
    let (command, reply_to) = find(190, MSG_ID_COMMAND_LONG);
    let (param_set, _) = find(190, 23);
    let (wrong, _) = find(191, MSG_ID_COMMAND_LONG);
    for f in [&command, &param_set, &wrong] {
        assert!(f.is_signed() && f.is_verified(), "{f:?}");
    }

    // pymavlink's timestamp reads as its wall clock: the byte order agrees.
    let theirs = SignatureFields::of(&command).unwrap().timestamp;
    let ours = timestamp_at(SystemTime::now());
    assert!(
        theirs <= ours && ours - theirs < 60 * TIMESTAMP_UNITS_PER_S,
        "pymavlink timestamp {theirs}, wall clock {ours}"
    );

    let key = SigningKey::from_passphrase(PASSPHRASE);
    let mut vehicle = Signing::new(key.clone(), 0, 0);
    assert!(matches!(
        vehicle.verify_now(&command),
        Ok(Accepted::Signed { link_id: 7, .. })
    ));
    assert!(matches!(
        vehicle.verify_now(&param_set),
        Ok(Accepted::Signed { link_id: 7, .. })
    ));
    assert_eq!(vehicle.verify_now(&wrong), Err(Refusal::BadSignature));
    assert!(matches!(
        vehicle.verify_now(&command),
        Err(Refusal::Replayed {
            link_id: 7,
            system_id: 255,
            component_id: 190,
            ..
        })
    ));

    // vtol-link signs; pymavlink must take "signed" and "end" only.
    let signed = vehicle.sign_now(&statustext("signed")).unwrap();
    let end = vehicle.sign_now(&statustext("end")).unwrap();
    // Another link id: pymavlink 2.4.50 records a stream's timestamp before it checks the
    // signature, so a wrongly signed frame on our own stream would lock "end" out.
    let mut other = Signing::new(SigningKey::from_passphrase("another passphrase"), 9, 0);
    let sends = [
        signed.clone(),
        signed, // replayed
        other.sign_now(&statustext("wrong key")).unwrap(),
        statustext("unsigned"),
        end.clone(),
    ];
    for f in &sends {
        sock.send_to(f.as_bytes(), reply_to).unwrap();
    }

    let mut out = String::new();
    child
        .stdout
        .take()
        .unwrap()
        .read_to_string(&mut out)
        .unwrap();
    assert!(child.wait().unwrap().success(), "python failed: {out}");
    let result: serde_json::Value = serde_json::from_str(out.trim()).expect(&out);
    assert_eq!(
        result["texts"],
        serde_json::json!(["signed", "end"]),
        "{out}"
    );
    assert_eq!(result["goodsig"], 2, "{out}");
    // The replay and the wrong key fail pymavlink's check; the unsigned frame is refused
    // before it (no signature to check).
    assert_eq!(result["badsig"], 2, "{out}");
    // pymavlink read our last timestamp as we wrote it, on our stream (link 0, system 1, comp 1),
    // and it is our wall clock.
    let read = result["streams"]["0,1,1"].as_u64().expect(&out);
    let now = timestamp_at(SystemTime::now());
    assert!(
        read <= now && now - read < 60 * TIMESTAMP_UNITS_PER_S,
        "{read} vs {now}"
    );
    assert_eq!(
        result["streams"]["0,1,1"],
        SignatureFields::of(&end).unwrap().timestamp,
        "{out}"
    );
}
