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
    let seq = u16::from_le_bytes([req[0], req[1]]).wrapping_add(1);
    p[..2].copy_from_slice(&seq.to_le_bytes());
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

/// What a read cost.
#[derive(Debug, Default)]
struct Served {
    opens: usize,
    bursts: usize,
    reads: usize,
    /// ReadFile requests by the offset they asked for.
    reads_at: BTreeMap<usize, usize>,
}

/// Runs the machine against `file`, served as ArduPilot serves it, dropping the replies whose
/// number (over the whole read, 1 first) is in `lose`; the open is answered after `open_rtt`
/// (a fast link reads by ReadFile, a slow one bursts). Returns the table and what it took.
fn serve(file: &[u8], lose: &[usize], open_rtt: Duration) -> (ParamSet, Served) {
    serve_with(file, lose, open_rtt, OpenCase::Clean)
}

/// How the open meets the vehicle in [`serve_with`].
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum OpenCase {
    /// The file is closed and every answer arrives.
    Clean,
    /// The first open's answer is lost.
    AnswerLost,
    /// An earlier reader with this session number left the file open.
    LeftOpen,
}

/// [`serve`], with the open in `case`. As ArduPilot does, the vehicle refuses an open (FTP
/// error Fail) while the file is open, until the session is terminated, and answers a request
/// that repeats the last one it answered (same session and sequence number) with the same
/// answer again.
fn serve_with(
    file: &[u8],
    lose: &[usize],
    open_rtt: Duration,
    case: OpenCase,
) -> (ParamSet, Served) {
    let t0 = Instant::now();
    let mut now = t0;
    let mut m = FtpPullMachine::new(V, 7, Duration::from_millis(20));
    let mut out = m.start(now);
    let (mut sent, mut cost) = (0usize, Served::default());
    let (mut is_open, mut lose_open_ack) =
        (case == OpenCase::LeftOpen, case == OpenCase::AnswerLost);
    let mut last_answered: Option<(u16, Inbound)> = None;
    let eof = |req: &[u8; 251]| {
        let mut eof = reply(req, OP_NAK, &[ERR_EOF], 12345, false);
        if let MavMessage::FILE_TRANSFER_PROTOCOL(f) = &mut eof.msg {
            f.payload[4] = 1;
        }
        eof
    };
    for _ in 0..5000 {
        if let Some(r) = m.result() {
            return (r.expect("read"), cost);
        }
        let mut inbound = Vec::new();
        for msg in out.drain(..) {
            let req = payload(&msg);
            assert_eq!(req[2], 7, "the session");
            let ofs = u32::from_le_bytes([req[8], req[9], req[10], req[11]]) as usize;
            let seq = u16::from_le_bytes([req[0], req[1]]);
            if req[3] == OP_OPEN_RO {
                cost.opens += 1;
                now += open_rtt;
                if let Some((_, again)) = last_answered.as_ref().filter(|(s, _)| *s == seq) {
                    inbound.push(again.clone());
                    continue;
                }
            }
            match req[3] {
                OP_OPEN_RO => {
                    let answer = if is_open {
                        reply(&req, OP_NAK, &[ERR_FAIL], 0, false)
                    } else {
                        is_open = true;
                        reply(&req, OP_ACK, &400u32.to_le_bytes(), 0, false)
                    };
                    last_answered = Some((seq, answer.clone()));
                    if !std::mem::take(&mut lose_open_ack) {
                        inbound.push(answer);
                    }
                }
                OP_BURST => {
                    cost.bursts += 1;
                    let mut ofs = ofs;
                    loop {
                        let chunk = &file[ofs.min(file.len())..(ofs + CHUNK).min(file.len())];
                        if chunk.is_empty() {
                            inbound.push(eof(&req));
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
                OP_READ => {
                    cost.reads += 1;
                    *cost.reads_at.entry(ofs).or_default() += 1;
                    assert_eq!(usize::from(req[4]), CHUNK, "a whole chunk asked for");
                    let chunk = &file[ofs.min(file.len())..(ofs + CHUNK).min(file.len())];
                    sent += 1;
                    if lose.contains(&sent) {
                        continue;
                    }
                    if chunk.is_empty() {
                        inbound.push(eof(&req));
                    } else {
                        inbound.push(reply(&req, OP_ACK, chunk, ofs as u32, false));
                    }
                }
                OP_TERMINATE => {
                    is_open = false;
                    last_answered = None;
                    inbound.push(reply(&req, OP_ACK, &[], 0, false));
                }
                other => panic!("opcode {other}"),
            }
        }
        for i in &inbound {
            now += Duration::from_micros(100);
            out.extend(m.on_message(now, i));
        }
        if out.is_empty() && m.result_pending() {
            now = now.max(m.deadline());
            out = m.on_time(now);
        }
    }
    panic!(
        "no end: {:?} end {:?} contiguous {} reads {} chunks {} cost {cost:?} done {:?}",
        m.phase,
        m.end,
        m.contiguous(),
        m.reads.len(),
        m.chunks.len(),
        m.done.is_some()
    );
}

impl FtpPullMachine {
    fn result_pending(&self) -> bool {
        self.done.is_none()
    }
}

const SLOW: Duration = Duration::from_millis(100);
const FAST: Duration = Duration::from_millis(1);

#[test]
fn on_a_slow_link_the_file_comes_in_one_burst_and_lost_chunks_are_read_again() {
    let t = table(1566);
    let file = pack(&borrowed(&t));
    let chunks = file.len().div_ceil(CHUNK);
    let (set, cost) = serve(&file, &[], SLOW);
    assert_eq!(set.len(), 1566);
    assert_eq!((cost.bursts, cost.reads), (1, 0));
    // The second chunk and the last one lost: read by themselves, not by a second burst.
    let (set, cost) = serve(&file, &[2, chunks], SLOW);
    assert_eq!(set, decode_pck(&file).expect("decodes"));
    assert_eq!(cost.bursts, 1);
    assert!((2..=4).contains(&cost.reads), "{cost:?}");
    // The reads of the gaps lost too: asked for again, in two copies from then on.
    let lose: Vec<usize> = (1..=chunks + 4).filter(|n| n % 3 == 0).collect();
    let (set, cost) = serve(&file, &lose, SLOW);
    assert_eq!(set, decode_pck(&file).expect("decodes"));
    assert_eq!(cost.bursts, 1, "{cost:?}");
}

#[test]
fn a_chunk_whose_read_was_lost_is_asked_for_again_in_one_copy_more() {
    let t = table(1566);
    let file = pack(&borrowed(&t));
    let chunks = file.len().div_ceil(CHUNK);
    // The burst loses the second chunk, one in fifty-two: its read goes in two copies (one
    // exchange in twenty-five fails), and both are lost too.
    assert_eq!(chunks, 52);
    let (set, cost) = serve(&file, &[2, chunks + 1, chunks + 2], SLOW);
    assert_eq!(set, decode_pck(&file).expect("decodes"));
    assert_eq!(
        cost.reads_at.get(&CHUNK),
        Some(&5),
        "two copies, then three: {cost:?}"
    );
}

#[test]
fn on_a_fast_link_the_file_is_read_by_requests_in_flight() {
    let t = table(1566);
    let file = pack(&borrowed(&t));
    let chunks = file.len().div_ceil(CHUNK);
    let (set, cost) = serve(&file, &[], FAST);
    assert_eq!(set, decode_pck(&file).expect("decodes"));
    assert_eq!(cost.bursts, 0);
    // Each chunk once, and at most a window's worth of requests past the end.
    assert!(
        cost.reads >= chunks && cost.reads <= chunks + READ_WINDOW,
        "{cost:?} for {chunks}"
    );
    // A file that ends on a chunk boundary ends with the NAK EndOfFile.
    let mut t = table(40);
    loop {
        let n = pack(&borrowed(&t)).len();
        if n.is_multiple_of(CHUNK) {
            break;
        }
        t.push((format!("Z{}", t.len()), 1, 1.0));
    }
    let even = pack(&borrowed(&t));
    let (set, _) = serve(&even, &[], FAST);
    assert_eq!(set, decode_pck(&even).expect("decodes"));
    // Every fifth reply lost, the first and the last chunk among them.
    let lose: Vec<usize> = (1..=3 * chunks)
        .filter(|n| n % 5 == 1 || *n == chunks)
        .collect();
    let (set, cost) = serve(&file, &lose, FAST);
    assert_eq!(set, decode_pck(&file).expect("decodes"));
    assert_eq!(cost.bursts, 0);
}

#[test]
fn an_open_left_by_an_earlier_reader_is_reset_and_one_whose_answer_was_lost_is_answered_again() {
    let t = table(300);
    let file = pack(&borrowed(&t));
    // Left open: the open and its copies are refused (the file is open), then the three
    // after the reset. Answer lost: the copies repeat the open's sequence number, so the
    // vehicle sends the lost answer again and no reset is needed.
    for (case, opens) in [(OpenCase::LeftOpen, 6), (OpenCase::AnswerLost, 3)] {
        for rtt in [FAST, SLOW] {
            let (set, cost) = serve_with(&file, &[], rtt, case);
            assert_eq!(set, decode_pck(&file).expect("decodes"));
            assert_eq!(cost.opens, opens, "{case:?} {rtt:?}: {cost:?}");
        }
    }
}

#[test]
fn a_burst_answer_that_comes_after_its_pause_is_kept_and_its_end_of_file_is_no_refusal() {
    let t = table(100);
    let file = pack(&borrowed(&t));
    let t0 = Instant::now();
    let mut m = FtpPullMachine::new(V, 2, Duration::from_millis(20));
    let open = payload(&m.start(t0)[0]);
    let mut now = t0 + SLOW;
    let burst = payload(&m.on_message(now, &reply(&open, OP_ACK, &[0; 4], 0, false))[0]);
    assert_eq!(burst[3], OP_BURST);
    // The first chunk, then a pause: the machine turns to reads.
    now += Duration::from_millis(1);
    m.on_message(now, &reply(&burst, OP_ACK, &file[..CHUNK], 0, false));
    now = m.deadline();
    let reads = m.on_time(now);
    assert!(reads.iter().all(|r| payload(r)[3] == OP_READ), "{reads:?}");
    assert_eq!(m.phase, Phase::Window);
    // The burst's second chunk and its end of file arrive late.
    now += Duration::from_millis(1);
    m.on_message(
        now,
        &reply(&burst, OP_ACK, &file[CHUNK..2 * CHUNK], CHUNK as u32, false),
    );
    assert!(
        m.chunks.contains_key(&(CHUNK as u32)),
        "the late chunk is kept"
    );
    let mut eof = reply(&burst, OP_NAK, &[ERR_EOF], file.len() as u32, false);
    if let MavMessage::FILE_TRANSFER_PROTOCOL(f) = &mut eof.msg {
        f.payload[4] = 1;
    }
    m.on_message(now, &eof);
    assert!(m.result().is_none(), "not a refusal");
}

#[test]
fn an_open_answered_after_its_retry_is_a_slow_link() {
    let t0 = Instant::now();
    let mut m = FtpPullMachine::new(V, 4, Duration::from_millis(200));
    let first = payload(&m.start(t0)[0]);
    // No answer: the open goes again after the retry timeout.
    let retry_at = m.deadline();
    assert!(!m.on_time(retry_at).is_empty());
    // The first open's answer, a moment after the retry: 1 ms after it, 201 ms after the first.
    let now = retry_at + Duration::from_millis(1);
    let out = m.on_message(now, &reply(&first, OP_ACK, &[0; 4], 0, false));
    assert_eq!(out.len(), 1, "{out:?}");
    assert_eq!(
        payload(&out[0])[3],
        OP_BURST,
        "a burst, not reads paced for a fast link"
    );
}

#[test]
fn requests_leave_four_at_once_then_paced_within_the_window() {
    let t0 = Instant::now();
    let mut m = FtpPullMachine::new(V, 1, Duration::from_millis(20));
    let open = payload(&m.start(t0)[0]);
    let now = t0 + FAST;
    let first = m.on_message(now, &reply(&open, OP_ACK, &[0; 4], 0, false));
    assert_eq!(first.len(), 4, "four back to back");
    assert!(first.iter().all(|r| payload(r)[3] == OP_READ));
    // The next one is due a pace later, not before.
    assert_eq!(m.deadline(), now + READ_PACE);
    assert!(m.on_time(now + READ_PACE / 2).is_empty());
    assert_eq!(m.on_time(now + READ_PACE).len(), 1);
    // Unanswered, never more than the window in flight.
    let mut t = now + READ_PACE;
    let mut sent = 5;
    for _ in 0..200 {
        t += READ_PACE;
        sent += m.on_time(t).len();
        assert!(m.reads.len() <= READ_WINDOW);
        if t.duration_since(now) >= m.read_timeout {
            break;
        }
    }
    assert!(sent >= READ_WINDOW.min(10), "{sent}");
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
    assert!(
        sends <= 3 * usize::from(FTP_TRIES),
        "three copies a try: {sends}"
    );
    assert!(m.result().expect("done").is_err());
}

#[test]
fn an_open_answered_after_lost_tries_times_its_reads_by_the_link_not_by_the_retries() {
    // The link's round trip is 200 ms (rto 300 ms); two opens were lost, and the third's
    // answer comes 200 ms after it was sent.
    let t0 = Instant::now();
    let mut m = FtpPullMachine::new(V, 4, Duration::from_millis(300));
    m.start(t0);
    let mut now = t0;
    let mut last = None;
    for _ in 0..2 {
        now = m.deadline();
        let out = m.on_time(now);
        assert!(!out.is_empty(), "the open again");
        last = Some(payload(&out[0]));
    }
    let answered = now + Duration::from_millis(200);
    m.on_message(
        answered,
        &reply(&last.expect("sent"), OP_ACK, &[0; 4], 0, false),
    );
    let from_first = answered.duration_since(t0);
    assert!(
        m.read_timeout < Duration::from_millis(600) && m.read_timeout < from_first,
        "read timeout {:?}, {from_first:?} from the first open",
        m.read_timeout
    );
    assert!(
        m.stall() > m.read_timeout * 3,
        "a lost read is asked again before the read is given up"
    );
}

#[test]
fn a_burst_of_which_nothing_came_is_asked_again_before_any_gap_is_read() {
    let t0 = Instant::now();
    let mut m = FtpPullMachine::new(V, 4, Duration::from_millis(300));
    let open = payload(&m.start(t0)[0]);
    let now = t0 + Duration::from_millis(200);
    let out = m.on_message(now, &reply(&open, OP_ACK, &[0; 4], 0, false));
    assert_eq!(payload(&out[0])[3], OP_BURST);
    // The burst request is lost: nothing comes back.
    let later = m.deadline();
    let out = m.on_time(later);
    assert_eq!(out.len(), 1, "{out:?}");
    let again = payload(&out[0]);
    assert_eq!(again[3], OP_BURST, "the burst again, not reads");
    assert_eq!(
        u32::from_le_bytes([again[8], again[9], again[10], again[11]]),
        0
    );
}
