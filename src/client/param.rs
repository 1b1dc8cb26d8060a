//! The parameter protocol as state machines: the whole-table download, one read, and one
//! verified write.
//!
//! Download: PARAM_REQUEST_LIST, then, once the stream has ended (its last index arrived, or it
//! has been silent for a round-trip timeout), the missing indices by PARAM_REQUEST_READ(index), at most [`PULL_WINDOW`]
//! outstanding: each answer lets the next request go, so the pace follows what the link
//! carries. A request unanswered for a timeout is sent again. Echoes with index 65535 (a by-name
//! answer or another client's write) update values by name.
//!
//! Write: PARAM_SET, confirmed only by a PARAM_VALUE echo equal to the value after the vehicle's
//! type conversion (bit-exact for floats). A PARAM_ERROR is a definite refusal; the reason is
//! the vehicle's STATUSTEXT about that name when one arrives, otherwise the error code.

use std::collections::{BTreeMap, HashMap};
use std::time::{Duration, Instant};

use vtol_link::dialect::{self as apm, MavMessage, MavParamError, MavParamType};
use vtol_link::{ComponentId, SystemId};

use super::machine::{GIVE_UP_AFTER, Inbound, Machine, Rtt, retry_wait};
use crate::params::{Param, ParamSet, stored_value};

/// Index re-requests outstanding at once during a download.
pub const PULL_WINDOW: usize = 16;
/// Consecutive timeouts without any new value before a download gives up…
pub const PULL_STALLS: u32 = 12;
/// …and at least this long without one: a busy machine can pause a fast link for longer than
/// twelve short timeouts.
pub const PULL_GIVE_UP: Duration = Duration::from_secs(3);
/// Sends of one write or read before giving up. At 30 % loss each way one exchange fails about
/// half the time, so twelve sends leave a 0.03 % chance of a false "no answer"; with the
/// timeout at a few round trips that is still well under a second on a fast link.
pub const PARAM_TRIES: u8 = 12;

fn name_of(id: &mavlink::types::CharArray<16>) -> String {
    id.to_str().unwrap_or("").trim_end_matches('\0').to_owned()
}

/// Why a download did not complete.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct PullStalled {
    /// Values received.
    pub received: usize,
    /// Values announced (0 if no value ever came).
    pub total: usize,
}

/// The whole-table download.
#[derive(Debug)]
pub struct PullMachine {
    target: (SystemId, ComponentId),
    /// The client's estimate, refined by this download's own samples.
    rtt: Rtt,
    rto: Duration,
    count: Option<u16>,
    values: BTreeMap<u16, (String, Param)>,
    by_name: HashMap<String, u16>,
    /// Re-requested index -> (answer due, sent at, first send?).
    outstanding: BTreeMap<u16, (Instant, Instant, bool)>,
    /// Indices already asked once: a later answer may be to any send (Karn's rule).
    asked: std::collections::HashSet<u16>,
    samples: Vec<Duration>,
    started: Instant,
    last_rx: Instant,
    deadline: Instant,
    stalls: u32,
    list_sends: u32,
    /// PARAM_REQUEST_READs sent (for the benchmark's report).
    pub rerequests: usize,
    done: Option<Result<ParamSet, PullStalled>>,
}

impl PullMachine {
    /// A download from `target`, starting from the client's round-trip estimate.
    #[must_use]
    pub fn new(target: (SystemId, ComponentId), rtt: Rtt) -> Self {
        let now = Instant::now();
        Self {
            target,
            rtt,
            rto: rtt.rto(),
            count: None,
            values: BTreeMap::new(),
            by_name: HashMap::new(),
            outstanding: BTreeMap::new(),
            asked: std::collections::HashSet::new(),
            samples: Vec::new(),
            started: now,
            last_rx: now,
            deadline: now,
            stalls: 0,
            list_sends: 0,
            rerequests: 0,
            done: None,
        }
    }

    /// (received, total) for a progress bar; total is 0 until the first value.
    #[must_use]
    pub fn progress(&self) -> (usize, usize) {
        (self.values.len(), self.count.map_or(0, usize::from))
    }

    fn list(&mut self, now: Instant) -> MavMessage {
        self.list_sends += 1;
        self.deadline = now + self.rto;
        MavMessage::PARAM_REQUEST_LIST(apm::PARAM_REQUEST_LIST_DATA {
            target_system: self.target.0.0,
            target_component: self.target.1.0,
        })
    }

    fn read(&mut self, index: u16, now: Instant) -> MavMessage {
        self.rerequests += 1;
        let first = self.asked.insert(index);
        self.outstanding.insert(index, (now + self.rto, now, first));
        MavMessage::PARAM_REQUEST_READ(apm::PARAM_REQUEST_READ_DATA {
            param_index: index as i16,
            target_system: self.target.0.0,
            target_component: self.target.1.0,
            param_id: "".into(),
        })
    }

    /// Fill the window with requests for missing indices not already asked for.
    fn refill(&mut self, now: Instant) -> Vec<MavMessage> {
        let Some(count) = self.count else {
            return Vec::new();
        };
        let mut out = Vec::new();
        let mut next = 0u16;
        while self.outstanding.len() < PULL_WINDOW && next < count {
            if !self.values.contains_key(&next) && !self.outstanding.contains_key(&next) {
                out.push(self.read(next, now));
            }
            next += 1;
        }
        out
    }

    fn complete(&mut self) {
        if let Some(count) = self.count
            && self.values.len() >= usize::from(count)
        {
            let set = self.values.values().map(|(n, p)| (n.clone(), *p)).collect();
            self.done = Some(Ok(set));
        }
    }
}

impl Machine for PullMachine {
    type Output = Result<ParamSet, PullStalled>;

    fn start(&mut self, now: Instant) -> Vec<MavMessage> {
        self.last_rx = now;
        self.started = now;
        vec![self.list(now)]
    }

    fn on_message(&mut self, now: Instant, m: &Inbound) -> Vec<MavMessage> {
        if self.done.is_some() || (m.sys, m.comp) != self.target {
            return Vec::new();
        }
        let MavMessage::PARAM_VALUE(v) = &m.msg else {
            return Vec::new();
        };
        let name = name_of(&v.param_id);
        let param = Param {
            value: v.param_value,
            ty: v.param_type,
        };
        self.count.get_or_insert(v.param_count);
        let index = if v.param_index == u16::MAX {
            match self.by_name.get(&name) {
                Some(&i) => i,
                None => return Vec::new(),
            }
        } else {
            v.param_index
        };
        if self.count.is_some_and(|c| index >= c) {
            return Vec::new();
        }
        self.last_rx = now;
        self.stalls = 0;
        self.by_name.insert(name.clone(), index);
        self.values.insert(index, (name, param));
        let mut sample = None;
        if self.values.len() == 1 && self.list_sends == 1 {
            sample = Some(now.duration_since(self.started));
        }
        let asked = self.outstanding.remove(&index);
        if let Some((_, sent, true)) = asked {
            sample = Some(now.duration_since(sent));
        }
        if let Some(s) = sample {
            self.samples.push(s);
            self.rtt.sample(s);
            self.rto = self.rtt.rto();
        }
        let was_asked = asked.is_some();
        self.deadline = now + self.rto;
        self.complete();
        if self.done.is_some() {
            return Vec::new();
        }
        // While re-requesting, each answer frees a window slot for the next request. The last
        // index of the list stream (sent in index order) means the stream is over: ask for the
        // holes now rather than after a silence.
        let stream_end = !was_asked && self.count == Some(index + 1);
        if was_asked || stream_end {
            self.refill(now)
        } else {
            Vec::new()
        }
    }

    fn on_time(&mut self, now: Instant) -> Vec<MavMessage> {
        if self.done.is_some() || now < self.deadline() {
            return Vec::new();
        }
        if now.duration_since(self.last_rx) >= self.rto {
            self.stalls += 1;
            if self.stalls > PULL_STALLS && now.duration_since(self.last_rx) >= PULL_GIVE_UP {
                let (received, total) = self.progress();
                self.done = Some(Err(PullStalled { received, total }));
                return Vec::new();
            }
        }
        if self.count.is_none() {
            return vec![self.list(now)];
        }
        // Requests whose answer is overdue are asked again.
        let overdue: Vec<u16> = self
            .outstanding
            .iter()
            .filter(|(_, (due, ..))| *due <= now)
            .map(|(i, _)| *i)
            .collect();
        let mut out: Vec<MavMessage> = overdue.into_iter().map(|i| self.read(i, now)).collect();
        if self.outstanding.is_empty() && now.duration_since(self.last_rx) >= self.rto {
            // The list stream went quiet: start asking for the holes.
            out.extend(self.refill(now));
        }
        self.deadline = now + self.rto;
        out
    }

    fn deadline(&self) -> Instant {
        let stream_quiet = self.last_rx + self.rto;
        let next_due = self.outstanding.values().map(|(due, ..)| *due).min();
        match next_due {
            Some(d) => d.min(self.deadline.max(stream_quiet)),
            None => self.deadline.max(stream_quiet),
        }
    }

    fn result(&mut self) -> Option<Self::Output> {
        self.done.take()
    }

    fn take_rtt_samples(&mut self) -> Vec<Duration> {
        std::mem::take(&mut self.samples)
    }
}

/// Why one write or read did not confirm.
#[derive(Debug, Clone, PartialEq)]
pub enum ParamFailure {
    /// The vehicle refused: its reason.
    Refused(String),
    /// The vehicle has no such parameter.
    Unknown,
    /// No confirming answer after every try; `last_echo` is the last value it reported.
    NoAnswer {
        /// Sends made.
        tries: u8,
        /// A value echoed that did not match, if any.
        last_echo: Option<f32>,
    },
}

fn param_error_text(e: MavParamError) -> &'static str {
    match e {
        MavParamError::MAV_PARAM_ERROR_DOES_NOT_EXIST => "does not exist",
        MavParamError::MAV_PARAM_ERROR_VALUE_OUT_OF_RANGE => "value out of range",
        MavParamError::MAV_PARAM_ERROR_PERMISSION_DENIED => "permission denied",
        MavParamError::MAV_PARAM_ERROR_READ_ONLY => "read-only",
        MavParamError::MAV_PARAM_ERROR_TYPE_MISMATCH => "type mismatch",
        MavParamError::MAV_PARAM_ERROR_TYPE_UNSUPPORTED => "type unsupported",
        _ => "refused",
    }
}

/// One read by name, or one verified write.
#[derive(Debug)]
pub struct ParamMachine {
    target: (SystemId, ComponentId),
    name: String,
    /// `Some((value, type))` for a write; `None` for a read.
    write: Option<(f32, MavParamType)>,
    rto: Duration,
    tries: u8,
    started: Instant,
    deadline: Instant,
    last_echo: Option<f32>,
    refused: Option<(String, Instant)>,
    /// Long reasons come in chunks (STATUSTEXT `id`/`chunk_seq`).
    assembler: super::statustext::TextAssembler,
    /// Round trip of an exchange answered on its first send.
    pub first_try_rtt: Option<Duration>,
    done: Option<Result<Param, ParamFailure>>,
}

/// How long a PARAM_ERROR waits for the STATUSTEXT that explains it.
const REASON_GRACE: Duration = Duration::from_millis(150);

impl ParamMachine {
    /// Reads `name`.
    #[must_use]
    pub fn read(target: (SystemId, ComponentId), name: &str, rto: Duration) -> Self {
        Self::new(target, name, None, rto)
    }

    /// Writes `value` to `name`, whose type on the vehicle is `ty`.
    #[must_use]
    pub fn write(
        target: (SystemId, ComponentId),
        name: &str,
        value: f32,
        ty: MavParamType,
        rto: Duration,
    ) -> Self {
        Self::new(target, name, Some((value, ty)), rto)
    }

    fn new(
        target: (SystemId, ComponentId),
        name: &str,
        write: Option<(f32, MavParamType)>,
        rto: Duration,
    ) -> Self {
        let now = Instant::now();
        Self {
            target,
            name: name.to_owned(),
            write,
            rto,
            tries: 0,
            started: now,
            deadline: now,
            last_echo: None,
            refused: None,
            assembler: super::statustext::TextAssembler::default(),
            first_try_rtt: None,
            done: None,
        }
    }

    fn request(&mut self, now: Instant) -> MavMessage {
        self.tries += 1;
        self.deadline = now + retry_wait(self.rto, self.tries);
        match self.write {
            Some((value, ty)) => MavMessage::PARAM_SET(apm::PARAM_SET_DATA {
                param_value: value,
                target_system: self.target.0.0,
                target_component: self.target.1.0,
                param_id: self.name.as_str().into(),
                param_type: ty,
            }),
            None => MavMessage::PARAM_REQUEST_READ(apm::PARAM_REQUEST_READ_DATA {
                param_index: -1,
                target_system: self.target.0.0,
                target_component: self.target.1.0,
                param_id: self.name.as_str().into(),
            }),
        }
    }
}

impl Machine for ParamMachine {
    type Output = Result<Param, ParamFailure>;

    fn start(&mut self, now: Instant) -> Vec<MavMessage> {
        self.started = now;
        vec![self.request(now)]
    }

    fn on_message(&mut self, now: Instant, m: &Inbound) -> Vec<MavMessage> {
        if self.done.is_some() || (m.sys, m.comp) != self.target {
            return Vec::new();
        }
        match &m.msg {
            MavMessage::PARAM_VALUE(v) if name_of(&v.param_id) == self.name => {
                let p = Param {
                    value: v.param_value,
                    ty: v.param_type,
                };
                let confirmed = match self.write {
                    None => true,
                    Some((want, _)) => crate::params::same_value(p.value, stored_value(p.ty, want)),
                };
                if confirmed {
                    if self.tries == 1 {
                        self.first_try_rtt = Some(now.duration_since(self.started));
                    }
                    self.done = Some(Ok(p));
                } else {
                    // The unchanged value of a refusal, or an old echo: wait for PARAM_ERROR
                    // or the echo of a retry.
                    self.last_echo = Some(p.value);
                }
            }
            MavMessage::PARAM_ERROR(e) if name_of(&e.param_id) == self.name => {
                if e.error == MavParamError::MAV_PARAM_ERROR_DOES_NOT_EXIST {
                    self.done = Some(Err(ParamFailure::Unknown));
                } else if self.write.is_some() && self.refused.is_none() {
                    let reason = format!("{}: {}", self.name, param_error_text(e.error));
                    self.refused = Some((reason, now));
                    self.deadline = now + REASON_GRACE;
                }
            }
            MavMessage::STATUSTEXT(t) => {
                // Long reasons come in chunks: put them together first.
                if let Some(text) = self.assembler.push(t)
                    && self.refused.is_some()
                    && text.contains(self.name.as_str())
                {
                    self.done = Some(Err(ParamFailure::Refused(text)));
                }
            }
            _ => {}
        }
        Vec::new()
    }

    fn on_time(&mut self, now: Instant) -> Vec<MavMessage> {
        if self.done.is_some() || now < self.deadline {
            return Vec::new();
        }
        if let Some((reason, _)) = self.refused.take() {
            self.done = Some(Err(ParamFailure::Refused(reason)));
            return Vec::new();
        }
        if self.tries >= PARAM_TRIES && now.duration_since(self.started) >= GIVE_UP_AFTER {
            self.done = Some(Err(ParamFailure::NoAnswer {
                tries: self.tries,
                last_echo: self.last_echo,
            }));
            return Vec::new();
        }
        vec![self.request(now)]
    }

    fn deadline(&self) -> Instant {
        self.deadline
    }

    fn result(&mut self) -> Option<Self::Output> {
        self.done.take()
    }

    fn take_rtt_samples(&mut self) -> Vec<Duration> {
        self.first_try_rtt.take().into_iter().collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const V: (SystemId, ComponentId) = (SystemId(1), ComponentId(1));
    const F32: MavParamType = MavParamType::MAV_PARAM_TYPE_REAL32;

    fn value(name: &str, v: f32, index: u16, count: u16, ty: MavParamType) -> Inbound {
        Inbound {
            sys: V.0,
            comp: V.1,
            msg: MavMessage::PARAM_VALUE(apm::PARAM_VALUE_DATA {
                param_value: v,
                param_count: count,
                param_index: index,
                param_id: name.into(),
                param_type: ty,
            }),
        }
    }

    fn rtt(ms: u64) -> Rtt {
        let mut r = Rtt::default();
        r.sample(Duration::from_millis(ms));
        r
    }

    fn read_indices(out: &[MavMessage]) -> Vec<i16> {
        out.iter()
            .filter_map(|m| match m {
                MavMessage::PARAM_REQUEST_READ(r) => Some(r.param_index),
                _ => None,
            })
            .collect()
    }

    #[test]
    fn pull_rerequests_holes_after_a_silence_and_completes() {
        let t0 = Instant::now();
        let mut m = PullMachine::new(V, rtt(10));
        let first = m.start(t0);
        assert!(matches!(first[..], [MavMessage::PARAM_REQUEST_LIST(_)]));
        // 5 parameters; 1 and 3 are lost, and the stream is still going.
        for i in [0u16, 2] {
            assert!(
                m.on_message(t0, &value(&format!("P{i}"), f32::from(i), i, 5, F32))
                    .is_empty()
            );
        }
        assert!(m.result().is_none());
        assert_eq!(m.progress(), (2, 5));
        // The last index ends the stream: the holes are asked for at once.
        let asks = m.on_message(t0, &value("P4", 4.0, 4, 5, F32));
        assert_eq!(read_indices(&asks), [1, 3]);
        assert!(
            m.on_time(t0 + Duration::from_millis(5)).is_empty(),
            "nothing overdue yet"
        );
        // An echo by name (index 65535) of a known parameter updates it.
        m.on_message(t0, &value("P2", 7.0, u16::MAX, 5, F32));
        m.on_message(t0, &value("P1", 1.0, 1, 5, F32));
        // 3 was lost again: asked again once overdue.
        let again = m.on_time(m.deadline());
        assert_eq!(read_indices(&again), [3]);
        m.on_message(t0, &value("P3", 3.0, 3, 5, F32));
        let set = m.result().expect("done").expect("complete");
        assert_eq!(set.len(), 5);
        assert_eq!(set["P2"].value, 7.0);
    }

    #[test]
    fn pull_gives_up_when_nothing_answers() {
        let t0 = Instant::now();
        let mut m = PullMachine::new(V, rtt(10));
        m.start(t0);
        let mut lists = 0;
        for _ in 0..1000 {
            let d = m.deadline();
            lists += m.on_time(d).len();
            if let Some(r) = m.result() {
                assert_eq!(
                    r,
                    Err(PullStalled {
                        received: 0,
                        total: 0
                    })
                );
                assert!(lists >= 3, "the list request is repeated before giving up");
                assert!(d.duration_since(t0) >= PULL_GIVE_UP, "gave up too soon");
                return;
            }
        }
        panic!("never gave up");
    }

    #[test]
    fn write_is_confirmed_only_by_the_exact_echo() {
        let t0 = Instant::now();
        let mut m = ParamMachine::write(V, "LAT_SAT_A", 0.4, F32, Duration::from_millis(20));
        m.start(t0);
        // Another value (an old echo, or a refusal's unchanged value) does not confirm.
        m.on_message(t0, &value("LAT_SAT_A", 1.2, 6, 38, F32));
        assert!(m.result().is_none());
        // A value for another name does not either.
        m.on_message(t0, &value("LAT_SAT_B", 0.4, 7, 38, F32));
        assert!(m.result().is_none());
        m.on_message(t0, &value("LAT_SAT_A", 0.4, u16::MAX, 38, F32));
        assert_eq!(m.result().expect("done").expect("confirmed").value, 0.4);
    }

    #[test]
    fn integer_write_confirms_with_the_vehicle_rounding() {
        let t0 = Instant::now();
        let i16t = MavParamType::MAV_PARAM_TYPE_INT16;
        let mut m = ParamMachine::write(V, "SIM_PUSH_MS", 250.4, i16t, Duration::from_millis(20));
        m.start(t0);
        m.on_message(t0, &value("SIM_PUSH_MS", 250.0, 34, 38, i16t));
        assert_eq!(m.result().expect("done").expect("confirmed").value, 250.0);
    }

    #[test]
    fn param_error_is_a_refusal_with_the_vehicle_text() {
        let t0 = Instant::now();
        let mut m = ParamMachine::write(V, "LAT_SAT_B", 2.0, F32, Duration::from_millis(20));
        m.start(t0);
        m.on_message(t0, &value("LAT_SAT_B", 0.6, 7, 38, F32));
        m.on_message(
            t0,
            &Inbound {
                sys: SystemId(1),
                comp: ComponentId(1),
                msg: MavMessage::PARAM_ERROR(apm::PARAM_ERROR_DATA {
                    param_index: 7,
                    target_system: 255,
                    target_component: 190,
                    param_id: "LAT_SAT_B".into(),
                    error: MavParamError::MAV_PARAM_ERROR_VALUE_OUT_OF_RANGE,
                }),
            },
        );
        assert!(m.result().is_none(), "waits briefly for the reason");
        m.on_message(
            t0,
            &Inbound {
                sys: SystemId(1),
                comp: ComponentId(1),
                msg: MavMessage::STATUSTEXT(apm::STATUSTEXT_DATA {
                    severity: apm::MavSeverity::MAV_SEVERITY_WARNING,
                    text: "Param write denied (LAT_SAT_B: needs a > b + c + d)".into(),
                    id: 0,
                    chunk_seq: 0,
                }),
            },
        );
        match m.result() {
            Some(Err(ParamFailure::Refused(r))) => {
                assert!(r.contains("needs a > b + c + d"), "{r}")
            }
            other => panic!("{other:?}"),
        }
    }

    #[test]
    fn write_retries_then_reports_no_answer() {
        let t0 = Instant::now();
        let mut m = ParamMachine::write(V, "ALT_KP", 6.0, F32, Duration::from_millis(20));
        let mut sends = m.start(t0).len();
        while m.result_peek_pending() {
            let d = m.deadline();
            sends += m.on_time(d).len();
        }
        assert!(sends >= usize::from(PARAM_TRIES), "{sends} sends");
        assert!(m.deadline().duration_since(t0) >= GIVE_UP_AFTER);
    }

    impl ParamMachine {
        fn result_peek_pending(&self) -> bool {
            self.done.is_none()
        }
    }
}
