//! The parameter protocol as state machines: the whole-table download, one read, and one
//! verified write.
//!
//! Download: PARAM_REQUEST_LIST, then, once the stream has been silent for a round-trip
//! timeout, the missing indices by PARAM_REQUEST_READ(index), at most [`PULL_WINDOW`]
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

use super::machine::{Inbound, Machine};
use crate::params::{Param, ParamSet, stored_value};

/// Index re-requests outstanding at once during a download.
pub const PULL_WINDOW: usize = 16;
/// Consecutive timeouts without any new value before a download gives up.
pub const PULL_STALLS: u32 = 12;
/// Sends of one write or read before giving up.
pub const PARAM_TRIES: u8 = 6;

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
    target: (u8, u8),
    rto: Duration,
    count: Option<u16>,
    values: BTreeMap<u16, (String, Param)>,
    by_name: HashMap<String, u16>,
    outstanding: BTreeMap<u16, Instant>,
    last_rx: Instant,
    deadline: Instant,
    stalls: u32,
    list_sends: u32,
    /// PARAM_REQUEST_READs sent (for the benchmark's report).
    pub rerequests: usize,
    done: Option<Result<ParamSet, PullStalled>>,
}

impl PullMachine {
    /// A download from `target` with retransmission timeout `rto`.
    #[must_use]
    pub fn new(target: (u8, u8), rto: Duration) -> Self {
        let now = Instant::now();
        Self {
            target,
            rto,
            count: None,
            values: BTreeMap::new(),
            by_name: HashMap::new(),
            outstanding: BTreeMap::new(),
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
            target_system: self.target.0,
            target_component: self.target.1,
        })
    }

    fn read(&mut self, index: u16, now: Instant) -> MavMessage {
        self.rerequests += 1;
        self.outstanding.insert(index, now + self.rto);
        MavMessage::PARAM_REQUEST_READ(apm::PARAM_REQUEST_READ_DATA {
            param_index: index as i16,
            target_system: self.target.0,
            target_component: self.target.1,
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
        let was_asked = self.outstanding.remove(&index).is_some();
        self.complete();
        if self.done.is_some() {
            return Vec::new();
        }
        // While re-requesting, each answer frees a window slot for the next request.
        if was_asked {
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
            if self.stalls > PULL_STALLS {
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
            .filter(|(_, due)| **due <= now)
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
        let next_due = self.outstanding.values().min().copied();
        match next_due {
            Some(d) => d.min(self.deadline.max(stream_quiet)),
            None => self.deadline.max(stream_quiet),
        }
    }

    fn result(&mut self) -> Option<Self::Output> {
        self.done.take()
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
    target: (u8, u8),
    name: String,
    /// `Some((value, type))` for a write; `None` for a read.
    write: Option<(f32, MavParamType)>,
    rto: Duration,
    tries: u8,
    started: Instant,
    deadline: Instant,
    last_echo: Option<f32>,
    refused: Option<(String, Instant)>,
    /// Round trip of an exchange answered on its first send.
    pub first_try_rtt: Option<Duration>,
    done: Option<Result<Param, ParamFailure>>,
}

/// How long a PARAM_ERROR waits for the STATUSTEXT that explains it.
const REASON_GRACE: Duration = Duration::from_millis(150);

impl ParamMachine {
    /// Reads `name`.
    #[must_use]
    pub fn read(target: (u8, u8), name: &str, rto: Duration) -> Self {
        Self::new(target, name, None, rto)
    }

    /// Writes `value` to `name`, whose type on the vehicle is `ty`.
    #[must_use]
    pub fn write(
        target: (u8, u8),
        name: &str,
        value: f32,
        ty: MavParamType,
        rto: Duration,
    ) -> Self {
        Self::new(target, name, Some((value, ty)), rto)
    }

    fn new(
        target: (u8, u8),
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
            first_try_rtt: None,
            done: None,
        }
    }

    fn request(&mut self, now: Instant) -> MavMessage {
        self.tries += 1;
        self.deadline = now + self.rto;
        match self.write {
            Some((value, ty)) => MavMessage::PARAM_SET(apm::PARAM_SET_DATA {
                param_value: value,
                target_system: self.target.0,
                target_component: self.target.1,
                param_id: self.name.as_str().into(),
                param_type: ty,
            }),
            None => MavMessage::PARAM_REQUEST_READ(apm::PARAM_REQUEST_READ_DATA {
                param_index: -1,
                target_system: self.target.0,
                target_component: self.target.1,
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
                    self.refused = Some((param_error_text(e.error).to_owned(), now));
                    self.deadline = now + REASON_GRACE;
                }
            }
            MavMessage::STATUSTEXT(t) if self.refused.is_some() => {
                let text = t.text.to_str().unwrap_or("").trim_end_matches('\0');
                if text.contains(self.name.as_str()) {
                    self.done = Some(Err(ParamFailure::Refused(text.to_owned())));
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
        if self.tries >= PARAM_TRIES {
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
}
