//! The packed file's decoding, and the FTP read against a vehicle that packs and bursts as
//! ArduPilot does (AP_Filesystem_Param.cpp, GCS_FTP.cpp), with chunks lost.

use super::*;

const V: (SystemId, ComponentId) = (SystemId(1), ComponentId(1));

/// Packs `table` as AP_Filesystem_Param.cpp does for reads of `CHUNK` bytes: shared name
/// prefixes, and zero padding so that no value straddles two chunks.
fn pack(table: &[(&str, u8, f64)]) -> Vec<u8> {
    let n = u16::try_from(table.len()).expect("small");
    let mut out = Vec::new();
    out.extend_from_slice(&MAGIC.to_le_bytes());
    out.extend_from_slice(&n.to_le_bytes());
    out.extend_from_slice(&n.to_le_bytes());
    let mut last: &[u8] = b"";
    for (name, ty, value) in table {
        let raw = name.as_bytes();
        let mut common = raw
            .iter()
            .zip(last)
            .take(15)
            .take_while(|(a, b)| a == b)
            .count();
        if common == raw.len() {
            common -= 1;
        }
        let rest = &raw[common..];
        let data: Vec<u8> = match ty {
            1 => vec![(*value as i8) as u8],
            2 => (*value as i16).to_le_bytes().to_vec(),
            3 => (*value as i32).to_le_bytes().to_vec(),
            _ => (*value as f32).to_le_bytes().to_vec(),
        };
        let packed = 2 + rest.len() + data.len();
        if data.len() > 1 {
            let ofs_mod = (out.len() + packed) % CHUNK;
            if ofs_mod > 0 && ofs_mod < data.len() {
                out.extend(std::iter::repeat_n(0, data.len() - ofs_mod));
            }
        }
        out.push(*ty);
        out.push(u8::try_from(common | ((rest.len() - 1) << 4)).expect("lengths"));
        out.extend_from_slice(rest);
        out.extend_from_slice(&data);
        last = raw;
    }
    out
}

fn table(n: usize) -> Vec<(String, u8, f64)> {
    (0..n)
        .map(|i| {
            let ty = [1u8, 2, 3, 4][i % 4];
            let value = if ty == 4 {
                i as f64 * 0.1
            } else {
                -((i % 100) as f64)
            };
            (format!("Q_A_RAT_{i:04}_P"), ty, value)
        })
        .collect()
}

fn borrowed(t: &[(String, u8, f64)]) -> Vec<(&str, u8, f64)> {
    t.iter().map(|(n, ty, v)| (n.as_str(), *ty, *v)).collect()
}

#[test]
fn a_packed_table_decodes_to_names_types_and_float32_values() {
    let t = table(400);
    let data = pack(&borrowed(&t));
    assert!(data.len() > 3 * CHUNK, "padding is exercised");
    let set = decode_pck(&data).expect("decodes");
    assert_eq!(set.len(), 400);
    for (name, ty, value) in &t {
        let p = set[name];
        assert_eq!(p.value, *value as f32, "{name}");
        let want = match ty {
            1 => MavParamType::MAV_PARAM_TYPE_INT8,
            2 => MavParamType::MAV_PARAM_TYPE_INT16,
            3 => MavParamType::MAV_PARAM_TYPE_INT32,
            _ => MavParamType::MAV_PARAM_TYPE_REAL32,
        };
        assert_eq!(p.ty, want);
    }
    assert!(matches!(
        decode_pck(&data[..data.len() - 3]),
        Err(PckError::Truncated(_) | PckError::Incomplete { .. })
    ));
    assert_eq!(
        decode_pck(&[1, 2, 3, 4, 5, 6]),
        Err(PckError::Magic(0x0201))
    );
}

fn ftp(payload: [u8; 251]) -> Inbound {
    Inbound {
        sys: V.0,
        comp: V.1,
        msg: MavMessage::FILE_TRANSFER_PROTOCOL(apm::FILE_TRANSFER_PROTOCOL_DATA {
            target_network: 0,
            target_system: 255,
            target_component: 190,
            payload,
        }),
    }
}

fn reply(req: &[u8; 251], op: u8, data: &[u8], offset: u32, complete: bool) -> Inbound {
    let mut p = [0u8; 251];
    p[2] = req[2];
    p[3] = op;
    p[4] = u8::try_from(data.len()).expect("chunk");
    p[5] = req[3];
    p[6] = u8::from(complete);
    p[8..12].copy_from_slice(&offset.to_le_bytes());
    p[12..12 + data.len()].copy_from_slice(data);
    ftp(p)
}

fn payload(m: &MavMessage) -> [u8; 251] {
    match m {
        MavMessage::FILE_TRANSFER_PROTOCOL(f) => f.payload,
        other => panic!("{other:?}"),
    }
}

/// Runs the machine against `file`, served as ArduPilot serves it, dropping the chunks whose
/// number (over the whole read) is in `lose`. Returns the table and the bursts asked for.
fn serve(file: &[u8], lose: &[usize]) -> (ParamSet, usize) {
    let t0 = Instant::now();
    let mut now = t0;
    let mut m = FtpPullMachine::new(V, 7, Duration::from_millis(20));
    let mut out = m.start(now);
    let (mut sent, mut bursts) = (0usize, 0usize);
    for _ in 0..1000 {
        if let Some(r) = m.result() {
            return (r.expect("read"), bursts);
        }
        let mut inbound = Vec::new();
        for msg in out.drain(..) {
            let req = payload(&msg);
            assert_eq!(req[2], 7, "the session");
            match req[3] {
                OP_OPEN_RO => inbound.push(reply(&req, OP_ACK, &400u32.to_le_bytes(), 0, false)),
                OP_BURST => {
                    bursts += 1;
                    let mut ofs = u32::from_le_bytes([req[8], req[9], req[10], req[11]]) as usize;
                    loop {
                        let chunk = &file[ofs.min(file.len())..(ofs + CHUNK).min(file.len())];
                        if chunk.is_empty() {
                            let mut eof = reply(&req, OP_NAK, &[ERR_EOF], ofs as u32, false);
                            if let MavMessage::FILE_TRANSFER_PROTOCOL(f) = &mut eof.msg {
                                f.payload[4] = 1;
                            }
                            inbound.push(eof);
                            break;
                        }
                        let last = chunk.len() < CHUNK;
                        sent += 1;
                        if !lose.contains(&sent) {
                            inbound.push(reply(&req, OP_ACK, chunk, ofs as u32, last));
                        }
                        ofs += chunk.len();
                        if last {
                            break;
                        }
                    }
                }
                OP_TERMINATE => inbound.push(reply(&req, OP_ACK, &[], 0, false)),
                other => panic!("opcode {other}"),
            }
        }
        for i in &inbound {
            now += Duration::from_micros(100);
            out.extend(m.on_message(now, i));
        }
        if out.is_empty() && m.result_pending() {
            now = m.deadline();
            out = m.on_time(now);
        }
    }
    panic!("no end");
}

impl FtpPullMachine {
    fn result_pending(&self) -> bool {
        self.done.is_none()
    }
}

#[test]
fn the_file_comes_in_one_burst_and_lost_chunks_are_asked_for_again() {
    let t = table(1566);
    let file = pack(&borrowed(&t));
    let (set, bursts) = serve(&file, &[]);
    assert_eq!(set.len(), 1566);
    assert_eq!(bursts, 1);
    // The second chunk and the last one lost.
    let chunks = file.len().div_ceil(CHUNK);
    let (set, bursts) = serve(&file, &[2, chunks]);
    assert_eq!(set.len(), 1566);
    assert!(bursts >= 2, "{bursts}");
    assert_eq!(set, decode_pck(&file).expect("decodes"));
}

#[test]
fn a_nak_on_open_hands_over_to_the_parameter_protocol() {
    let t0 = Instant::now();
    let mut m = FtpPullMachine::new(V, 3, Duration::from_millis(20));
    let req = payload(&m.start(t0)[0]);
    // The twin's answer: FileNotFound.
    m.on_message(t0, &reply(&req, OP_NAK, &[10], 0, false));
    assert!(m.result().expect("done").is_err());
    // Silence: given up after the tries.
    let mut m = FtpPullMachine::new(V, 3, Duration::from_millis(20));
    let mut sends = m.start(t0).len();
    while m.result_pending() {
        let d = m.deadline();
        sends += m.on_time(d).len();
    }
    assert!(sends <= usize::from(FTP_TRIES), "{sends}");
    assert!(m.result().expect("done").is_err());
}
