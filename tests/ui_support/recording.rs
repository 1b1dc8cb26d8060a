//! Recorded vehicle states for whole-frame UI tests: real MAVLink frames applied to the
//! tracker and the history at fixed times, any number of vehicles, and a frame rendered into
//! ratatui's `TestBackend` at any size.

use std::time::{Duration, Instant};

use ratatui::Terminal;
use ratatui::backend::TestBackend;
use ratatui::crossterm::event::{KeyCode, KeyEvent, KeyModifiers};
use vtol_gcs::links::Side;
use vtol_gcs::tracker::{History, VehicleState};
use vtol_gcs::tui::app::{App, Outcome};
use vtol_gcs::tui::attitude::hover_to_wing;
use vtol_gcs::tui::view::{self, LinkRow, RenderState, RouterCounters, Snapshot, TlogInfo};
use vtol_link::dialect::{self, MavAutopilot, MavMessage, MavModeFlag, MavState, MavType};
use vtol_link::{ComponentId, Frame, LinkId, LinkStatsSnapshot, SystemId};

/// The link every recorded vehicle frame comes on.
pub const VEHICLE_LINK: LinkId = LinkId(1);
/// The link of the daemon's own client, in a recording [`Recording::with_own_traffic`].
pub const OWN_LINK: LinkId = LinkId(2);
/// ArduPlane's mode numbers from QSTABILIZE (17) on are the Q (VTOL) modes.
const Q_MODES_FROM: u32 = 17;

/// The tracker state and history after frames applied at known times.
pub struct Recording {
    /// Time zero.
    pub t0: Instant,
    /// The tracker's state.
    pub state: VehicleState,
    /// The history the charts read.
    pub history: History,
    seq: [u8; 256],
    own_traffic: bool,
}

impl Default for Recording {
    fn default() -> Self {
        Self::new()
    }
}

impl Recording {
    /// Nothing recorded yet.
    #[must_use]
    pub fn new() -> Self {
        let t0 = Instant::now();
        Self {
            t0,
            state: VehicleState::new(t0),
            history: History::new(t0),
            seq: [0; 256],
            own_traffic: false,
        }
    }

    /// Nothing recorded yet; [`Recording::fly`] also records the daemon's own client's 1 Hz
    /// heartbeat on [`OWN_LINK`].
    #[must_use]
    pub fn with_own_traffic() -> Self {
        Self {
            own_traffic: true,
            ..Self::new()
        }
    }

    /// `ms` after time zero.
    #[must_use]
    pub fn at(&self, ms: u64) -> Instant {
        self.t0 + Duration::from_millis(ms)
    }

    /// Applies `msg` from vehicle `sys` (component 1) at `ms`.
    pub fn feed_from(&mut self, sys: u8, ms: u64, msg: &MavMessage) {
        let seq = &mut self.seq[usize::from(sys)];
        let frame = Frame::encode_v2(SystemId(sys), ComponentId(1), *seq, msg);
        *seq = seq.wrapping_add(1);
        let now = self.at(ms);
        let decoded = self.state.apply(VEHICLE_LINK, Side::Vehicle, &frame, now);
        self.history.record(&frame, decoded.as_ref(), now);
    }

    /// Applies a frame built by hand (a payload the typed encoder cannot express) at `ms`.
    pub fn feed_frame(&mut self, ms: u64, frame: &Frame) {
        let now = self.at(ms);
        let decoded = self.state.apply(VEHICLE_LINK, Side::Vehicle, frame, now);
        self.history.record(frame, decoded.as_ref(), now);
    }

    /// Applies `msg` from vehicle 1 at `ms`.
    pub fn feed(&mut self, ms: u64, msg: &MavMessage) {
        self.feed_from(1, ms, msg);
    }

    /// Applies the daemon's own client's heartbeat (255, 190) at `ms`, on [`OWN_LINK`].
    pub fn feed_gcs(&mut self, ms: u64) {
        let frame = Frame::encode_v2(
            SystemId(255),
            ComponentId(190),
            (ms / 1000) as u8,
            &vtol_link::gcs_heartbeat(),
        );
        let now = self.at(ms);
        let decoded = self.state.apply(OWN_LINK, Side::Client, &frame, now);
        self.history.record(&frame, decoded.as_ref(), now);
    }

    /// Vehicle 1 armed in QHOVER for the first 20 s, rocking slightly in roll and pitch at
    /// 1 m.
    pub fn fly_hover(&mut self) {
        self.fly(0, 20_000, |t| {
            let wobble = (t * 2.0).sin() as f32;
            (18, true, 0.05 * wobble, -0.03 * wobble, 0.3, 1.0)
        });
    }

    /// Vehicle 1 from `from_ms` to `to_ms`: 1 Hz heartbeat, 50 Hz attitude, 10 Hz outputs and
    /// position, from a function of time giving (mode, armed, roll, pitch, yaw, altitude) with
    /// the attitude in the tailsitter's hover frame (upright is level), reported as ArduPlane
    /// reports it: ATTITUDE in its VTOL view (the hover frame) in a Q mode, in the wing frame
    /// otherwise; the body rates in the wing frame.
    pub fn fly(
        &mut self,
        from_ms: u64,
        to_ms: u64,
        f: impl Fn(f64) -> (u32, bool, f32, f32, f32, f32),
    ) {
        self.fly_frames(from_ms, to_ms, |t| {
            let (mode, armed, roll, pitch, yaw, alt) = f(t);
            let [r, p, y] = [roll, pitch, yaw].map(f64::from);
            let (r, p, y) = if mode >= Q_MODES_FROM {
                (r, p, y)
            } else {
                hover_to_wing(nalgebra::UnitQuaternion::from_euler_angles(r, p, y)).euler_angles()
            };
            // Hover rates (0.01, −0.02, 0) about the wing's axes: (−r, q, p).
            let rates = [0.0, -0.02, 0.01];
            (
                mode,
                armed,
                [r as f32, p as f32, y as f32],
                rates,
                roll,
                alt,
            )
        });
    }

    /// As [`Recording::fly`] with the attitude given in the wing frame, as reported.
    pub fn fly_wing(
        &mut self,
        from_ms: u64,
        to_ms: u64,
        f: impl Fn(f64) -> (u32, bool, f32, f32, f32, f32),
    ) {
        self.fly_frames(from_ms, to_ms, |t| {
            let (mode, armed, roll, pitch, yaw, alt) = f(t);
            (
                mode,
                armed,
                [roll, pitch, yaw],
                [0.01, -0.02, 0.0],
                roll,
                alt,
            )
        });
    }

    /// The frames of [`Recording::fly`]: (mode, armed, reported roll/pitch/yaw, reported body
    /// rates, the roll the ailerons answer, altitude).
    #[allow(clippy::type_complexity)]
    fn fly_frames(
        &mut self,
        from_ms: u64,
        to_ms: u64,
        f: impl Fn(f64) -> (u32, bool, [f32; 3], [f32; 3], f32, f32),
    ) {
        let mut ms = from_ms;
        while ms < to_ms {
            let (mode, armed, [roll, pitch, yaw], rates, surface_roll, alt) = f(ms as f64 / 1000.0);
            if ms.is_multiple_of(1000) {
                self.feed(ms, &heartbeat(mode, armed));
                if self.own_traffic {
                    self.feed_gcs(ms);
                }
            }
            self.feed(
                ms,
                &MavMessage::ATTITUDE(dialect::ATTITUDE_DATA {
                    time_boot_ms: ms as u32,
                    roll,
                    pitch,
                    yaw,
                    rollspeed: rates[0],
                    pitchspeed: rates[1],
                    yawspeed: rates[2],
                }),
            );
            if ms.is_multiple_of(100) {
                let esc = if armed {
                    1450 + (alt * 40.0) as u16
                } else {
                    1000
                };
                self.feed(
                    ms,
                    &MavMessage::SERVO_OUTPUT_RAW(dialect::SERVO_OUTPUT_RAW_DATA {
                        servo1_raw: esc + 12,
                        servo2_raw: esc - 12,
                        servo3_raw: 1500 + (surface_roll * 500.0) as u16,
                        servo4_raw: 1500 - (surface_roll * 500.0) as u16,
                        servo5_raw: 1520,
                        ..Default::default()
                    }),
                );
                self.feed(
                    ms,
                    &MavMessage::LOCAL_POSITION_NED(dialect::LOCAL_POSITION_NED_DATA {
                        time_boot_ms: ms as u32,
                        x: 0.05,
                        y: -0.02,
                        z: -alt,
                        ..Default::default()
                    }),
                );
            }
            ms += 20;
        }
    }

    /// A STATUSTEXT from vehicle 1.
    pub fn status(&mut self, ms: u64, severity: dialect::MavSeverity, text: &str) {
        let mut data = dialect::STATUSTEXT_DATA {
            severity,
            ..Default::default()
        };
        data.text = text.into();
        self.feed(ms, &MavMessage::STATUSTEXT(data));
    }

    /// Renders one whole frame at `at_ms` on a `size` terminal.
    pub fn render(&self, app: &mut App, at_ms: u64, size: (u16, u16)) -> String {
        let vehicle = self.state.links.get(&VEHICLE_LINK);
        let links = vec![LinkRow {
            id: VEHICLE_LINK,
            side: Side::Vehicle,
            peer: "tcp:127.0.0.1:5760".into(),
            own: false,
            policy: None,
            stats: LinkStatsSnapshot {
                rx_frames: vehicle.map_or(0, |h| h.frames),
                ..Default::default()
            },
        }];
        let snap = Snapshot {
            now: self.at(at_ms),
            state: &self.state,
            history: &self.history,
            links,
            router: RouterCounters {
                frames_in: 1234,
                frames_out: 1200,
                ..Default::default()
            },
            tlog: Some(TlogInfo {
                path: "logs/2026-11-23T11-00-00.tlog".into(),
                bytes: 123_456,
                records: 2345,
                ..Default::default()
            }),
            serving: vec!["tcpin:127.0.0.1:5770".into()],
        };
        draw_snapshot(app, &snap, size)
    }
}

/// One whole frame of `snap` drawn by `app` on a `size` terminal, as text: the app observes the
/// snapshot first, as the UI's event loop does before each frame.
#[must_use]
pub fn draw_snapshot(app: &mut App, snap: &Snapshot, size: (u16, u16)) -> String {
    let mut terminal = Terminal::new(TestBackend::new(size.0, size.1)).expect("test backend");
    let mut render = RenderState::default();
    vtol_gcs::tui::observe(app, snap);
    terminal
        .draw(|f| view::draw(f, app, &mut render, snap))
        .expect("draw");
    format!("{}", terminal.backend())
}

/// A tailsitter's heartbeat in ArduPlane mode `mode`, from an ArduPilot autopilot: active when
/// armed, standing by otherwise.
#[must_use]
pub fn heartbeat(mode: u32, armed: bool) -> MavMessage {
    let status = if armed {
        MavState::MAV_STATE_ACTIVE
    } else {
        MavState::MAV_STATE_STANDBY
    };
    tailsitter_heartbeat(
        mode,
        armed,
        MavAutopilot::MAV_AUTOPILOT_ARDUPILOTMEGA,
        status,
    )
}

/// A tailsitter's heartbeat in ArduPlane mode `mode` from `autopilot` in state `status`.
#[must_use]
pub fn tailsitter_heartbeat(
    mode: u32,
    armed: bool,
    autopilot: MavAutopilot,
    system_status: MavState,
) -> MavMessage {
    let mut base_mode = MavModeFlag::MAV_MODE_FLAG_CUSTOM_MODE_ENABLED;
    if armed {
        base_mode |= MavModeFlag::MAV_MODE_FLAG_SAFETY_ARMED;
    }
    MavMessage::HEARTBEAT(dialect::HEARTBEAT_DATA {
        custom_mode: mode,
        mavtype: MavType::MAV_TYPE_VTOL_TAILSITTER_DUOROTOR,
        autopilot,
        base_mode,
        system_status,
        mavlink_version: 3,
    })
}

/// The part of the twin's parameter table every view test shows.
const TWIN_PARAMS: [(&str, f32); 9] = [
    ("HOVER_ALT", 1.0),
    ("LAT_SAT_A", 1.2),
    ("LAT_SAT_B", 0.6),
    ("SERVO1_FUNCTION", 74.0),
    ("SERVO2_FUNCTION", 73.0),
    ("SERVO3_FUNCTION", 4.0),
    ("SERVO4_FUNCTION", 4.0),
    ("SERVO5_FUNCTION", 19.0),
    ("SIM_PUSH_ROLL", 0.0),
];

/// [`TWIN_PARAMS`] and `more`, in name order.
#[must_use]
pub fn params_with(more: &[(&str, f32)]) -> Vec<(String, f32)> {
    let mut table: Vec<(String, f32)> = TWIN_PARAMS
        .iter()
        .chain(more)
        .map(|&(n, v)| (n.to_owned(), v))
        .collect();
    table.sort_by(|a, b| a.0.cmp(&b.0));
    table
}

/// The twin's parameter table, as far as the views use it.
#[must_use]
pub fn params() -> Vec<(String, f32)> {
    params_with(&[("ARSPD_FBW_MIN", 10.0)])
}

/// A UI that has `table`.
#[must_use]
pub fn app_with(table: Vec<(String, f32)>) -> App {
    let mut app = App::default();
    app.on_outcome(Outcome::Params(table));
    app
}

/// A UI that has the table.
#[must_use]
pub fn app_with_params() -> App {
    app_with(params())
}

/// A key without modifiers.
#[must_use]
pub fn key(c: KeyCode) -> KeyEvent {
    KeyEvent::new(c, KeyModifiers::NONE)
}

/// A hover of 20 s in QHOVER with two texts.
#[must_use]
pub fn hover() -> Recording {
    let mut rec = Recording::new();
    rec.fly_hover();
    rec.status(
        19_990,
        dialect::MavSeverity::MAV_SEVERITY_INFO,
        "Mode QHOVER",
    );
    rec
}
