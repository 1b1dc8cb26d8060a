//! The vehicle's state at a glance, read from the last message of each kind the tracker kept
//! for it: battery (BATTERY_STATUS, else SYS_STATUS), GPS (GPS_RAW_INT), home (HOME_POSITION
//! against LOCAL_POSITION_NED), air or ground (EXTENDED_SYS_STATE), the RC receiver
//! (RC_CHANNELS), sensor health (SYS_STATUS) and the reason for a CRITICAL or EMERGENCY state
//! (the newest urgent STATUSTEXT). Pure: the header, the Flight view, the guarded keys and the
//! status line of `vtol-gcs run` all read the same [`Vitals`].

use vtol_link::dialect::{
    GpsFixType, MavBatteryChargeState, MavLandedState, MavMessage, MavState, MavSysStatusSensor,
};
use vtol_link::protocol::id;

use crate::tracker::state::{VehicleState, VehicleView};

/// How bad something is; the colour follows it.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord)]
pub enum Severity {
    /// Fine.
    Ok,
    /// Needs the operator's attention (low battery, weak fix).
    Warn,
    /// Act now (critical battery, no fix, a failsafe, a crash).
    Bad,
}

/// The flight battery.
#[derive(Debug, Clone, PartialEq)]
pub struct Battery {
    /// Pack voltage, V.
    pub voltage_v: f32,
    /// Remaining charge, %, when the vehicle knows it.
    pub remaining_pct: Option<u8>,
    /// Current drawn, A, when measured.
    pub current_a: Option<f32>,
    /// Flight time left at the present draw, s, when the vehicle estimates it.
    pub time_left_s: Option<u32>,
    /// How urgent the charge is.
    pub severity: Severity,
}

/// Everything the header and the Flight view show about the vehicle's health.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Vitals {
    /// The flight battery, once reported.
    pub battery: Option<Battery>,
    /// GPS fix in words and satellites in view, once reported.
    pub gps: Option<(&'static str, u8, Severity)>,
    /// Horizontal distance (m) and bearing (degrees from North) from home to the vehicle.
    pub home: Option<(f32, f32)>,
    /// In the air (EXTENDED_SYS_STATE says so, or more than 0.5 m above home).
    pub airborne: bool,
    /// Whether an RC receiver gives a throttle (None until RC_CHANNELS is heard).
    pub rc: Option<bool>,
    /// Sensors the vehicle uses that it reports unhealthy, in words.
    pub unhealthy: Vec<&'static str>,
    /// Why the vehicle is CRITICAL or EMERGENCY: its newest urgent message.
    pub reason: Option<String>,
    /// The newest failsafe message while the vehicle is armed.
    pub failsafe: Option<String>,
}

impl Severity {
    /// The worse of two.
    #[must_use]
    pub fn max(self, other: Self) -> Self {
        Ord::max(self, other)
    }
}

fn fix_name(f: GpsFixType) -> (&'static str, Severity) {
    match f {
        GpsFixType::GPS_FIX_TYPE_NO_GPS => ("no GPS", Severity::Bad),
        GpsFixType::GPS_FIX_TYPE_NO_FIX => ("no fix", Severity::Bad),
        GpsFixType::GPS_FIX_TYPE_2D_FIX => ("2D fix", Severity::Warn),
        GpsFixType::GPS_FIX_TYPE_3D_FIX => ("3D fix", Severity::Ok),
        GpsFixType::GPS_FIX_TYPE_DGPS => ("DGPS", Severity::Ok),
        GpsFixType::GPS_FIX_TYPE_RTK_FLOAT => ("RTK float", Severity::Ok),
        GpsFixType::GPS_FIX_TYPE_RTK_FIXED => ("RTK fixed", Severity::Ok),
        GpsFixType::GPS_FIX_TYPE_STATIC => ("static", Severity::Ok),
        GpsFixType::GPS_FIX_TYPE_PPP => ("PPP", Severity::Ok),
    }
}

/// Sensors named as an operator reads them (SYS_STATUS bits).
const SENSOR_NAMES: [(MavSysStatusSensor, &str); 8] = [
    (MavSysStatusSensor::MAV_SYS_STATUS_SENSOR_3D_GYRO, "gyro"),
    (MavSysStatusSensor::MAV_SYS_STATUS_SENSOR_3D_ACCEL, "accel"),
    (MavSysStatusSensor::MAV_SYS_STATUS_SENSOR_3D_MAG, "compass"),
    (MavSysStatusSensor::MAV_SYS_STATUS_SENSOR_GPS, "GPS"),
    (MavSysStatusSensor::MAV_SYS_STATUS_AHRS, "EKF"),
    (
        MavSysStatusSensor::MAV_SYS_STATUS_SENSOR_MOTOR_OUTPUTS,
        "motors",
    ),
    (MavSysStatusSensor::MAV_SYS_STATUS_SENSOR_BATTERY, "battery"),
    (MavSysStatusSensor::MAV_SYS_STATUS_SENSOR_RC_RECEIVER, "RC"),
];

/// Severities up to this one explain a CRITICAL/EMERGENCY state (MAV_SEVERITY_CRITICAL).
const URGENT: u8 = 2;

/// Reads the vitals of `v` from the messages `state` kept for it.
#[must_use]
pub fn vitals(state: &VehicleState, v: &VehicleView) -> Vitals {
    let last = |id: u32| {
        state
            .messages
            .get(&(v.system_id, v.component_id, id))
            .and_then(|s| s.last.decode_lenient().ok().map(|l| l.msg))
    };
    let mut out = Vitals::default();
    if let Some(MavMessage::SYS_STATUS(s)) = last(id::SYS_STATUS) {
        let used = s.onboard_control_sensors_present & s.onboard_control_sensors_enabled;
        out.unhealthy = SENSOR_NAMES
            .iter()
            .filter(|(bit, _)| {
                used.contains(*bit) && !s.onboard_control_sensors_health.contains(*bit)
            })
            .map(|(_, n)| *n)
            .collect();
        // No battery monitor (ArduPilot's BATT_MONITOR 0): 0 mV and an unknown charge, or
        // the "not sent" value; shown as "-", not as an empty pack at 0.0 V.
        let no_monitor =
            s.voltage_battery == u16::MAX || (s.voltage_battery == 0 && s.battery_remaining < 0);
        if !no_monitor {
            let pct = u8::try_from(s.battery_remaining).ok();
            out.battery = Some(Battery {
                voltage_v: f32::from(s.voltage_battery) / 1000.0,
                remaining_pct: pct,
                current_a: (s.current_battery >= 0).then(|| f32::from(s.current_battery) / 100.0),
                time_left_s: None,
                severity: match pct {
                    Some(p) if p < 10 => Severity::Bad,
                    Some(p) if p < 20 => Severity::Warn,
                    _ => Severity::Ok,
                },
            });
        }
    }
    if let Some(MavMessage::BATTERY_STATUS(b)) = last(id::BATTERY_STATUS) {
        let cells: Vec<u16> = b
            .voltages
            .iter()
            .copied()
            .filter(|c| *c != u16::MAX)
            .collect();
        let volts = cells.iter().map(|c| f32::from(*c)).sum::<f32>() / 1000.0;
        let severity = match b.charge_state {
            MavBatteryChargeState::MAV_BATTERY_CHARGE_STATE_LOW => Severity::Warn,
            MavBatteryChargeState::MAV_BATTERY_CHARGE_STATE_CRITICAL
            | MavBatteryChargeState::MAV_BATTERY_CHARGE_STATE_EMERGENCY
            | MavBatteryChargeState::MAV_BATTERY_CHARGE_STATE_FAILED
            | MavBatteryChargeState::MAV_BATTERY_CHARGE_STATE_UNHEALTHY => Severity::Bad,
            _ => Severity::Ok,
        };
        let prev = out.battery.take();
        let no_monitor =
            (cells.is_empty() || volts <= 0.0) && prev.is_none() && b.battery_remaining < 0;
        out.battery = (!no_monitor).then(|| Battery {
            voltage_v: if cells.is_empty() {
                prev.as_ref().map_or(0.0, |p| p.voltage_v)
            } else {
                volts
            },
            remaining_pct: u8::try_from(b.battery_remaining)
                .ok()
                .or(prev.as_ref().and_then(|p| p.remaining_pct)),
            current_a: (b.current_battery >= 0).then(|| f32::from(b.current_battery) / 100.0),
            time_left_s: u32::try_from(b.time_remaining).ok().filter(|t| *t > 0),
            severity: severity.max(prev.map_or(Severity::Ok, |p| p.severity)),
        });
    }
    if let Some(MavMessage::GPS_RAW_INT(g)) = last(id::GPS_RAW_INT) {
        let (name, sev) = fix_name(g.fix_type);
        out.gps = Some((name, g.satellites_visible, sev));
    }
    if let (Some(MavMessage::HOME_POSITION(h)), Some(p)) = (last(id::HOME_POSITION), v.position) {
        let (dn, de) = (p.pos_ned_m[0] - h.x, p.pos_ned_m[1] - h.y);
        let bearing = de.atan2(dn).to_degrees().rem_euclid(360.0);
        // ArduPilot's home has no local position (NaN) until its EKF sets an origin.
        out.home = Some((dn.hypot(de), bearing)).filter(|(d, _)| d.is_finite());
    }
    // Either says so: EXTENDED_SYS_STATE and the armed flag (HEARTBEAT) come at 1 Hz, slower
    // than the position, and a guard must not wait for them while the vehicle climbs.
    let home_down = match last(id::HOME_POSITION) {
        Some(MavMessage::HOME_POSITION(h)) => h.z,
        _ => 0.0,
    };
    let climbed = v
        .position
        .is_some_and(|p| p.pos_ned_m[2] - home_down < -0.5);
    out.airborne = climbed
        || matches!(last(id::EXTENDED_SYS_STATE), Some(MavMessage::EXTENDED_SYS_STATE(e)) if !matches!(
            e.landed_state,
            MavLandedState::MAV_LANDED_STATE_ON_GROUND | MavLandedState::MAV_LANDED_STATE_UNDEFINED
        ));
    if let Some(MavMessage::RC_CHANNELS(r)) = last(id::RC_CHANNELS) {
        out.rc = Some(r.chancount >= 3 && r.chan3_raw != 0 && r.chan3_raw != u16::MAX);
    }
    if matches!(
        v.system_status,
        MavState::MAV_STATE_CRITICAL | MavState::MAV_STATE_EMERGENCY
    ) {
        // The newest urgent text since the vehicle last armed or booted: older ones are
        // about an earlier flight.
        out.reason = v
            .status_texts
            .iter()
            .rev()
            .take_while(|(_, t)| t != "Arming motors" && t != "Rebooted")
            .find(|(sev, _)| *sev <= URGENT)
            .map(|(_, t)| t.clone())
            .or_else(|| {
                out.battery
                    .as_ref()
                    .filter(|b| b.severity == Severity::Bad)
                    .map(|_| "battery critical".to_owned())
            });
    }
    let failsafe = v
        .status_texts
        .iter()
        .rev()
        .find(|(_, t)| is_failsafe(t))
        .map(|(_, t)| t.clone());
    // The vehicle's battery failsafe outranks its charge estimate.
    if let (Some(b), Some(text)) = (out.battery.as_mut(), &failsafe) {
        let lower = text.to_ascii_lowercase();
        if lower.starts_with("battery") {
            let sev = if lower.contains("critical") || lower.contains("terminate") {
                Severity::Bad
            } else {
                Severity::Warn
            };
            b.severity = b.severity.max(sev);
        }
    }
    if v.armed {
        out.failsafe = failsafe;
    }
    out
}

/// A failsafe's STATUSTEXT: ArduPilot's "Battery 1 is low …" or any "failsafe".
fn is_failsafe(text: &str) -> bool {
    let t = text.to_ascii_lowercase();
    t.contains("failsafe")
        || (t.starts_with("battery") && (t.contains(" is low") || t.contains(" is critical")))
}

/// Formats seconds as `m:ss`.
#[must_use]
pub fn mm_ss(s: u32) -> String {
    format!("{}:{:02}", s / 60, s % 60)
}

impl Battery {
    /// `11.4V 62% 5.1A 9:12`: what is known, in that order.
    #[must_use]
    pub fn summary(&self) -> String {
        let mut s = format!("{:.1}V", self.voltage_v);
        if let Some(p) = self.remaining_pct {
            s.push_str(&format!(" {p}%"));
        }
        if let Some(a) = self.current_a {
            s.push_str(&format!(" {a:.1}A"));
        }
        if let Some(t) = self.time_left_s {
            s.push(' ');
            s.push_str(&mm_ss(t));
        }
        s
    }
}

/// What a "crashed" refusal adds: how to recover.
pub const CRASH_RECOVERY: &str =
    "reboot the vehicle to recover: vtol-gcs reboot, or R in the terminal UI";

/// A refusal with the way out added when it is a crash.
#[must_use]
pub fn with_recovery(reason: &str) -> String {
    if reason.to_ascii_lowercase().contains("crash") && !reason.contains("reboot") {
        format!("{reason} ({CRASH_RECOVERY})")
    } else {
        reason.to_owned()
    }
}
