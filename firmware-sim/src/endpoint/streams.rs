//! Telemetry: which messages the twin can produce, how each is built from a [`Telemetry`]
//! snapshot (NED at the wire, attitudes and body axes in ArduPilot's fixed-wing body frame —
//! ATTITUDE's angles in its VTOL view while hovering —, converted here through
//! [`crate::model::frames`]), and the per-link schedule of rates.
//!
//! A message's rate on a link is, in order of precedence: a `SET_MESSAGE_INTERVAL` for that
//! message on that link; the rate of its ArduPlane stream group, set on that link by
//! `REQUEST_DATA_STREAM` or for every link by the `SR0_*` parameters (−1 = not set); the
//! per-message default of [`STREAMABLE`]. A `REQUEST_DATA_STREAM` clears the per-message
//! intervals of its members, as MAVProxy's periodic re-request does on ArduPilot.

use mavlink::dialects::ardupilotmega as apm;
use mavlink::types::CharArray;
use nalgebra::Vector3;

use crate::model::frames::fixed_wing::{self, body_vector};
use crate::model::frames::paper_to_ned;
use crate::model::mode::VtolState;
use crate::model::vehicle::Telemetry;

/// Message ids the twin produces (the dialect's, from vtol-link's table).
pub mod id {
    pub use super::super::readiness::EKF_STATUS_REPORT;
    pub use vtol_link::protocol::id::{
        ATTITUDE, ATTITUDE_QUATERNION, AUTOPILOT_VERSION, BATTERY_STATUS, EXTENDED_SYS_STATE,
        GLOBAL_POSITION_INT, GPS_RAW_INT, HEARTBEAT, HOME_POSITION, LOCAL_POSITION_NED,
        MISSION_CURRENT, NAMED_VALUE_FLOAT, NAV_CONTROLLER_OUTPUT, RAW_IMU, RC_CHANNELS,
        SCALED_IMU, SERVO_OUTPUT_RAW, SYS_STATUS, SYSTEM_TIME, VFR_HUD,
    };
    /// AOA_SSA (ardupilotmega 11020): angle of attack and sideslip.
    pub const AOA_SSA: u32 =
        <mavlink::dialects::ardupilotmega::AOA_SSA_DATA as mavlink::MessageData>::ID;
}

pub use vtol_link::protocol::CONTROLLER_OUTPUT_NAMES;

/// ArduPlane stream groups (`MAV_DATA_STREAM`), as the `SR0_*` parameters name them.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Group {
    /// RAW_SENSORS (1): `SR0_RAW_SENS`.
    RawSensors,
    /// EXTENDED_STATUS (2): `SR0_EXT_STAT`.
    ExtendedStatus,
    /// RC_CHANNELS (3): `SR0_RC_CHAN`.
    RcChannels,
    /// POSITION (6): `SR0_POSITION`.
    Position,
    /// EXTRA1 (10): `SR0_EXTRA1`.
    Extra1,
    /// EXTRA3 (12): `SR0_EXTRA3`.
    Extra3,
    /// EXTRA2 (11): `SR0_EXTRA2`.
    Extra2,
}

impl Group {
    /// Every group, in `GROUP_PARAMS` order.
    pub const ALL: [Self; 7] = [
        Self::RawSensors,
        Self::ExtendedStatus,
        Self::RcChannels,
        Self::Position,
        Self::Extra1,
        Self::Extra3,
        Self::Extra2,
    ];

    /// The group for a `MAV_DATA_STREAM` number (RAW_CONTROLLER has no members).
    #[must_use]
    pub fn from_stream_id(n: u8) -> Option<Self> {
        Some(match n {
            1 => Self::RawSensors,
            2 => Self::ExtendedStatus,
            3 => Self::RcChannels,
            6 => Self::Position,
            10 => Self::Extra1,
            11 => Self::Extra2,
            12 => Self::Extra3,
            _ => return None,
        })
    }

    /// The `SR0_*` parameter.
    #[must_use]
    pub const fn param(self) -> &'static str {
        match self {
            Self::RawSensors => "SR0_RAW_SENS",
            Self::ExtendedStatus => "SR0_EXT_STAT",
            Self::RcChannels => "SR0_RC_CHAN",
            Self::Position => "SR0_POSITION",
            Self::Extra1 => "SR0_EXTRA1",
            Self::Extra3 => "SR0_EXTRA3",
            Self::Extra2 => "SR0_EXTRA2",
        }
    }

    fn index(self) -> usize {
        Self::ALL.iter().position(|g| *g == self).unwrap_or(0)
    }
}

/// A streamable message: id, default rate, group.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct StreamDef {
    /// Message id.
    pub msgid: u32,
    /// Default rate, Hz (0 = off unless requested).
    pub default_hz: f64,
    /// ArduPlane group, if any.
    pub group: Option<Group>,
}

/// Every message the twin streams, with its default rate.
pub const STREAMABLE: [StreamDef; 22] = [
    StreamDef {
        msgid: id::HEARTBEAT,
        default_hz: 1.0,
        group: None,
    },
    StreamDef {
        msgid: id::SYS_STATUS,
        default_hz: 1.0,
        group: Some(Group::ExtendedStatus),
    },
    StreamDef {
        msgid: id::SYSTEM_TIME,
        default_hz: 1.0,
        group: Some(Group::Extra3),
    },
    StreamDef {
        msgid: id::SCALED_IMU,
        default_hz: 2.0,
        group: Some(Group::RawSensors),
    },
    StreamDef {
        msgid: id::RAW_IMU,
        default_hz: 2.0,
        group: Some(Group::RawSensors),
    },
    StreamDef {
        msgid: id::ATTITUDE,
        default_hz: 20.0,
        group: Some(Group::Extra1),
    },
    StreamDef {
        msgid: id::ATTITUDE_QUATERNION,
        default_hz: 0.0,
        group: None,
    },
    StreamDef {
        msgid: id::LOCAL_POSITION_NED,
        default_hz: 10.0,
        group: Some(Group::Position),
    },
    StreamDef {
        msgid: id::SERVO_OUTPUT_RAW,
        default_hz: 10.0,
        group: Some(Group::RcChannels),
    },
    StreamDef {
        msgid: id::RC_CHANNELS,
        default_hz: 4.0,
        group: Some(Group::RcChannels),
    },
    StreamDef {
        msgid: id::EXTENDED_SYS_STATE,
        default_hz: 1.0,
        group: Some(Group::ExtendedStatus),
    },
    // The controller's outputs, at the servo outputs' rate: a tlog then holds Fig 5.
    StreamDef {
        msgid: id::NAMED_VALUE_FLOAT,
        default_hz: 10.0,
        group: Some(Group::Extra1),
    },
    // On the globe and about the flight (`position`, `mission`).
    StreamDef {
        msgid: id::GLOBAL_POSITION_INT,
        default_hz: 10.0,
        group: Some(Group::Position),
    },
    StreamDef {
        msgid: id::GPS_RAW_INT,
        default_hz: 2.0,
        group: Some(Group::ExtendedStatus),
    },
    StreamDef {
        msgid: id::VFR_HUD,
        default_hz: 4.0,
        group: Some(Group::Extra2),
    },
    // Angle of attack and sideslip, in ArduPlane's EXTRA3 group.
    StreamDef {
        msgid: id::AOA_SSA,
        default_hz: 2.0,
        group: Some(Group::Extra3),
    },
    StreamDef {
        msgid: id::BATTERY_STATUS,
        default_hz: 1.0,
        group: Some(Group::Extra3),
    },
    StreamDef {
        msgid: id::MISSION_CURRENT,
        default_hz: 1.0,
        group: Some(Group::ExtendedStatus),
    },
    StreamDef {
        msgid: id::NAV_CONTROLLER_OUTPUT,
        default_hz: 2.0,
        group: Some(Group::ExtendedStatus),
    },
    // While the navigator flies to a target (GUIDED, AUTO, QRTL), as ArduPlane's extended
    // status does.
    StreamDef {
        msgid: super::position::POSITION_TARGET_GLOBAL_INT,
        default_hz: 2.0,
        group: Some(Group::ExtendedStatus),
    },
    // On request and when home moves.
    StreamDef {
        msgid: id::HOME_POSITION,
        default_hz: 0.0,
        group: None,
    },
    StreamDef {
        msgid: id::EKF_STATUS_REPORT,
        default_hz: 1.0,
        group: Some(Group::Extra3),
    },
];

/// The controller's outputs of the last control tick as NAMED_VALUE_FLOAT messages, in the
/// order of [`CONTROLLER_OUTPUT_NAMES`].
#[must_use]
pub fn controller_outputs(t: &Telemetry) -> [apm::MavMessage; 4] {
    let c = &t.control;
    let values = [c.tau_tilde[2], c.tau_tilde[1], c.tau_tilde[0], c.fz_n];
    let ms = time_boot_ms(t);
    std::array::from_fn(|i| {
        apm::MavMessage::NAMED_VALUE_FLOAT(apm::NAMED_VALUE_FLOAT_DATA {
            time_boot_ms: ms,
            value: values[i] as f32,
            name: CharArray::from(CONTROLLER_OUTPUT_NAMES[i]),
        })
    })
}

/// A per-message interval request.
#[derive(Debug, Clone, Copy, PartialEq)]
enum Interval {
    Disabled,
    Every(u64),
}

fn hz_to_interval(hz: f64) -> Interval {
    if hz > 0.0 {
        Interval::Every((1e6 / hz).round() as u64)
    } else {
        Interval::Disabled
    }
}

/// The stream schedule of one link.
#[derive(Debug, Clone)]
pub struct Schedule {
    /// Per-message override from SET_MESSAGE_INTERVAL.
    overrides: [Option<Interval>; STREAMABLE.len()],
    /// Group rates on this link, Hz (None = not set: per-message defaults).
    group_hz: [Option<f64>; Group::ALL.len()],
    next_due_us: [u64; STREAMABLE.len()],
}

impl Schedule {
    /// A schedule with the given `SR0_*` group rates (None = per-message defaults).
    #[must_use]
    pub fn new(group_hz: [Option<f64>; Group::ALL.len()]) -> Self {
        Self {
            overrides: [None; STREAMABLE.len()],
            group_hz,
            next_due_us: [0; STREAMABLE.len()],
        }
    }

    fn slot(msgid: u32) -> Option<usize> {
        STREAMABLE.iter().position(|s| s.msgid == msgid)
    }

    fn effective(&self, k: usize) -> Interval {
        if let Some(i) = self.overrides[k] {
            return i;
        }
        let def = &STREAMABLE[k];
        match def.group.and_then(|g| self.group_hz[g.index()]) {
            Some(hz) => hz_to_interval(hz),
            None => hz_to_interval(def.default_hz),
        }
    }

    /// Current interval of a message on this link: `Some(µs)`, `Some(-1)` when disabled, None
    /// when the twin cannot stream it.
    #[must_use]
    pub fn interval_us(&self, msgid: u32) -> Option<i64> {
        let k = Self::slot(msgid)?;
        Some(match self.effective(k) {
            Interval::Disabled => -1,
            Interval::Every(us) => us as i64,
        })
    }

    /// SET_MESSAGE_INTERVAL semantics: −1 disables, 0 restores the default, > 0 is µs.
    /// Returns false when the message cannot be streamed or the interval is invalid.
    pub fn set_interval(&mut self, msgid: u32, interval_us: f64, now_us: u64) -> bool {
        let Some(k) = Self::slot(msgid) else {
            return false;
        };
        self.overrides[k] = match interval_us {
            -1.0 => Some(Interval::Disabled),
            0.0 => None,
            x if x > 0.0 && x.is_finite() => Some(Interval::Every(x.round().max(1.0) as u64)),
            _ => return false,
        };
        self.next_due_us[k] = now_us;
        true
    }

    /// REQUEST_DATA_STREAM / `SR0_*`: sets a group's rate (None = back to defaults) and clears
    /// the per-message overrides of its members.
    pub fn set_group(&mut self, group: Group, hz: Option<f64>, now_us: u64) {
        self.group_hz[group.index()] = hz;
        for (k, def) in STREAMABLE.iter().enumerate() {
            if def.group == Some(group) {
                self.overrides[k] = None;
                self.next_due_us[k] = now_us;
            }
        }
    }

    /// Message ids due at `now_us`, advancing their next due time.
    pub fn due(&mut self, now_us: u64) -> Vec<u32> {
        let mut out = Vec::new();
        for (k, def) in STREAMABLE.iter().enumerate() {
            let Interval::Every(iv) = self.effective(k) else {
                continue;
            };
            if now_us >= self.next_due_us[k] {
                out.push(def.msgid);
                // Keep the average rate exact; after a gap restart from now instead of bursting.
                // Saturating: an interval of ~1e19 µs (SET_MESSAGE_INTERVAL of 3e38, found by
                // fuzzing) means never again, not a wrap to "due at every tick".
                self.next_due_us[k] = self.next_due_us[k].saturating_add(iv);
                if self.next_due_us[k] <= now_us {
                    self.next_due_us[k] = now_us.saturating_add(iv);
                }
            }
        }
        out
    }
}

/// Whether the twin can build a message on request (REQUEST_MESSAGE).
#[must_use]
pub fn can_produce(msgid: u32) -> bool {
    Schedule::slot(msgid).is_some() || msgid == id::AUTOPILOT_VERSION
}

/// Standard gravity for mG conversions.
const G_M_S2: f64 = 9.80665;

fn time_boot_ms(t: &Telemetry) -> u32 {
    (t.t_us / 1000) as u32
}

fn clamp_i16(v: f64) -> i16 {
    v.round().clamp(f64::from(i16::MIN), f64::from(i16::MAX)) as i16
}

/// Sensor bits SYS_STATUS reports: rate gyros, accelerometer, the external position sensor (also
/// reported as the GPS), the attitude estimator, the control loops, motor outputs, the RC
/// receiver and the battery monitor.
fn sensors() -> apm::MavSysStatusSensor {
    use apm::MavSysStatusSensor as S;
    S::MAV_SYS_STATUS_SENSOR_3D_GYRO
        | S::MAV_SYS_STATUS_SENSOR_3D_ACCEL
        | S::MAV_SYS_STATUS_SENSOR_VISION_POSITION
        | S::MAV_SYS_STATUS_SENSOR_GPS
        | S::MAV_SYS_STATUS_AHRS
        | S::MAV_SYS_STATUS_SENSOR_BATTERY
        | S::MAV_SYS_STATUS_SENSOR_ANGULAR_RATE_CONTROL
        | S::MAV_SYS_STATUS_SENSOR_ATTITUDE_STABILIZATION
        | S::MAV_SYS_STATUS_SENSOR_YAW_POSITION
        | S::MAV_SYS_STATUS_SENSOR_Z_ALTITUDE_CONTROL
        | S::MAV_SYS_STATUS_SENSOR_XY_POSITION_CONTROL
        | S::MAV_SYS_STATUS_SENSOR_MOTOR_OUTPUTS
        | S::MAV_SYS_STATUS_SENSOR_RC_RECEIVER
}

/// Builds a streamable telemetry message (not HEARTBEAT, which needs endpoint state).
// Long: one arm per streamed message, each the message's fields from the telemetry; a table
// read top to bottom, which split would only scatter.
#[must_use]
pub fn build(msgid: u32, t: &Telemetry, errors_comm: u16) -> Option<apm::MavMessage> {
    use apm::MavMessage as M;
    let ms = time_boot_ms(t);
    // ArduPlane reports a tailsitter's rates in its fixed-wing body frame, in every message.
    let [p, q, r] = body_vector(&t.omega_est_rad_s);
    Some(match msgid {
        id::SYS_STATUS => {
            use apm::MavSysStatusSensor as S;
            let present = sensors();
            let mut enabled = present;
            if !t.armed {
                enabled.remove(S::MAV_SYS_STATUS_SENSOR_MOTOR_OUTPUTS);
            }
            // ArduPilot's convention: a bit is healthy unless something is wrong, so the
            // geofence (which the twin does not have) is healthy, not breached.
            let mut health = present | S::MAV_SYS_STATUS_GEOFENCE;
            if t.state == crate::model::vehicle::SystemState::Calibrating {
                // No navigation solution yet: no fix, estimator settling.
                health.remove(S::MAV_SYS_STATUS_SENSOR_GPS | S::MAV_SYS_STATUS_AHRS);
            }
            let b = &t.battery;
            M::SYS_STATUS(apm::SYS_STATUS_DATA {
                onboard_control_sensors_present: present,
                onboard_control_sensors_enabled: enabled,
                onboard_control_sensors_health: health,
                load: 0,
                voltage_battery: (b.voltage_v * 1000.0).round().clamp(0.0, 65534.0) as u16,
                current_battery: (b.current_a * 100.0).round().clamp(0.0, 32767.0) as i16,
                drop_rate_comm: 0,
                errors_comm,
                errors_count1: 0,
                errors_count2: 0,
                errors_count3: 0,
                errors_count4: 0,
                battery_remaining: (b.remaining * 100.0).round().clamp(0.0, 100.0) as i8,
                onboard_control_sensors_present_extended: apm::MavSysStatusSensorExtended::empty(),
                onboard_control_sensors_enabled_extended: apm::MavSysStatusSensorExtended::empty(),
                onboard_control_sensors_health_extended: apm::MavSysStatusSensorExtended::empty(),
            })
        }
        // Unix time is unknown to a deterministic twin: 0 as common.xml allows.
        id::SYSTEM_TIME => M::SYSTEM_TIME(apm::SYSTEM_TIME_DATA {
            time_unix_usec: 0,
            time_boot_ms: ms,
        }),
        id::ATTITUDE => {
            // In ArduPlane's VTOL view while flying as a multicopter (fixed_wing.rs).
            let fw = fixed_wing::attitude(&t.euler_est);
            let a = match t.vtol_state {
                VtolState::Mc | VtolState::TransitionToFw => fixed_wing::vtol_view(&fw),
                VtolState::Fw | VtolState::TransitionToMc => fw,
            };
            M::ATTITUDE(apm::ATTITUDE_DATA {
                time_boot_ms: ms,
                roll: a.roll_rad as f32,
                pitch: a.pitch_rad as f32,
                yaw: a.yaw_rad as f32,
                rollspeed: p as f32,
                pitchspeed: q as f32,
                yawspeed: r as f32,
            })
        }
        id::ATTITUDE_QUATERNION => {
            let qn = fixed_wing::attitude(&t.euler_est).quaternion;
            M::ATTITUDE_QUATERNION(apm::ATTITUDE_QUATERNION_DATA {
                time_boot_ms: ms,
                q1: qn[0] as f32,
                q2: qn[1] as f32,
                q3: qn[2] as f32,
                q4: qn[3] as f32,
                rollspeed: p as f32,
                pitchspeed: q as f32,
                yawspeed: r as f32,
                repr_offset_q: [0.0; 4],
            })
        }
        id::LOCAL_POSITION_NED => {
            let pos = paper_to_ned(&t.pos_m);
            let vel = paper_to_ned(&t.vel_m_s);
            M::LOCAL_POSITION_NED(apm::LOCAL_POSITION_NED_DATA {
                time_boot_ms: ms,
                x: pos[0] as f32,
                y: pos[1] as f32,
                z: pos[2] as f32,
                vx: vel[0] as f32,
                vy: vel[1] as f32,
                vz: vel[2] as f32,
            })
        }
        id::SERVO_OUTPUT_RAW => {
            let s = t.pwm_us;
            M::SERVO_OUTPUT_RAW(apm::SERVO_OUTPUT_RAW_DATA {
                // u32 µs wraps after ~71.6 min, as on ArduPilot.
                time_usec: t.t_us as u32,
                servo1_raw: s[0],
                servo2_raw: s[1],
                servo3_raw: s[2],
                servo4_raw: s[3],
                servo5_raw: s[4],
                ..Default::default()
            })
        }
        id::RC_CHANNELS => {
            let c = t.rc_us;
            M::RC_CHANNELS(apm::RC_CHANNELS_DATA {
                time_boot_ms: ms,
                chan1_raw: c[0],
                chan2_raw: c[1],
                chan3_raw: c[2],
                chan4_raw: c[3],
                chan5_raw: c[4],
                chan6_raw: c[5],
                chan7_raw: c[6],
                chan8_raw: c[7],
                chan9_raw: u16::MAX,
                chan10_raw: u16::MAX,
                chan11_raw: u16::MAX,
                chan12_raw: u16::MAX,
                chan13_raw: u16::MAX,
                chan14_raw: u16::MAX,
                chan15_raw: u16::MAX,
                chan16_raw: u16::MAX,
                chan17_raw: u16::MAX,
                chan18_raw: u16::MAX,
                chancount: 8,
                rssi: u8::MAX,
            })
        }
        id::SCALED_IMU => {
            // Sensor axes are the paper's body axes; the fixed-wing frame at the wire. The
            // ADXL203 has no z_B axis: no axis along the nose, the fixed-wing x.
            let acc = body_vector(&Vector3::new(t.accel_m_s2[0], t.accel_m_s2[1], 0.0));
            let gyro = body_vector(&Vector3::from(t.gyro_rad_s));
            let mg = |a: f64| clamp_i16(a / G_M_S2 * 1000.0);
            let mrad = |w: f64| clamp_i16(w * 1000.0);
            M::SCALED_IMU(apm::SCALED_IMU_DATA {
                time_boot_ms: ms,
                xacc: 0,
                yacc: mg(acc[1]),
                zacc: mg(acc[2]),
                xgyro: mrad(gyro[0]),
                ygyro: mrad(gyro[1]),
                zgyro: mrad(gyro[2]),
                xmag: 0,
                ymag: 0,
                zmag: 0,
                temperature: 2500,
            })
        }
        id::RAW_IMU => {
            // The 12-bit ADC counts as sampled, in sensor axes: gyro x, y, z; accel x, y.
            let c = t.adc_counts.map(|v| v as i16);
            M::RAW_IMU(apm::RAW_IMU_DATA {
                time_usec: t.t_us,
                xacc: c[3],
                yacc: c[4],
                zacc: 0,
                xgyro: c[0],
                ygyro: c[1],
                zgyro: c[2],
                xmag: 0,
                ymag: 0,
                zmag: 0,
                id: 0,
                temperature: 2500,
            })
        }
        id::EXTENDED_SYS_STATE => M::EXTENDED_SYS_STATE(apm::EXTENDED_SYS_STATE_DATA {
            vtol_state: match t.vtol_state {
                VtolState::Mc => apm::MavVtolState::MAV_VTOL_STATE_MC,
                VtolState::TransitionToFw => apm::MavVtolState::MAV_VTOL_STATE_TRANSITION_TO_FW,
                VtolState::Fw => apm::MavVtolState::MAV_VTOL_STATE_FW,
                VtolState::TransitionToMc => apm::MavVtolState::MAV_VTOL_STATE_TRANSITION_TO_MC,
            },
            landed_state: if t.landed {
                apm::MavLandedState::MAV_LANDED_STATE_ON_GROUND
            } else {
                apm::MavLandedState::MAV_LANDED_STATE_IN_AIR
            },
        }),
        id::AOA_SSA => M::AOA_SSA(apm::AOA_SSA_DATA {
            time_usec: t.t_us,
            AOA: t.angle_of_attack_rad().to_degrees() as f32,
            SSA: t.sideslip_rad().to_degrees() as f32,
        }),
        id::AUTOPILOT_VERSION => {
            return Some(super::identity::autopilot_version(vtol_link::SystemId(0)));
        }
        _ => return None,
    })
}

/// A STATUSTEXT (single chunk; text cut to 50 bytes).
#[must_use]
pub fn statustext(severity: apm::MavSeverity, text: &str) -> apm::MavMessage {
    let cut: String = text.chars().take(50).collect();
    apm::MavMessage::STATUSTEXT(apm::STATUSTEXT_DATA {
        severity,
        text: CharArray::from(cut.as_str()),
        id: 0,
        chunk_seq: 0,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn extended_sys_state_carries_the_vtol_state_and_aoa_ssa_the_angles() {
        let t = Telemetry {
            vtol_state: VtolState::TransitionToFw,
            air_velocity_body_m_s: Vector3::new(1.0, -1.0, 10.0),
            ..Telemetry::default()
        };
        let Some(apm::MavMessage::EXTENDED_SYS_STATE(e)) = build(id::EXTENDED_SYS_STATE, &t, 0)
        else {
            panic!("no EXTENDED_SYS_STATE");
        };
        assert_eq!(
            e.vtol_state,
            apm::MavVtolState::MAV_VTOL_STATE_TRANSITION_TO_FW
        );
        let Some(apm::MavMessage::AOA_SSA(a)) = build(id::AOA_SSA, &t, 0) else {
            panic!("no AOA_SSA");
        };
        assert!(
            (f64::from(a.AOA) - 0.1f64.atan().to_degrees()).abs() < 1e-3,
            "{a:?}"
        );
        assert!(a.SSA > 0.0, "moving toward the right wing (-y_B): {a:?}");
        assert!(can_produce(id::AOA_SSA));
    }

    #[test]
    fn default_rates_and_overrides() {
        let mut s = Schedule::new([None; Group::ALL.len()]);
        assert_eq!(s.interval_us(id::ATTITUDE), Some(50_000));
        assert_eq!(s.interval_us(id::ATTITUDE_QUATERNION), Some(-1));
        assert_eq!(s.interval_us(id::AUTOPILOT_VERSION), None);
        assert!(s.set_interval(id::ATTITUDE, 100_000.0, 0));
        assert_eq!(s.interval_us(id::ATTITUDE), Some(100_000));
        s.set_group(Group::Extra1, Some(4.0), 0);
        assert_eq!(
            s.interval_us(id::ATTITUDE),
            Some(250_000),
            "group request clears override"
        );
        assert!(s.set_interval(id::ATTITUDE, -1.0, 0));
        assert_eq!(s.interval_us(id::ATTITUDE), Some(-1));
        assert!(s.set_interval(id::ATTITUDE, 0.0, 0));
        assert_eq!(s.interval_us(id::ATTITUDE), Some(250_000));
        assert!(!s.set_interval(id::ATTITUDE, -5.0, 0));
    }

    #[test]
    fn due_keeps_the_average_rate() {
        let mut s = Schedule::new([None; Group::ALL.len()]);
        let mut count = 0;
        // 10 s in 7 ms ticks: ATTITUDE at 20 Hz gives 200 (± the first one).
        let mut t = 0;
        while t <= 10_000_000 {
            count += s.due(t).iter().filter(|&&m| m == id::ATTITUDE).count();
            t += 7_000;
        }
        assert!((200..=201).contains(&count), "{count}");
    }

    #[test]
    fn an_interval_beyond_the_clock_is_never_due_again() {
        let mut s = Schedule::new([None; Group::ALL.len()]);
        assert!(s.set_interval(id::ATTITUDE, 3.4e38, 5));
        assert!(s.due(5).contains(&id::ATTITUDE));
        for t in [6, 1_000_000, u64::MAX / 2] {
            assert!(!s.due(t).contains(&id::ATTITUDE), "due again at {t}");
        }
    }
}
