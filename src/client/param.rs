//! The parameter protocol as state machines: the whole-table download, one read, and one
//! verified write.
//!
//! Download ([`PullMachine`], in `param/pull.rs`): PARAM_REQUEST_LIST, then the holes in the
//! stream by PARAM_REQUEST_READ(index), asked for as soon as a later index shows them, in
//! several copies once the link has shown loss.
//!
//! Write: PARAM_SET, confirmed by a PARAM_VALUE echo equal to the value after the vehicle's
//! type conversion ([`crate::params::same_value`]: float32 as the vehicle holds it). A
//! PARAM_ERROR is a definite refusal; the reason is the vehicle's STATUSTEXT about that name
//! when one arrives, otherwise the error code. ArduPilot has no PARAM_ERROR: it refuses a
//! write with a STATUSTEXT `Param write denied (NAME)` and echoes the unchanged value, and it
//! stores what its type can hold (an integer clamped to its range), echoing that. So a denial
//! text about the name is a refusal too, and the same other value echoed to two sends is the
//! vehicle's answer: the write ends with that value, which the caller compares.

use std::time::{Duration, Instant};

use vtol_link::dialect::{self as apm, MavMessage, MavParamError, MavParamType};
use vtol_link::{ComponentId, SystemId};

use super::machine::{GIVE_UP_AFTER, Inbound, Machine, Retry, Step};
use crate::params::{Param, stored_value};

mod ftp;
mod pull;
pub use ftp::{FtpPullMachine, PARAM_FILE, PckError, decode_pck};
pub use pull::{CLEAN_WINDOW, PULL_WINDOW, PullMachine, PullStalled};

/// Sends of one write or read before giving up. At 30 % loss each way one exchange fails about
/// half the time: twelve single sends left a 0.03 % chance of a false "no answer", which a
/// push of a dozen gains (a write and a read-back each) met once in a few hundred pushes. So a
/// send after the first goes in [`RETRY_COPIES`] copies: a retry means the link lost
/// something, and two copies fail together a quarter of the time (4 × 10⁻⁷ for the twelve).
pub const PARAM_TRIES: u8 = 12;
/// Copies of each send after the first.
pub const RETRY_COPIES: usize = 2;

fn name_of(id: &mavlink::types::CharArray<16>) -> String {
    id.to_str().unwrap_or("").trim_end_matches('\0').to_owned()
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

/// Whether `text` names the parameter `name` as a word (`Q_A_RAT_RLL_P` is not in
/// `Q_A_RAT_RLL_PDMX`).
fn mentions(text: &str, name: &str) -> bool {
    let word = |c: char| c.is_ascii_alphanumeric() || c == '_';
    text.match_indices(name).any(|(i, _)| {
        let before = text[..i].chars().next_back();
        let after = text[i + name.len()..].chars().next();
        !before.is_some_and(word) && !after.is_some_and(word)
    })
}

/// One read by name, or one verified write.
#[derive(Debug)]
pub struct ParamMachine {
    target: (SystemId, ComponentId),
    name: String,
    /// `Some((value, type))` for a write; `None` for a read.
    write: Option<(f32, MavParamType)>,
    retry: Retry,
    last_echo: Option<f32>,
    refused: Option<(String, Instant)>,
    /// An echo (index 65535) of another value than the one written, and the sends made when
    /// it came: the same value echoed to a later send is the vehicle's answer.
    other_echo: Option<(f32, u8)>,
    /// Long reasons come in chunks (STATUSTEXT `id`/`chunk_seq`).
    assembler: vtol_link::statustext::TextAssembler,
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
        Self {
            target,
            name: name.to_owned(),
            write,
            retry: Retry::new(rto, PARAM_TRIES, GIVE_UP_AFTER),
            last_echo: None,
            refused: None,
            other_echo: None,
            assembler: vtol_link::statustext::TextAssembler::default(),
            first_try_rtt: None,
            done: None,
        }
    }

    fn request(&mut self, now: Instant) -> MavMessage {
        self.retry.send(now);
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
                    if let Some(rtt) = self.retry.first_try_rtt(now) {
                        self.first_try_rtt = Some(rtt);
                    }
                    self.done = Some(Ok(p));
                } else {
                    // The unchanged value of a refusal, or an old echo: wait for PARAM_ERROR
                    // or the echo of a retry. The same other value echoed again to a retry
                    // (ArduPilot's echo carries index 65535) is what the vehicle holds.
                    if v.param_index == u16::MAX {
                        let tries = self.retry.tries();
                        match self.other_echo {
                            Some((seen, at))
                                if crate::params::same_value(seen, p.value) && tries > at =>
                            {
                                if self.refused.is_none() {
                                    self.done = Some(Ok(p));
                                }
                            }
                            _ => self.other_echo = Some((p.value, tries)),
                        }
                    }
                    self.last_echo = Some(p.value);
                }
            }
            MavMessage::PARAM_ERROR(e) if name_of(&e.param_id) == self.name => {
                if e.error == MavParamError::MAV_PARAM_ERROR_DOES_NOT_EXIST {
                    self.done = Some(Err(ParamFailure::Unknown));
                } else if self.write.is_some() && self.refused.is_none() {
                    let reason = format!("{}: {}", self.name, param_error_text(e.error));
                    self.refused = Some((reason, now));
                    self.retry.wait_until(now + REASON_GRACE);
                }
            }
            MavMessage::STATUSTEXT(t) => {
                // Long reasons come in chunks: put them together first.
                if let Some(text) = self.assembler.push(t)
                    && mentions(&text, &self.name)
                {
                    if self.refused.is_some() {
                        self.done = Some(Err(ParamFailure::Refused(text)));
                    } else if self.write.is_some() && text.to_ascii_lowercase().contains("denied") {
                        // ArduPilot's refusal: its unchanged echo follows (or came first).
                        self.refused = Some((text, now));
                        self.retry.wait_until(now + REASON_GRACE);
                    }
                }
            }
            _ => {}
        }
        Vec::new()
    }

    fn on_time(&mut self, now: Instant) -> Vec<MavMessage> {
        let step = self.retry.step(now);
        if self.done.is_some() || step == Step::Wait {
            return Vec::new();
        }
        if let Some((reason, _)) = self.refused.take() {
            self.done = Some(Err(ParamFailure::Refused(reason)));
            return Vec::new();
        }
        if step == Step::GiveUp {
            self.done = Some(Err(ParamFailure::NoAnswer {
                tries: self.retry.tries(),
                last_echo: self.last_echo,
            }));
            return Vec::new();
        }
        // A write's copies set the same value; echoes of them all count as this send's.
        vec![self.request(now); RETRY_COPIES]
    }

    fn deadline(&self) -> Instant {
        self.retry.deadline()
    }

    fn result(&mut self) -> Option<Self::Output> {
        self.done.take()
    }

    fn take_rtt_samples(&mut self) -> Vec<Duration> {
        self.first_try_rtt.take().into_iter().collect()
    }
}

/// The vehicle (1, 1) of the parameter machines' tests.
#[cfg(test)]
const TEST_VEHICLE: (SystemId, ComponentId) = (SystemId(1), ComponentId(1));

/// A PARAM_VALUE from [`TEST_VEHICLE`], as the parameter machines' tests feed them.
#[cfg(test)]
fn test_value(name: &str, v: f32, index: u16, count: u16, ty: MavParamType) -> Inbound {
    Inbound {
        sys: TEST_VEHICLE.0,
        comp: TEST_VEHICLE.1,
        msg: MavMessage::PARAM_VALUE(apm::PARAM_VALUE_DATA {
            param_value: v,
            param_count: count,
            param_index: index,
            param_id: name.into(),
            param_type: ty,
        }),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const V: (SystemId, ComponentId) = TEST_VEHICLE;
    const F32: MavParamType = MavParamType::MAV_PARAM_TYPE_REAL32;
    use super::test_value as value;

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

    fn text(s: &str) -> Inbound {
        Inbound {
            sys: SystemId(1),
            comp: ComponentId(1),
            msg: MavMessage::STATUSTEXT(apm::STATUSTEXT_DATA {
                severity: apm::MavSeverity::MAV_SEVERITY_WARNING,
                text: s.into(),
                id: 0,
                chunk_seq: 0,
            }),
        }
    }

    /// ArduPilot has no PARAM_ERROR: "Param write denied (NAME)" and the unchanged value.
    #[test]
    fn ardupilots_denial_text_is_a_refusal() {
        let t0 = Instant::now();
        let i16t = MavParamType::MAV_PARAM_TYPE_INT16;
        let mut m = ParamMachine::write(V, "MIS_TOTAL", 3.0, i16t, Duration::from_millis(20));
        m.start(t0);
        // Another parameter's denial is not this one's.
        m.on_message(t0, &text("Param write denied (MIS_TOTAL_X)"));
        m.on_message(t0, &text("Param write denied (MIS_TOTAL)"));
        m.on_message(t0, &value("MIS_TOTAL", 0.0, u16::MAX, 1566, i16t));
        assert!(m.result().is_none(), "the grace for a fuller reason");
        m.on_time(m.deadline());
        match m.result() {
            Some(Err(ParamFailure::Refused(r))) => assert_eq!(r, "Param write denied (MIS_TOTAL)"),
            other => panic!("{other:?}"),
        }
    }

    /// ArduPilot stores what the type holds: the same other value echoed to two sends is the
    /// answer (the caller sees the vehicle kept another value), not a silence of 12 tries.
    #[test]
    fn the_same_other_echo_to_a_retry_ends_the_write_with_it() {
        let t0 = Instant::now();
        let i8t = MavParamType::MAV_PARAM_TYPE_INT8;
        let mut m = ParamMachine::write(V, "Q_TILT_ENABLE", 1.0, i8t, Duration::from_millis(20));
        m.start(t0);
        m.on_message(t0, &value("Q_TILT_ENABLE", 0.0, u16::MAX, 1566, i8t));
        assert!(m.result().is_none(), "maybe an old echo");
        let d = m.deadline();
        assert_eq!(m.on_time(d).len(), RETRY_COPIES, "a retry goes in copies");
        // A stream value (real index) does not count as an echo.
        m.on_message(d, &value("Q_TILT_ENABLE", 0.0, 400, 1566, i8t));
        assert!(m.result().is_none());
        m.on_message(d, &value("Q_TILT_ENABLE", 0.0, u16::MAX, 1566, i8t));
        assert_eq!(m.result().expect("done").expect("answered").value, 0.0);
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
