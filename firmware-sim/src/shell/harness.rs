//! The harness channel: how a test drives a running twin from outside MAVLink. It steps a
//! lockstep twin, reads the vehicle's true state and writes parameters the way a test fixture
//! wants them (the `vtol_twin` pytest plugin in `python/vtol_twin/` is its client).
//!
//! # Protocol (stable)
//!
//! `firmware-sim serve --control tcpin:HOST:PORT` listens for any number of clients and prints
//! `control tcpin:HOST:PORT` (the real port) after its `listening` lines. Each request is one
//! line of ASCII words; each gets exactly one reply line, a JSON object, in order:
//!
//! | request | reply |
//! |---|---|
//! | `advance SECONDS` | `{"t_us":N}` once the twin has flown SECONDS more of sim time (rounded to whole 1 ms physics steps) and every frame that became due on the way is queued on its link. Lockstep only. |
//! | `state` | the true state: `{"t_us", "armed", "mode", "system_status", "landed", "position_ned_m": [n, e, d], "altitude_m", "velocity_ned_m_s": [..], "roll_rad", "pitch_rad", "yaw_rad", "rates_frd_rad_s": [p, q, r], "pwm_us": [5]}`, MAVLink's frames: NED, and ArduPilot's fixed-wing body frame for the attitude and rates (nose x, right wing y, belly z; pitch 90° on the tail), as ATTITUDE reports them on the wing |
//! | `param NAME VALUE` | `{"name", "value"}`: the value stored, after the same checks and effects as a PARAM_SET; every GCS link gets its PARAM_VALUE |
//!
//! Anything else, a bad number or a refused value gets `{"error": "why"}`, and the connection
//! stays open. A line longer than [`MAX_LINE`] bytes or one that is not UTF-8 gets an error
//! and the connection is closed.
//!
//! # Determinism
//!
//! Under `--lockstep` sim time moves only on `advance`; stream rates count in sim time, nothing
//! is dropped (a link short of room waits for its reader instead), and frames received between
//! two advances are handled at the sim time standing. So a script that waits for each reply
//! (COMMAND_ACK, PARAM_VALUE) before it advances gets the same telemetry on every run.
//! The in-process form of the channel is [`Harness`], from [`crate::shell::serve::Twin::harness`].

use std::net::SocketAddr;

use serde::Serialize;
use tokio::io::{AsyncBufReadExt, AsyncReadExt, AsyncWriteExt, BufReader};
use tokio::net::{TcpListener, TcpStream};
use tokio::sync::{mpsc, oneshot};
use tokio::task::JoinHandle;
use tokio_util::sync::CancellationToken;

use crate::model::frames::fixed_wing::{self, body_vector};
use crate::model::frames::paper_to_ned;
use crate::model::vehicle::{SystemState, Telemetry};

/// Longest request line accepted, bytes.
pub const MAX_LINE: usize = 1024;

/// Longest single `advance`, s of sim time (a day, like `simulate --duration`).
pub const MAX_ADVANCE_S: f64 = 86_400.0;

/// One request of the harness protocol.
#[derive(Debug, Clone, PartialEq)]
pub enum Request {
    /// Fly this many seconds of sim time (lockstep only).
    Advance {
        /// Sim time to run, s.
        seconds: f64,
    },
    /// The true state.
    State,
    /// Write a parameter.
    Param {
        /// Parameter name (any case).
        name: String,
        /// Requested value.
        value: f64,
    },
}

/// Parses one request line (without its newline).
///
/// # Errors
/// What is wrong with the line, in words for the reply.
pub fn parse_request(line: &str) -> Result<Request, String> {
    let words: Vec<&str> = line.split_ascii_whitespace().collect();
    let number = |w: &str, what: &str| -> Result<f64, String> {
        match w.parse::<f64>() {
            Ok(v) if v.is_finite() => Ok(v),
            _ => Err(format!("{what} must be a finite number, got '{w}'")),
        }
    };
    match words.as_slice() {
        ["advance", s] => {
            let seconds = number(s, "advance SECONDS")?;
            if !(0.0..=MAX_ADVANCE_S).contains(&seconds) {
                return Err(format!(
                    "advance SECONDS must be in [0, {MAX_ADVANCE_S}], got {seconds}"
                ));
            }
            Ok(Request::Advance { seconds })
        }
        ["state"] => Ok(Request::State),
        ["param", name, v] => Ok(Request::Param {
            name: name.to_ascii_uppercase(),
            value: number(v, "param VALUE")?,
        }),
        [] => Err("empty request (advance SECONDS | state | param NAME VALUE)".into()),
        [w, ..] => Err(format!(
            "unknown request '{w}' or wrong arguments (advance SECONDS | state | param NAME VALUE)"
        )),
    }
}

/// The vehicle's true state, in MAVLink's frames (NED position; attitude and rates in the
/// fixed-wing body frame, FRD), as `state` replies.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct TrueState {
    /// Sim time, µs since start.
    pub t_us: u64,
    /// Armed.
    pub armed: bool,
    /// Flight mode name (`QHOVER` …).
    pub mode: &'static str,
    /// The heartbeat's system status name (`STANDBY`, `ACTIVE`, `EMERGENCY` …).
    pub system_status: &'static str,
    /// Weight on the landing gear.
    pub landed: bool,
    /// True position, NED, m.
    pub position_ned_m: [f64; 3],
    /// Height above the ground, m (−down).
    pub altitude_m: f64,
    /// True velocity, NED, m/s.
    pub velocity_ned_m_s: [f64; 3],
    /// True roll, rad.
    pub roll_rad: f64,
    /// True pitch, rad.
    pub pitch_rad: f64,
    /// True yaw, rad.
    pub yaw_rad: f64,
    /// True body rates (roll, pitch, yaw: about the nose, the right wing, the belly), rad/s.
    pub rates_frd_rad_s: [f64; 3],
    /// PWM outputs, µs (ESC 1, ESC 2, left aileron, right aileron, elevator).
    pub pwm_us: [u16; 5],
}

/// `x` with a negative zero made positive (the frame change flips signs of exact zeros).
fn unsigned_zero(x: f64) -> f64 {
    x + 0.0
}

impl TrueState {
    /// The true state in a telemetry snapshot.
    #[must_use]
    pub fn of(t: &Telemetry) -> Self {
        let pos = paper_to_ned(&t.pos_m).map(unsigned_zero);
        let vel = paper_to_ned(&t.vel_m_s).map(unsigned_zero);
        let a = fixed_wing::attitude(&t.euler);
        let [roll, pitch, yaw] = [a.roll_rad, a.pitch_rad, a.yaw_rad].map(unsigned_zero);
        Self {
            t_us: t.t_us,
            armed: t.armed,
            mode: t.mode.name(),
            system_status: match t.state {
                SystemState::Calibrating => "CALIBRATING",
                SystemState::Standby => "STANDBY",
                SystemState::Active => "ACTIVE",
                SystemState::Critical => "CRITICAL",
                SystemState::Emergency => "EMERGENCY",
            },
            landed: t.landed,
            position_ned_m: [pos[0], pos[1], pos[2]],
            altitude_m: t.pos_m.z,
            velocity_ned_m_s: [vel[0], vel[1], vel[2]],
            roll_rad: roll,
            pitch_rad: pitch,
            yaw_rad: yaw,
            rates_frd_rad_s: body_vector(&t.omega_body_rad_s).map(unsigned_zero),
            pwm_us: t.pwm_us,
        }
    }
}

/// The answer to one request.
#[derive(Debug, Clone, PartialEq)]
pub enum Reply {
    /// `advance` done: the sim time now, µs.
    Time(u64),
    /// `state`.
    State(TrueState),
    /// `param`: the stored value.
    Param {
        /// Parameter name as the table spells it.
        name: String,
        /// Value stored.
        value: f64,
    },
    /// Refused, with the reason.
    Error(String),
}

impl Reply {
    /// The reply line (JSON, no newline).
    #[must_use]
    pub fn to_json(&self) -> String {
        let v = match self {
            Self::Time(t_us) => serde_json::json!({ "t_us": t_us }),
            Self::State(s) => serde_json::to_value(s).unwrap_or_default(),
            Self::Param { name, value } => serde_json::json!({ "name": name, "value": value }),
            Self::Error(e) => serde_json::json!({ "error": e }),
        };
        v.to_string()
    }
}

/// Why a harness call failed.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum HarnessError {
    /// The twin refused the request.
    #[error("{0}")]
    Refused(String),
    /// The twin has stopped.
    #[error("the twin has stopped")]
    Stopped,
}

/// A request on its way to the vehicle loop, with where its reply goes.
#[derive(Debug)]
pub(crate) struct Call {
    pub request: Request,
    pub reply: oneshot::Sender<Reply>,
}

/// The in-process harness of a running twin (cheap to clone).
#[derive(Debug, Clone)]
pub struct Harness {
    tx: mpsc::Sender<Call>,
}

impl Harness {
    pub(crate) fn new(tx: mpsc::Sender<Call>) -> Self {
        Self { tx }
    }

    /// Sends one request and waits for its reply.
    ///
    /// # Errors
    /// [`HarnessError::Stopped`] when the twin is gone.
    pub async fn call(&self, request: Request) -> Result<Reply, HarnessError> {
        let (reply, rx) = oneshot::channel();
        self.tx
            .send(Call { request, reply })
            .await
            .map_err(|_| HarnessError::Stopped)?;
        rx.await.map_err(|_| HarnessError::Stopped)
    }

    /// Flies `seconds` of sim time (lockstep only); returns the sim time after, µs.
    ///
    /// # Errors
    /// Refused when the twin is not in lockstep or `seconds` is out of range.
    pub async fn advance(&self, seconds: f64) -> Result<u64, HarnessError> {
        match self.call(Request::Advance { seconds }).await? {
            Reply::Time(t) => Ok(t),
            other => Err(unexpected(other)),
        }
    }

    /// The true state.
    ///
    /// # Errors
    /// [`HarnessError::Stopped`].
    pub async fn state(&self) -> Result<TrueState, HarnessError> {
        match self.call(Request::State).await? {
            Reply::State(s) => Ok(s),
            other => Err(unexpected(other)),
        }
    }

    /// Writes a parameter; returns the value stored.
    ///
    /// # Errors
    /// The refusal (unknown name, out of range …).
    pub async fn set_param(&self, name: &str, value: f64) -> Result<f64, HarnessError> {
        let request = Request::Param {
            name: name.to_ascii_uppercase(),
            value,
        };
        match self.call(request).await? {
            Reply::Param { value, .. } => Ok(value),
            other => Err(unexpected(other)),
        }
    }
}

fn unexpected(reply: Reply) -> HarnessError {
    match reply {
        Reply::Error(e) => HarnessError::Refused(e),
        other => HarnessError::Refused(format!("unexpected reply {}", other.to_json())),
    }
}

/// Binds the control listener at `addr` and serves every client through `harness` until
/// `cancel` fires. Returns the bound address (the real port when 0 was asked).
///
/// # Errors
/// The bind error.
pub(crate) async fn spawn_listener(
    addr: &str,
    harness: Harness,
    cancel: CancellationToken,
) -> std::io::Result<(SocketAddr, JoinHandle<()>)> {
    let listener = TcpListener::bind(addr).await?;
    let local = listener.local_addr()?;
    let task = tokio::spawn(async move {
        loop {
            tokio::select! {
                () = cancel.cancelled() => break,
                accepted = listener.accept() => match accepted {
                    Ok((stream, peer)) => {
                        tracing::debug!(%peer, "control client");
                        tokio::spawn(serve_client(stream, harness.clone(), cancel.clone()));
                    }
                    Err(e) => tracing::warn!("control listener: {e}"),
                },
            }
        }
    });
    Ok((local, task))
}

async fn serve_client(stream: TcpStream, harness: Harness, cancel: CancellationToken) {
    let (rd, mut wr) = stream.into_split();
    let mut rd = BufReader::new(rd);
    let mut line = String::new();
    loop {
        line.clear();
        let mut limited = (&mut rd).take(MAX_LINE as u64 + 1);
        let read = tokio::select! {
            () = cancel.cancelled() => return,
            r = limited.read_line(&mut line) => r,
        };
        let (reply, close) = match read {
            Ok(0) => return,
            Ok(_) if !line.ends_with('\n') && line.len() > MAX_LINE => (
                Reply::Error(format!("request longer than {MAX_LINE} bytes")),
                true,
            ),
            Ok(_) => match parse_request(line.trim_end_matches(['\r', '\n'])) {
                Ok(request) => match harness.call(request).await {
                    Ok(r) => (r, false),
                    Err(e) => (Reply::Error(e.to_string()), true),
                },
                Err(e) => (Reply::Error(e), false),
            },
            Err(e) => (Reply::Error(format!("unreadable request: {e}")), true),
        };
        let mut text = reply.to_json();
        text.push('\n');
        if wr.write_all(text.as_bytes()).await.is_err() || close {
            return;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn requests_parse_and_bad_ones_say_why() {
        assert_eq!(
            parse_request("advance 1.5"),
            Ok(Request::Advance { seconds: 1.5 })
        );
        assert_eq!(parse_request("  state "), Ok(Request::State));
        assert_eq!(
            parse_request("param hover_alt 2"),
            Ok(Request::Param {
                name: "HOVER_ALT".into(),
                value: 2.0
            })
        );
        for (line, says) in [
            ("advance", "unknown request 'advance'"),
            ("advance nan", "finite number"),
            ("advance -1", "[0, 86400]"),
            ("advance 1e9", "[0, 86400]"),
            ("param X", "wrong arguments"),
            ("param X inf", "finite number"),
            ("fly", "unknown request 'fly'"),
            ("", "empty request"),
        ] {
            let e = parse_request(line).expect_err(line);
            assert!(e.contains(says), "{line}: {e}");
        }
    }

    #[test]
    fn replies_are_one_json_object() {
        assert_eq!(Reply::Time(5).to_json(), r#"{"t_us":5}"#);
        assert_eq!(
            Reply::Error("no \"x\"".into()).to_json(),
            r#"{"error":"no \"x\""}"#
        );
        let s = TrueState::of(&Telemetry {
            pos_m: nalgebra::Vector3::new(1.0, 2.0, 3.0),
            ..Telemetry::default()
        });
        let v: serde_json::Value = serde_json::from_str(&Reply::State(s).to_json()).unwrap();
        // Paper frame (x, y, z up) → NED: a half-turn about y, (−x, y, −z).
        assert_eq!(v["position_ned_m"], serde_json::json!([-1.0, 2.0, -3.0]));
        assert_eq!(v["altitude_m"], serde_json::json!(3.0));
        assert_eq!(v["mode"], "QSTABILIZE");
        assert_eq!(v["system_status"], "CALIBRATING");
    }
}
