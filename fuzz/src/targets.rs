//! The fuzz targets. Each takes any bytes and panics only when a contract is broken:
//!
//! - nothing in the code under test panics, whatever the input;
//! - an error, as the binaries print it ([`vtol_link::error_line`]), is one line;
//! - what parses also survives its round trip (written out and read back, the same value).
//!
//! Inputs that must be valid MAVLink to reach deep code (the twin's message handlers, the
//! tracker) are built from the bytes as frames with a correct CRC: the bytes choose the
//! message and fill its payload, so every field the code reads by hand takes any value.

use std::path::Path;
use std::time::{Duration, Instant, UNIX_EPOCH};

use bytes::Bytes;
use firmware_sim::endpoint::{Endpoint, EndpointConfig, LinkKey};
use vtol_gcs::links::Side;
use vtol_gcs::tracker::VehicleState;
use vtol_link::dialect::{MavMessage, STATUSTEXT_DATA};
use vtol_link::frame::{crc_extra, known_message_ids};
use vtol_link::{Frame, FrameDecoder, LinkId, LinkUrl};

/// The name errors carry in place of a file.
const PATH: &str = "fuzz-input";

/// Panics unless `err`, as the binaries print it, is one non-empty line.
fn one_line(err: &(dyn std::error::Error + 'static)) {
    let line = vtol_link::error_line(err);
    assert!(
        !line.trim().is_empty() && !line.contains('\n'),
        "error is not one line: {line:?}"
    );
}

/// Panics unless a `String` error is one non-empty line.
fn one_line_text(err: &str) {
    assert!(
        !err.trim().is_empty() && !err.contains('\n'),
        "error is not one line: {err:?}"
    );
}

fn text(data: &[u8]) -> std::borrow::Cow<'_, str> {
    String::from_utf8_lossy(data)
}

/// Frames out of a byte stream, pushed in two pieces split where the first byte says; the
/// same bytes pushed whole must give the same frames.
pub fn frame_decoder(data: &[u8]) {
    let split = data
        .first()
        .map_or(0, |b| usize::from(*b) % (data.len() + 1));
    let mut pieces = FrameDecoder::new();
    pieces.push(&data[..split]);
    let mut frames: Vec<Frame> = pieces.frames().collect();
    pieces.push(&data[split..]);
    frames.extend(pieces.frames());
    frames.extend(pieces.finish());
    let mut whole = FrameDecoder::new();
    whole.push(data);
    let mut at_once: Vec<Frame> = whole.frames().collect();
    at_once.extend(whole.finish());
    // Once the stream has ended, the checked frames do not depend on where it was split. (A
    // frame of an id the dialect does not know that ends where the bytes end is let through at
    // once rather than held until the next byte shows its boundary, so a split there can pass
    // one that a whole read skips; and a long false candidate holds what follows it until more
    // bytes or the end of the stream decide.)
    let checked = |fs: &[Frame]| -> Vec<Vec<u8>> {
        fs.iter()
            .filter(|f| f.is_verified())
            .map(|f| f.as_bytes().to_vec())
            .collect()
    };
    assert_eq!(
        checked(&frames),
        checked(&at_once),
        "the checked frames depend on where the stream was split"
    );
    for f in &frames {
        let _ = (f.seq(), f.system_id(), f.component_id(), f.message_id());
        let _ = (f.target(), f.raw_command(), f.message_name(), f.signature());
        let _ = (f.payload().len(), f.is_verified(), f.crc(), f.version());
        if let Err(e) = f.decode() {
            one_line(&e);
        }
        let again = Frame::from_bytes(f.bytes().clone()).expect("a decoded frame parses again");
        assert_eq!(again.as_bytes(), f.as_bytes());
    }
}

/// A tlog read to the end, and `log stats` over it.
pub fn tlog(data: &[u8]) {
    let mut reader = vtol_gcs::tlog::TlogReader::from_bytes(data.to_vec());
    let mut records = 0;
    for (_, frame) in reader.by_ref() {
        assert!(!frame.is_empty());
        records += 1;
    }
    assert!(reader.bytes_consumed() <= data.len() as u64);
    assert!(reader.skipped_bytes + reader.truncated_tail_bytes <= data.len());
    // The direction convention is detected from the same records, as `log stats` does.
    let directions =
        vtol_gcs::tlog::Directions::detect(vtol_gcs::tlog::TlogReader::from_bytes(data.to_vec()));
    let mut again = vtol_gcs::tlog::TlogReader::from_bytes(data.to_vec());
    let stats = vtol_gcs::log::stats::scan(&mut again, data.len() as u64, directions, &mut |_| {});
    assert_eq!(stats.frames, records, "stats and the reader disagree");
}

/// A URL parses, or is one line of error; a parsed URL prints as a URL that parses to itself.
pub fn link_url(data: &[u8]) {
    match text(data).parse::<LinkUrl>() {
        Ok(url) => {
            let shown = url.to_string();
            let back: LinkUrl = shown
                .parse()
                .unwrap_or_else(|e| panic!("{url:?} prints as {shown:?}, which fails: {e}"));
            assert_eq!(back, url, "{shown:?} does not read back");
        }
        Err(e) => one_line(&e),
    }
}

/// A `--vehicle` value.
pub fn vehicle_source(data: &[u8]) {
    if let Err(e) = text(data).parse::<vtol_gcs::config::VehicleSource>() {
        one_line(&e);
    }
}

/// The daemon's config file, parsed and applied over the defaults.
pub fn daemon_config(data: &[u8]) {
    use vtol_gcs::config::{Config, ConfigError, FileConfig};
    match FileConfig::parse(&text(data)) {
        Ok(file) => {
            let mut config = Config::default();
            match file.apply(&mut config) {
                // The status line's timer cannot tick at a zero period.
                Ok(()) => assert!(!config.status_interval.is_zero(), "a zero status interval"),
                Err(e) => one_line(&e),
            }
        }
        Err(message) => one_line(&ConfigError::Parse {
            path: PATH.into(),
            message,
        }),
    }
}

/// A parameter file; what parses is written in each format and read back unchanged.
pub fn param_file(data: &[u8]) {
    use vtol_gcs::params::file::{Format, ParamFile, render};
    match ParamFile::parse(&text(data), Path::new(PATH)) {
        Ok(file) => {
            for format in [Format::Mavproxy, Format::Missionplanner, Format::Qgc] {
                let written = render(
                    &file.params,
                    format,
                    (vtol_link::SystemId(1), vtol_link::ComponentId(1)),
                );
                let back = ParamFile::parse(&written, Path::new(PATH))
                    .unwrap_or_else(|e| panic!("{format:?} output does not read back: {e}"));
                assert_eq!(back.params.len(), file.params.len());
                for (name, p) in &file.params {
                    let q = &back.params[name];
                    assert_eq!(
                        q.value.to_bits(),
                        p.value.to_bits(),
                        "{name} changed in {format:?}"
                    );
                }
            }
        }
        Err(e) => one_line(&e),
    }
}

/// The twin's parameter file, round trip.
pub fn twin_param_file(data: &[u8]) {
    use firmware_sim::nav::params::Params;
    match Params::from_parm_str(&text(data), Path::new(PATH)) {
        Ok(p) => {
            let written = p.to_parm_string();
            let back = Params::from_parm_str(&written, Path::new(PATH))
                .unwrap_or_else(|e| panic!("the twin's own file does not read back: {e}"));
            assert_eq!(back.to_parm_string(), written);
        }
        Err(e) => one_line(&e),
    }
}

/// The twin's mission file, round trip.
pub fn mission_file(data: &[u8]) {
    use firmware_sim::nav::mission::Mission;
    match Mission::from_wpl_str(&text(data), Path::new(PATH)) {
        Ok(m) => {
            let written = m.to_wpl_string();
            let back = Mission::from_wpl_str(&written, Path::new(PATH))
                .unwrap_or_else(|e| panic!("the twin's own mission does not read back: {e}"));
            assert_eq!(back.to_wpl_string(), written);
        }
        Err(e) => one_line(&e),
    }
}

/// The signing state file, round trip; an error never quotes the file's key line.
pub fn signing_state(data: &[u8]) {
    use vtol_link::signing::SigningState;
    let input = text(data);
    match SigningState::parse(&input, Path::new(PATH)) {
        Ok(state) => {
            let written = state.to_text();
            let back = SigningState::parse(&written, Path::new(PATH))
                .unwrap_or_else(|e| panic!("the state file's own text does not read back: {e}"));
            assert_eq!(back, state);
        }
        Err(e) => {
            one_line(&e);
            // The fixed description of the format may share text with any input.
            let line = vtol_link::error_line(&e).replace(vtol_link::signing::STATE_FILE_FORMAT, "");
            // Key material is hex (a key is 64 hex digits): no run of 8 or more hex digits from
            // a key line's value may stand in the error. (A check on the whole value misfires:
            // libFuzzer writes values that are the error's own words, `key =: not valid TOM`.)
            for l in input.lines().filter(|l| l.trim_start().starts_with("key")) {
                let value = l.split_once('=').map_or("", |(_, v)| v);
                for run in value
                    .split(|c: char| !c.is_ascii_hexdigit())
                    .filter(|r| r.len() >= 8)
                {
                    assert!(!line.contains(run), "the error quotes the key: {line}");
                }
            }
        }
    }
}

/// `firmware-sim simulate` values; the first byte picks the flag.
pub fn sim_cli_values(data: &[u8]) {
    use firmware_sim::shell::simulate::{parse_initial, parse_param, parse_push, parse_setpoint};
    let Some((which, rest)) = data.split_first() else {
        return;
    };
    let s = text(rest);
    let err = match which % 4 {
        0 => parse_initial(&s).err(),
        1 => parse_setpoint(&s).err(),
        2 => parse_param(&s).err(),
        _ => parse_push(&s).err(),
    };
    if let Some(e) = err {
        one_line_text(&e);
    }
}

/// STATUSTEXT messages from the bytes (severity, id, chunk_seq, 50 text bytes each) joined
/// back by the client's assembler.
pub fn statustext(data: &[u8]) {
    let mut joiner = vtol_link::statustext::TextAssembler::default();
    for chunk in data.chunks(54) {
        let mut t = STATUSTEXT_DATA::default();
        let get = |i: usize| chunk.get(i).copied().unwrap_or(0);
        t.id = u16::from_le_bytes([get(1), get(2)]);
        t.chunk_seq = get(3);
        let mut text = [0u8; 50];
        for (i, b) in chunk.iter().skip(4).take(50).enumerate() {
            text[i] = *b;
        }
        t.text = text.into();
        if let Some(joined) = joiner.push(&t) {
            assert!(
                joined.len() <= 256 * 50 * 4,
                "a text longer than 256 chunks"
            );
        }
    }
}

/// The messages the twin reads (the first part of the list is tried more often): everything
/// it parses by hand, plus any id the dialect knows.
const TWIN_READS: &[u32] = &[
    0, 11, 20, 21, 23, 39, 40, 41, 43, 44, 45, 47, 51, 66, 69, 70, 73, 75, 76, 84, 86, 109, 110,
    111, 2, 4, 253, 256,
];

/// Builds frames with correct CRCs from the bytes: [selector, length, payload…] per frame.
fn frames_from(data: &[u8], system_id: u8, component_id: u8, ids: &[u32]) -> Vec<Frame> {
    let all = known_message_ids();
    let mut out = Vec::new();
    let mut rest = data;
    let mut seq = 0u8;
    while let [selector, len, tail @ ..] = rest {
        let id = if usize::from(*selector) < 224 {
            ids[usize::from(*selector) % ids.len()]
        } else {
            all[usize::from(*len) % all.len()]
        };
        let n = usize::from(*len).min(tail.len());
        let (payload, next) = tail.split_at(n);
        rest = next;
        let Some(extra) = crc_extra(id) else { continue };
        if let Ok(f) = Frame::encode_raw_v2(
            vtol_link::SystemId(system_id),
            vtol_link::ComponentId(component_id),
            seq,
            id,
            payload,
            extra,
        ) {
            out.push(f);
        }
        seq = seq.wrapping_add(1);
    }
    out
}

/// Every message the twin reads, with any field values, into its endpoint: 20 ms of flight
/// after each one. Everything it sends back is a whole, valid frame.
pub fn twin_endpoint(data: &[u8]) {
    let mut twin = Endpoint::new(EndpointConfig::default());
    let link = LinkKey(1);
    let mut now_us = 0;
    let check = |out: Vec<firmware_sim::endpoint::Outbound>| {
        for o in out {
            let f = Frame::from_bytes(Bytes::copy_from_slice(o.frame.as_bytes()))
                .unwrap_or_else(|e| panic!("the twin sent a broken frame: {e}"));
            assert!(f.is_verified(), "the twin sent a frame with a bad CRC");
        }
    };
    for f in frames_from(data, 255, 190, TWIN_READS) {
        check(twin.handle(link, &f));
        now_us += 20_000;
        check(twin.tick(now_us));
    }
}

/// The tracker reads vehicle frames of the types it tracks; the message inspector lists the
/// fields of each decoded one.
pub fn tracker(data: &[u8]) {
    let mut state = VehicleState::default();
    let t0 = Instant::now();
    let beat = Frame::encode_v2(
        vtol_link::SystemId(1),
        vtol_link::ComponentId(1),
        0,
        &MavMessage::HEARTBEAT(vtol_link::dialect::HEARTBEAT_DATA {
            mavtype: vtol_link::dialect::MavType::MAV_TYPE_VTOL_TAILSITTER_DUOROTOR,
            autopilot: vtol_link::dialect::MavAutopilot::MAV_AUTOPILOT_GENERIC,
            ..Default::default()
        }),
    );
    state.apply(LinkId(1), Side::Vehicle, &beat, t0);
    for (i, f) in frames_from(data, 1, 1, &[0, 30, 32, 36, 253])
        .iter()
        .enumerate()
    {
        let at = t0 + Duration::from_millis(i as u64 * 10);
        if let Some(msg) = state.apply(LinkId(1), Side::Vehicle, f, at) {
            for field in vtol_gcs::fields::fields(&msg) {
                assert!(!field.path.is_empty());
            }
        }
        if let Ok(msg) = f.decode() {
            let _ = vtol_gcs::fields::fields(&msg);
        }
    }
}

/// Frames into a keyed receiver's verification: refused or accepted, never a panic; a frame
/// signed with the key is accepted once and refused when replayed.
pub fn signing_verify(data: &[u8]) {
    use vtol_link::signing::{Signing, SigningKey};
    let key = SigningKey::from_passphrase("fuzz");
    let now = UNIX_EPOCH + Duration::from_secs(1_795_000_000);
    let mut rx = Signing::new(key.clone(), 0, 0);
    let mut dec = FrameDecoder::new();
    dec.push(data);
    let frames: Vec<Frame> = dec.frames().collect();
    for f in &frames {
        let _ = rx.verify(f, now);
    }
    // A signer keyed alike: what it signs from the same frames passes once, never twice.
    let mut tx = Signing::new(key, 1, 0);
    let mut rx = Signing::new(SigningKey::from_passphrase("fuzz"), 0, 0);
    for f in frames.iter().filter(|f| f.is_v2() && !f.is_signed()) {
        let Ok(signed) = tx.sign(f, now) else {
            continue;
        };
        if rx.verify(&signed, now).is_ok() {
            assert!(rx.verify(&signed, now).is_err(), "a replay was accepted");
        }
    }
}

/// Frames from three links through the router's addressing (target offsets, the command of a
/// COMMAND_LONG/INT, the command a COMMAND_ACK answers, all read from raw bytes) and its table:
/// nothing ever goes back to the link it came from, and a targeted frame only goes where its
/// target was seen.
pub fn router(data: &[u8]) {
    use vtol_gcs::links::table::{Route, RoutingTable, addressing};
    let links = [LinkId(1), LinkId(2), LinkId(3)];
    let mut table = RoutingTable::new();
    let mut out = Vec::new();
    let mut dec = FrameDecoder::new();
    dec.push(data);
    let mut frames: Vec<Frame> = dec.frames().collect();
    frames.extend(dec.finish());
    for (i, f) in frames.iter().enumerate() {
        let ingress = links[i % links.len()];
        let (system, component) = f.sender();
        table.learn(ingress, system, component);
        let a = addressing(f);
        if let Some(cmd) = a.command {
            table.note_command(ingress, system, component, cmd);
        }
        let route = table.route(ingress, &a, &links, &mut out);
        assert!(
            !out.contains(&ingress),
            "{route:?} back to the ingress link"
        );
        if route == Route::Targeted {
            let (system, _) = a.target.expect("a targeted frame has a target");
            for l in &out {
                assert!(
                    table.system_seen_on(system, *l) || a.ack_of_command.is_some(),
                    "to {l} where system {system} was never seen"
                );
            }
        }
        if route == Route::Unroutable {
            assert!(out.is_empty());
        }
        if i % 7 == 6 {
            table.forget_link(links[i % links.len()]);
        }
    }
}
