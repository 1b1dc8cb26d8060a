//! The onboard parameter table: names, types, units, ranges, defaults, the constraints between
//! parameters, and persistence in the `.parm` text format (`PROTOCOL.md` D.3).
//!
//! The table is fixed: [`TABLE`] has a constant order and count, and a parameter's index is its
//! position, because the MAVLink parameter protocol requires an invariant set (`PROTOCOL.md`
//! A.3). Names are upper case and at most 16 characters. Integer parameters are stored as the
//! C-cast of the float the GCS sent (rounded, then range-checked), which is the ArduPilot
//! convention the endpoint advertises.
//!
//! A write is refused, leaving the stored value unchanged, when the value is NaN or infinite,
//! outside the parameter's range, aimed at a read-only parameter, or when the resulting gain set
//! breaks the paper's saturation conditions a > b + c + d, b > c + d, c > d > 0
//! ([`Gains::validate`]).
//!
//! Perturbations (ArduPilot SITL style): writing a non-zero `SIM_PUSH_ROLL`/`PITCH`/`YAW` (N·m,
//! about the hover frame's FRD body axes, as a pilot behind the hovering vehicle sees them)
//! applies that torque for `SIM_PUSH_MS`, like the pushes of the paper's experiments
//! (Figs 8–10); the parameter then resets itself to 0 and is never saved. `SIM_WIND_SPD`/`SIM_WIND_DIR` (direction the wind comes from) set a steady wind and
//! `SIM_WIND_TURB` the gust intensity.
//!
//! Servo outputs (the `SERVOn_FUNCTION` values use ArduPilot's `SRV_Channel` function numbers):
//! SERVO1 = ESC of rotor 1, the right rotor (`ThrottleRight`, 74), SERVO2 = ESC of rotor 2, the
//! left rotor (`ThrottleLeft`, 73) — right and left as `frames` defines them for FRD —
//! SERVO3 = left aileron and SERVO4 = right aileron (both `Aileron`, 4, as ArduPilot does for a
//! pair of ailerons; left and right are told apart by the output number), SERVO5 = elevator
//! (`Elevator`, 19). The mixer is fixed, so these are read-only.

use std::collections::BTreeMap;
use std::fmt::Write as _;
use std::path::{Path, PathBuf};

use crate::model::control::forward_gains::ForwardGains;
use crate::model::control::position::{HoverHoldGains, HoverLaw};
use crate::model::control::tecs::TecsLimits;
use crate::model::control::{GainError, Gains, SaturationLevels};
use vtol_link::text_file::TextFileError;

/// How a parameter is stored and sent (`MAV_PARAM_TYPE`).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ParamType {
    /// 32-bit float (`MAV_PARAM_TYPE_REAL32`, 9).
    Real32,
    /// Signed 8-bit integer (`MAV_PARAM_TYPE_INT8`, 2).
    Int8,
    /// Signed 16-bit integer (`MAV_PARAM_TYPE_INT16`, 4).
    Int16,
    /// Signed 32-bit integer (`MAV_PARAM_TYPE_INT32`, 6).
    Int32,
}

impl ParamType {
    /// The `MAV_PARAM_TYPE` number.
    #[must_use]
    pub const fn mav_type(self) -> u8 {
        match self {
            Self::Real32 => 9,
            Self::Int8 => 2,
            Self::Int16 => 4,
            Self::Int32 => 6,
        }
    }

    /// Whether values are integers.
    #[must_use]
    pub const fn is_integer(self) -> bool {
        !matches!(self, Self::Real32)
    }

    /// The C cast of a value to this type, as ArduPilot stores a PARAM_SET value: integers are
    /// rounded to nearest. Floats are kept as given (a value from the wire is already an f32;
    /// one from a `.parm` file keeps its decimal meaning) and go out as f32.
    #[must_use]
    pub fn cast(self, value: f64) -> f64 {
        match self {
            Self::Real32 => value,
            _ => value.round(),
        }
    }
}

/// Who may change a parameter, and whether it is saved.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Access {
    /// Writable and persisted.
    ReadWrite,
    /// Fixed by the firmware; writes are refused.
    ReadOnly,
    /// Writable but never persisted: a one-shot trigger (the `SIM_PUSH_*` perturbations).
    Volatile,
}

/// One entry of the table.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ParamDef {
    /// Parameter id: upper case, ≤ 16 characters.
    pub name: &'static str,
    /// Storage type.
    pub ty: ParamType,
    /// Unit, for documentation and GCS display.
    pub unit: &'static str,
    /// Smallest accepted value.
    pub min: f64,
    /// Largest accepted value.
    pub max: f64,
    /// Value at first start (no parameter file).
    pub default: f64,
    /// Who may write it.
    pub access: Access,
    /// One line on what it does.
    pub description: &'static str,
}

const fn def(
    name: &'static str,
    ty: ParamType,
    unit: &'static str,
    (min, max): (f64, f64),
    default: f64,
    access: Access,
    description: &'static str,
) -> ParamDef {
    ParamDef {
        name,
        ty,
        unit,
        min,
        max,
        default,
        access,
        description,
    }
}

use Access::{ReadOnly as RO, ReadWrite as RW, Volatile as VOL};
use ParamType::{Int8 as I8, Int16 as I16, Int32 as I32, Real32 as F32};

/// Longest accepted parameter id (the MAVLink `param_id` field).
pub const MAX_NAME_LEN: usize = 16;

/// Version of the table layout; bumped when a parameter changes meaning.
pub const FORMAT_VERSION: f64 = 1.0;

/// The parameter table, in its fixed wire order.
// One parameter per line reads as a table; rustfmt would spread each over nine lines.
#[rustfmt::skip]
pub static TABLE: &[ParamDef] = &[
    def("FORMAT_VERSION", I16, "", (0.0, 32767.0), FORMAT_VERSION, RO, "Parameter table layout version"),
    def("SYSID_THISMAV", I16, "", (1.0, 255.0), 1.0, RW, "MAVLink system id of the twin (after restart; --sysid overrides)"),
    def("SYSID_MYGCS", I16, "", (1.0, 255.0), 255.0, RW, "System id whose manual input and heartbeats are trusted"),
    def("FS_GCS_ENABL", I8, "", (0.0, 1.0), 0.0, RW, "GCS heartbeat-loss failsafe: 0 off, 1 switch to QLAND"),
    def("FS_GCS_TIMEOUT", F32, "s", (1.0, 120.0), 5.0, RW, "GCS heartbeat silence before the failsafe triggers"),
    def("CTRL_RATE_HZ", I16, "Hz", (10.0, 1000.0), 100.0, RW, "Control loop rate (after restart)"),
    def("LAT_SAT_A", F32, "rad/s/s", (0.0, 20.0), 1.2, RW, "Lateral (y-phi) saturation level a; a > b + c + d"),
    def("LAT_SAT_B", F32, "rad/s/s", (0.0, 20.0), 0.6, RW, "Lateral saturation level b; b > c + d"),
    def("LAT_SAT_C", F32, "rad/s/s", (0.0, 20.0), 0.22, RW, "Lateral saturation level c; c > d"),
    def("LAT_SAT_D", F32, "rad/s/s", (0.0, 20.0), 0.18, RW, "Lateral saturation level d; d > 0"),
    def("LON_SAT_A", F32, "rad/s/s", (0.0, 20.0), 1.2, RW, "Longitudinal (x-theta) saturation level a; a > b + c + d"),
    def("LON_SAT_B", F32, "rad/s/s", (0.0, 20.0), 0.6, RW, "Longitudinal saturation level b; b > c + d"),
    def("LON_SAT_C", F32, "rad/s/s", (0.0, 20.0), 0.22, RW, "Longitudinal saturation level c; c > d"),
    def("LON_SAT_D", F32, "rad/s/s", (0.0, 20.0), 0.18, RW, "Longitudinal saturation level d; d > 0"),
    def("ALT_KD", F32, "1/s", (0.0, 50.0), 2.0, RW, "Altitude law (37) damping a_z1"),
    def("ALT_KP", F32, "1/s/s", (0.0, 100.0), 5.0, RW, "Altitude law (37) stiffness a_z2"),
    def("YAW_KD", F32, "1/s", (0.0, 50.0), 5.0, RW, "Yaw law (45) damping a_psi1"),
    def("YAW_KP", F32, "1/s/s", (0.0, 100.0), 5.0, RW, "Yaw law (45) stiffness a_psi2"),
    def("HOVER_ALT", F32, "m", (0.0, 50.0), 1.0, RW, "Altitude setpoint z_d in QHOVER and QLOITER"),
    def("LAND_SPEED", F32, "m/s", (0.0, 5.0), 0.5, RW, "Descent speed in QLAND"),
    def("Q_PILOT_SPEED_UP", F32, "cm/s", (50.0, 500.0), 250.0, RW, "Fastest climb of the Q modes' altitude hold (physical model)"),
    def("Q_PILOT_SPEED_DN", F32, "cm/s", (0.0, 500.0), 0.0, RW, "Fastest descent of the Q modes' altitude hold; 0 = Q_PILOT_SPEED_UP (physical model)"),
    def("SR0_RAW_SENS", I16, "Hz", (-1.0, 50.0), -1.0, RW, "RAW_IMU, SCALED_IMU rate; -1 = per-message default"),
    def("SR0_EXT_STAT", I16, "Hz", (-1.0, 50.0), -1.0, RW, "SYS_STATUS, EXTENDED_SYS_STATE rate; -1 = default"),
    def("SR0_RC_CHAN", I16, "Hz", (-1.0, 50.0), -1.0, RW, "SERVO_OUTPUT_RAW, RC_CHANNELS rate; -1 = default"),
    def("SR0_POSITION", I16, "Hz", (-1.0, 50.0), -1.0, RW, "LOCAL_POSITION_NED rate; -1 = default"),
    def("SR0_EXTRA1", I16, "Hz", (-1.0, 50.0), -1.0, RW, "ATTITUDE rate; -1 = default"),
    def("SR0_EXTRA3", I16, "Hz", (-1.0, 50.0), -1.0, RW, "SYSTEM_TIME rate; -1 = default"),
    def("SERVO1_FUNCTION", I16, "", (0.0, 200.0), 74.0, RO, "SERVO1 = ESC of rotor 1, the right rotor (ThrottleRight)"),
    def("SERVO2_FUNCTION", I16, "", (0.0, 200.0), 73.0, RO, "SERVO2 = ESC of rotor 2, the left rotor (ThrottleLeft)"),
    def("SERVO3_FUNCTION", I16, "", (0.0, 200.0), 4.0, RO, "SERVO3 = left aileron (Aileron)"),
    def("SERVO4_FUNCTION", I16, "", (0.0, 200.0), 4.0, RO, "SERVO4 = right aileron (Aileron)"),
    def("SERVO5_FUNCTION", I16, "", (0.0, 200.0), 19.0, RO, "SERVO5 = elevator (Elevator)"),
    def("SIM_PUSH_ROLL", F32, "N.m", (-2.0, 2.0), 0.0, VOL, "Non-zero: push about the hover FRD roll axis for SIM_PUSH_MS"),
    def("SIM_PUSH_PITCH", F32, "N.m", (-2.0, 2.0), 0.0, VOL, "Non-zero: push about the hover FRD pitch axis for SIM_PUSH_MS"),
    def("SIM_PUSH_YAW", F32, "N.m", (-2.0, 2.0), 0.0, VOL, "Non-zero: push about the hover FRD yaw axis for SIM_PUSH_MS"),
    def("SIM_PUSH_MS", I16, "ms", (1.0, 10000.0), 200.0, RW, "Duration of a SIM_PUSH_* push"),
    def("SIM_WIND_SPD", F32, "m/s", (0.0, 30.0), 0.0, RW, "Steady wind speed"),
    def("SIM_WIND_DIR", F32, "deg", (0.0, 360.0), 0.0, RW, "Direction the wind blows from (0 = north)"),
    def("SIM_WIND_TURB", F32, "m/s", (0.0, 10.0), 0.0, RW, "Gust intensity (standard deviation)"),
    def("SR0_EXTRA2", I16, "Hz", (-1.0, 50.0), -1.0, RW, "VFR_HUD rate; -1 = default"),
    def("SIM_HOME_LAT", F32, "deg", (-90.0, 90.0), -35.363_261, RW, "Latitude of the motion-capture origin (after restart)"),
    def("SIM_HOME_LON", F32, "deg", (-180.0, 180.0), 149.165_230, RW, "Longitude of the motion-capture origin (after restart)"),
    def("SIM_HOME_ALT", F32, "m", (-500.0, 9000.0), 584.0, RW, "Ground altitude above mean sea level at the origin (after restart)"),
    def("WP_RADIUS", I16, "m", (0.0, 32767.0), 90.0, RW, "On the wing a waypoint is reached within this (at most the L1 distance; an item's param2 overrides)"),
    def("WP_SPEED_UP", F32, "m/s", (0.1, 5.0), 1.0, RW, "Climb rate of take-offs and altitude changes in GUIDED, AUTO, QRTL"),
    def("WP_SPEED_DN", F32, "m/s", (0.1, 5.0), 0.5, RW, "Descent rate of altitude changes in GUIDED, AUTO, QRTL"),
    def("NAV_RADIUS_MAX", F32, "m", (1.0, 10000.0), 3000.0, RW, "Targets farther from home are refused"),
    def("NAV_ALT_MAX", F32, "m", (1.0, 1000.0), 100.0, RW, "Targets higher above home are refused"),
    def("BATT_CAPACITY", I32, "mAh", (100.0, 100_000.0), 1300.0, RW, "Battery capacity (after restart)"),
    def("SIM_BATT_VOLTAGE", F32, "V", (1.0, 60.0), 12.6, RW, "Voltage of the full battery at rest (after restart)"),
    def("BATT_LOW_VOLT", F32, "V", (0.0, 60.0), 10.5, RW, "Low battery below this voltage for BATT_LOW_TIMER; 0 = off"),
    def("BATT_CRT_VOLT", F32, "V", (0.0, 60.0), 0.0, RW, "Critical battery below this voltage for BATT_LOW_TIMER; 0 = off"),
    def("BATT_LOW_MAH", F32, "mAh", (0.0, 100_000.0), 0.0, RW, "Low battery below this remaining capacity; 0 = off"),
    def("BATT_CRT_MAH", F32, "mAh", (0.0, 100_000.0), 0.0, RW, "Critical battery below this remaining capacity; 0 = off"),
    def("BATT_LOW_TIMER", I8, "s", (0.0, 120.0), 10.0, RW, "Seconds the voltage must stay low before the failsafe"),
    def("BATT_FS_LOW_ACT", I8, "", (0.0, 6.0), 0.0, RW, "Low battery action: 0 none, 1 RTL, 2 Land, 3 Terminate, 4 QLand, 6 Loiter to QLand"),
    def("BATT_FS_CRT_ACT", I8, "", (0.0, 6.0), 0.0, RW, "Critical battery action: as BATT_FS_LOW_ACT"),
    def("ARMING_CHECK", I32, "", (0.0, 1.0), 1.0, RO, "Pre-arm checks (calibration, crash, mode, landed, level): 1 = all, always on"),
    def("ARSPD_FBW_MIN", I16, "m/s", (1.0, 50.0), 10.0, RW, "Lowest fixed-wing airspeed; the forward transition ends here; above the stall speed"),
    def("ARSPD_FBW_MAX", I16, "m/s", (2.0, 60.0), 18.0, RW, "Highest airspeed demanded; above TRIM_ARSPD_CM"),
    def("TRIM_ARSPD_CM", I32, "cm/s", (100.0, 5000.0), 1200.0, RW, "Cruise airspeed; between ARSPD_FBW_MIN and ARSPD_FBW_MAX"),
    def("TECS_TIME_CONST", F32, "s", (0.5, 20.0), 3.0, RW, "Time constant of the height and airspeed demands"),
    def("TECS_CLMB_MAX", F32, "m/s", (0.1, 10.0), 3.0, RW, "Largest climb rate in forward flight"),
    def("TECS_SINK_MAX", F32, "m/s", (0.1, 10.0), 3.0, RW, "Largest sink rate in forward flight"),
    def("LIM_ROLL_CD", I16, "cdeg", (100.0, 6500.0), 4500.0, RW, "Largest bank in forward flight"),
    def("Q_TAILSIT_RAT_FW", F32, "deg/s", (5.0, 500.0), 50.0, RW, "Nose-down rate of the forward transition"),
    def("Q_TAILSIT_RAT_VT", F32, "deg/s", (5.0, 500.0), 50.0, RW, "Nose-up rate of the back transition"),
    def("Q_TAILSIT_ANGLE", I8, "deg", (5.0, 80.0), 45.0, RW, "Nose angle from vertical before a forward transition may end"),
    def("Q_TAILSIT_ANG_VT", I8, "deg", (5.0, 89.0), 75.0, RW, "Nose angle above the horizon that ends a back transition"),
    def("Q_TRANSITION_MS", I16, "ms", (500.0, 30000.0), 8000.0, RW, "A forward transition not done by then is aborted to QLOITER"),
    def("FW_ATT_BW", F32, "rad/s", (0.5, 20.0), 5.0, RW, "Bandwidth of the forward-flight attitude law"),
    def("NAVL1_PERIOD", F32, "s", (1.0, 60.0), 10.0, RW, "Period of the L1 track guidance of the fixed-wing legs"),
    def("NAVL1_DAMPING", F32, "", (0.6, 1.0), 0.75, RW, "Damping of the L1 track guidance"),
    def("Q_RTL_MODE", I8, "", (0.0, 3.0), 0.0, RW, "RTL: 0 circles home on the wing, 1 and 2 switch to QRTL within RTL_RADIUS of home, 3 is QRTL always"),
    def("WP_LOITER_RAD", I16, "m", (1.0, 32767.0), 60.0, RW, "Radius of the fixed-wing loiter circles (NAV_LOITER_TIME, RTL, GUIDED)"),
    def("HOV_POS_LAW", I8, "", (0.0, 1.0), 1.0, RW, "Position modes, physical model: 0 the paper's chains, 1 the cascade with wind estimate"),
    def("Q_P_POSXY_P", F32, "1/s", (0.1, 5.0), 0.6, RW, "Hover hold: position to velocity gain"),
    def("Q_P_VELXY_P", F32, "1/s", (0.1, 10.0), 2.0, RW, "Hover hold: velocity to acceleration gain; <= HOV_ATT_BW / 2"),
    def("Q_P_VELXY_I", F32, "1/s/s", (0.0, 10.0), 0.4, RW, "Hover hold: velocity integral gain (the wind estimate)"),
    def("Q_P_VELXY_IMAX", F32, "cm/s/s", (0.0, 1000.0), 600.0, RW, "Hover hold: largest wind estimate"),
    def("Q_WP_SPEED", F32, "cm/s", (10.0, 500.0), 150.0, RW, "Hover hold: horizontal speed limit of the position modes"),
    def("Q_ANGLE_MAX", I16, "cdeg", (500.0, 5500.0), 3000.0, RW, "Hover hold: tilt limit of the position modes"),
    def("HOV_ATT_BW", F32, "rad/s", (0.5, 20.0), 10.0, RW, "Hover hold: attitude law bandwidth (both poles)"),
    def("HOV_ATT_ACC", F32, "rad/s/s", (0.5, 50.0), 12.0, RW, "Hover hold: attitude law's angular acceleration budget"),
    def("HOV_YAW_ACC", F32, "rad/s/s", (0.5, 100.0), 24.0, RW, "Hover hold: heading law's angular acceleration budget"),
    def("Q_WP_RADIUS", F32, "cm", (5.0, 1000.0), 200.0, RW, "In a hover a mission point is reached within this (an item's param2 overrides)"),
    def("TECS_LAND_ARSPD", F32, "m/s", (-1.0, 127.0), -1.0, RW, "Airspeed of a fixed-wing landing approach (-1: the cruise airspeed); the twin lands vertically, so only the VTOL-land pre-arm check reads it, as ArduPlane's does"),
    def("Q_TRANS_DECEL", F32, "m/s/s", (0.2, 10.0), 6.0, RW, "Deceleration of the VTOL landing approach (ArduPlane's tailsitter default): its distances are v^2 / (2 Q_TRANS_DECEL)"),
    def("RTL_RADIUS", I16, "m", (-32767.0, 32767.0), 0.0, RW, "RTL's loiter radius (0: WP_LOITER_RAD); with Q_RTL_MODE 1 QRTL starts within it"),
    def("RTL_ALTITUDE", F32, "m", (-1.0, 1000.0), 100.0, RW, "RTL flies home this high above home; negative: at the altitude it starts at"),
    def("Q_GUIDED_MODE", I8, "", (0.0, 1.0), 0.0, RW, "GUIDED targets in the air: 0 flown on the wing, circled at WP_LOITER_RAD; 1 flown and held in a hover"),
    def("Q_ENABLE", I8, "", (1.0, 2.0), 1.0, RW, "QuadPlane: 1 enabled, 2 VTOL AUTO (AUTO flies its position items in a hover)"),
    def("Q_TAILSIT_ENABLE", I8, "", (0.0, 2.0), 1.0, RO, "The twin is a tailsitter"),
];

/// Why a write was refused or a name not found.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum ParamError {
    /// No parameter has this name.
    #[error("unknown parameter {0}")]
    Unknown(String),
    /// NaN or infinite.
    #[error("{name}: value {value} is not finite")]
    NotFinite {
        /// Parameter id.
        name: &'static str,
        /// The rejected value.
        value: f64,
    },
    /// Outside the parameter's range.
    #[error("{name}: {value} outside [{min}, {max}]")]
    OutOfRange {
        /// Parameter id.
        name: &'static str,
        /// The rejected value (after the C cast).
        value: f64,
        /// Range minimum.
        min: f64,
        /// Range maximum.
        max: f64,
    },
    /// The parameter cannot be written.
    #[error("{0} is read-only")]
    ReadOnly(&'static str),
    /// The gain set would break a controller constraint.
    #[error("{name}: {source}")]
    Gains {
        /// Parameter id.
        name: &'static str,
        /// The violated constraint.
        source: GainError,
    },
}

impl ParamError {
    /// The reason in a few words, short enough for a 50-character STATUSTEXT.
    #[must_use]
    pub fn short_reason(&self) -> String {
        match self {
            Self::Unknown(_) => "unknown".to_owned(),
            Self::NotFinite { .. } => "not finite".to_owned(),
            Self::OutOfRange { min, max, .. } => format!("range {min}..{max}"),
            Self::ReadOnly(_) => "read-only".to_owned(),
            Self::Gains {
                source: GainError::SaturationConditions { condition, .. },
                ..
            } => {
                format!("needs {condition}")
            }
            Self::Gains {
                source: GainError::CrossCheck(condition),
                ..
            } => format!("needs {condition}"),
            Self::Gains { .. } => "must be > 0".to_owned(),
        }
    }

    /// The `MAV_PARAM_ERROR` code for PARAM_ERROR (common.xml).
    #[must_use]
    pub const fn mav_error(&self) -> u8 {
        match self {
            Self::Unknown(_) => 1,
            Self::NotFinite { .. } | Self::OutOfRange { .. } | Self::Gains { .. } => 2,
            Self::ReadOnly(_) => 5,
        }
    }
}

/// A `.parm` file that cannot be used. Loading never silently falls back to defaults.
#[derive(Debug, thiserror::Error)]
pub enum ParamFileError {
    /// Reading or writing failed, or a line is not `NAME VALUE`, names an unknown parameter,
    /// or holds a refused value.
    #[error(transparent)]
    File(#[from] TextFileError),
    /// The values are individually fine but break a constraint together.
    #[error("{path}: {source}")]
    Gains {
        /// The file.
        path: PathBuf,
        /// The violated constraint.
        source: GainError,
    },
}

/// The result of an accepted write.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Accepted {
    /// Index of the parameter.
    pub index: usize,
    /// Value before the write.
    pub old: f64,
    /// Stored value (after the C cast).
    pub new: f64,
}

/// The live parameter values, in [`TABLE`] order.
#[derive(Debug, Clone, PartialEq)]
pub struct Params {
    values: Vec<f64>,
}

impl Default for Params {
    fn default() -> Self {
        Self::new()
    }
}

impl Params {
    /// Every parameter at its default, stored as its type holds it (float32 for REAL32), so the
    /// constraint checks see exactly the values a ground station reads back.
    #[must_use]
    pub fn new() -> Self {
        Self {
            values: TABLE.iter().map(|d| d.ty.cast(d.default)).collect(),
        }
    }

    /// Number of parameters (constant).
    #[must_use]
    pub fn count(&self) -> usize {
        TABLE.len()
    }

    /// Index of a parameter by exact (case-sensitive) name.
    #[must_use]
    pub fn index_of(name: &str) -> Option<usize> {
        TABLE.iter().position(|d| d.name == name)
    }

    /// Definition and value at an index.
    #[must_use]
    pub fn at(&self, index: usize) -> Option<(&'static ParamDef, f64)> {
        TABLE.get(index).map(|d| (d, self.values[index]))
    }

    /// Value by name.
    #[must_use]
    pub fn get(&self, name: &str) -> Option<f64> {
        Self::index_of(name).map(|i| self.values[i])
    }

    /// Value by name for names the firmware itself uses: a typo is a bug, so it panics.
    #[must_use]
    pub fn value(&self, name: &str) -> f64 {
        match Self::index_of(name) {
            Some(i) => self.values[i],
            None => panic!("parameter {name} is not in the table"),
        }
    }

    /// Writes a value the way PARAM_SET does: C cast, finiteness, range, access, then the gain
    /// constraints of the whole set. On error nothing changes.
    ///
    /// # Errors
    /// See [`ParamError`].
    pub fn set(&mut self, name: &str, value: f64) -> Result<Accepted, ParamError> {
        let index = Self::index_of(name).ok_or_else(|| ParamError::Unknown(name.to_owned()))?;
        let d = &TABLE[index];
        if d.access == Access::ReadOnly {
            return Err(ParamError::ReadOnly(d.name));
        }
        let new = Self::checked(d, value)?;
        let mut candidate = self.values.clone();
        candidate[index] = new;
        gains_of(&candidate)
            .validate()
            .map_err(|source| ParamError::Gains {
                name: d.name,
                source,
            })?;
        let old = std::mem::replace(&mut self.values[index], new);
        Ok(Accepted { index, old, new })
    }

    /// A whole set of writes validated at once, as a `.parm` file is: each value must pass its
    /// parameter's type, range and access checks (the same as [`Params::set`], same error
    /// texts), and the resulting gain set must satisfy the constraints, so levels may be given
    /// in any order. On error nothing changes.
    ///
    /// # Errors
    /// The first refused write, or [`ParamError::Gains`] naming the last parameter of the set.
    pub fn set_all(&mut self, writes: &[(String, f64)]) -> Result<(), ParamError> {
        let mut candidate = self.values.clone();
        let mut last = None;
        for (name, value) in writes {
            let index = Self::index_of(name).ok_or_else(|| ParamError::Unknown(name.clone()))?;
            let d = &TABLE[index];
            if d.access == Access::ReadOnly {
                return Err(ParamError::ReadOnly(d.name));
            }
            candidate[index] = Self::checked(d, *value)?;
            last = Some(d.name);
        }
        if let Some(name) = last {
            gains_of(&candidate)
                .validate()
                .map_err(|source| ParamError::Gains { name, source })?;
        }
        self.values = candidate;
        Ok(())
    }

    /// Sets a value from inside the firmware (a one-shot trigger resetting itself), skipping the
    /// access check but not the range.
    ///
    /// # Errors
    /// [`ParamError::Unknown`] or a range error.
    pub fn set_internal(&mut self, name: &str, value: f64) -> Result<Accepted, ParamError> {
        let index = Self::index_of(name).ok_or_else(|| ParamError::Unknown(name.to_owned()))?;
        let new = Self::checked(&TABLE[index], value)?;
        let old = std::mem::replace(&mut self.values[index], new);
        Ok(Accepted { index, old, new })
    }

    fn checked(d: &'static ParamDef, value: f64) -> Result<f64, ParamError> {
        if !value.is_finite() {
            return Err(ParamError::NotFinite {
                name: d.name,
                value,
            });
        }
        let v = d.ty.cast(value);
        if !(d.min..=d.max).contains(&v) {
            return Err(ParamError::OutOfRange {
                name: d.name,
                value: v,
                min: d.min,
                max: d.max,
            });
        }
        Ok(v)
    }

    /// The wind `SIM_WIND_*` describe, in the paper's frame (z up), m/s, and the gust intensity:
    /// the direction is where the wind comes from (ArduPilot SITL).
    #[must_use]
    pub fn wind_paper_m_s(&self) -> (nalgebra::Vector3<f64>, f64) {
        let speed = self.value("SIM_WIND_SPD");
        let from = self.value("SIM_WIND_DIR").to_radians();
        let ned = nalgebra::Vector3::new(-speed * from.cos(), -speed * from.sin(), 0.0);
        (
            crate::model::frames::ned_to_paper(&ned),
            self.value("SIM_WIND_TURB"),
        )
    }

    /// The controller gains the table holds.
    #[must_use]
    pub fn gains(&self) -> Gains {
        gains_of(&self.values)
    }

    /// Where `SIM_HOME_LAT`/`LON`/`ALT` put the motion-capture origin on the globe.
    #[must_use]
    pub fn origin(&self) -> crate::nav::globe::Origin {
        crate::nav::globe::Origin::from_degrees(
            self.value("SIM_HOME_LAT"),
            self.value("SIM_HOME_LON"),
            self.value("SIM_HOME_ALT"),
        )
    }

    /// The battery `BATT_CAPACITY` and `SIM_BATT_VOLTAGE` describe.
    #[must_use]
    pub fn battery(&self) -> crate::model::plant::battery::BatteryConfig {
        crate::model::plant::battery::BatteryConfig {
            capacity_mah: self.value("BATT_CAPACITY"),
            full_voltage_v: self.value("SIM_BATT_VOLTAGE"),
        }
    }

    /// The table as `.parm` text: names sorted, `%-16.16s %d` for integers (MAVProxy's
    /// `mavparm.save`) and floats at their shortest round-trip decimal (no six-decimal
    /// rounding: a file read back holds exactly what was saved). Volatile parameters are left
    /// out.
    #[must_use]
    pub fn to_parm_string(&self) -> String {
        let mut sorted: Vec<(&ParamDef, f64)> = TABLE
            .iter()
            .zip(&self.values)
            .filter(|(d, _)| d.access != Access::Volatile)
            .map(|(d, v)| (d, *v))
            .collect();
        sorted.sort_by_key(|(d, _)| d.name);
        let mut out = String::from("# firmware-sim parameters\n");
        for (d, v) in sorted {
            // Writing into a String cannot fail.
            let _ = if d.ty.is_integer() {
                writeln!(out, "{:<16} {}", d.name, v as i64)
            } else {
                writeln!(out, "{:<16} {}", d.name, shortest(v))
            };
        }
        out
    }

    /// Parses `.parm` text over the defaults. Comments (`#`), blank lines, `NAME VALUE` and
    /// `NAME,VALUE` lines, and `0x` hex integers are accepted; read-only names are skipped (as
    /// MAVProxy skips its `exclude_load` names). Anything else is an error naming the line.
    ///
    /// # Errors
    /// [`ParamFileError::File`] (a line) or [`ParamFileError::Gains`].
    pub fn from_parm_str(text: &str, path: &Path) -> Result<Self, ParamFileError> {
        let mut params = Self::new();
        let line_err = |line: usize, reason: String| {
            ParamFileError::from(TextFileError::line(path, line, reason))
        };
        let mut seen = BTreeMap::new();
        for (n, raw) in text.lines().enumerate() {
            let line_no = n + 1;
            let body = raw.split('#').next().unwrap_or("").trim().replace(',', " ");
            if body.is_empty() {
                continue;
            }
            let tokens: Vec<&str> = body.split_whitespace().collect();
            let [name, value] = tokens[..] else {
                return Err(line_err(
                    line_no,
                    format!("expected NAME VALUE, got {raw:?}"),
                ));
            };
            let value = parse_value(value)
                .ok_or_else(|| line_err(line_no, format!("{name}: bad value {value:?}")))?;
            let index = Self::index_of(name)
                .ok_or_else(|| line_err(line_no, format!("unknown parameter {name}")))?;
            if let Some(first) = seen.insert(name.to_owned(), line_no) {
                return Err(line_err(
                    line_no,
                    format!("{name} already set on line {first}"),
                ));
            }
            let d = &TABLE[index];
            if d.access == Access::ReadOnly {
                continue;
            }
            params.values[index] =
                Self::checked(d, value).map_err(|e| line_err(line_no, e.to_string()))?;
        }
        // Constraints are checked on the whole set: a file may list levels in any order.
        params
            .gains()
            .validate()
            .map_err(|source| ParamFileError::Gains {
                path: path.to_owned(),
                source,
            })?;
        Ok(params)
    }

    /// Loads a `.parm` file.
    ///
    /// # Errors
    /// I/O errors and everything [`Params::from_parm_str`] refuses.
    pub fn load(path: &Path) -> Result<Self, ParamFileError> {
        let text = vtol_link::text_file::read_text(path)?;
        Self::from_parm_str(&text, path)
    }

    /// Writes the table atomically: a temporary file in the same directory, flushed to disk,
    /// then renamed over `path`, so a crash never leaves a half-written file.
    ///
    /// # Errors
    /// [`ParamFileError::File`].
    pub fn save(&self, path: &Path) -> Result<(), ParamFileError> {
        Ok(vtol_link::text_file::write_text(
            path,
            &self.to_parm_string(),
        )?)
    }
}

fn parse_value(s: &str) -> Option<f64> {
    if let Some(hex) = s.strip_prefix("0x").or_else(|| s.strip_prefix("0X")) {
        return i64::from_str_radix(hex, 16).ok().map(|v| v as f64);
    }
    s.parse::<f64>().ok()
}

fn gains_of(values: &[f64]) -> Gains {
    let v = |name: &str| values[Params::index_of(name).unwrap_or_else(|| unreachable!("{name}"))];
    let chain = |p: &str| SaturationLevels {
        a: v(&format!("{p}_A")),
        b: v(&format!("{p}_B")),
        c: v(&format!("{p}_C")),
        d: v(&format!("{p}_D")),
    };
    Gains {
        lateral: chain("LAT_SAT"),
        longitudinal: chain("LON_SAT"),
        alt_kd: v("ALT_KD"),
        alt_kp: v("ALT_KP"),
        yaw_kd: v("YAW_KD"),
        yaw_kp: v("YAW_KP"),
        hover_alt_m: v("HOVER_ALT"),
        land_speed_m_s: v("LAND_SPEED"),
        climb_max_m_s: v("Q_PILOT_SPEED_UP") / 100.0,
        sink_max_m_s: match v("Q_PILOT_SPEED_DN") {
            dn if dn > 0.0 => dn / 100.0,
            _ => v("Q_PILOT_SPEED_UP") / 100.0,
        },
        forward: ForwardGains {
            airspeed_min_m_s: v("ARSPD_FBW_MIN"),
            airspeed_max_m_s: v("ARSPD_FBW_MAX"),
            airspeed_trim_m_s: v("TRIM_ARSPD_CM") / 100.0,
            tecs: TecsLimits {
                time_const_s: v("TECS_TIME_CONST"),
                climb_max_m_s: v("TECS_CLMB_MAX"),
                sink_max_m_s: v("TECS_SINK_MAX"),
            },
            roll_limit_rad: (v("LIM_ROLL_CD") / 100.0).to_radians(),
            transition_rate_fw_rad_s: v("Q_TAILSIT_RAT_FW").to_radians(),
            transition_rate_vt_rad_s: v("Q_TAILSIT_RAT_VT").to_radians(),
            transition_angle_fw_rad: v("Q_TAILSIT_ANGLE").to_radians(),
            transition_angle_vt_rad: v("Q_TAILSIT_ANG_VT").to_radians(),
            transition_timeout_s: v("Q_TRANSITION_MS") / 1000.0,
            attitude_bandwidth_rad_s: v("FW_ATT_BW"),
        },
        hover: HoverHoldGains {
            law: if v("HOV_POS_LAW") == 0.0 {
                HoverLaw::PaperChains
            } else {
                HoverLaw::Cascade
            },
            pos_p: v("Q_P_POSXY_P"),
            vel_p: v("Q_P_VELXY_P"),
            vel_i: v("Q_P_VELXY_I"),
            vel_imax_m_s2: 0.01 * v("Q_P_VELXY_IMAX"),
            speed_max_m_s: 0.01 * v("Q_WP_SPEED"),
            angle_max_rad: (0.01 * v("Q_ANGLE_MAX")).to_radians(),
            att_bw_rad_s: v("HOV_ATT_BW"),
            att_acc_rad_s2: v("HOV_ATT_ACC"),
            yaw_acc_rad_s2: v("HOV_YAW_ACC"),
        },
    }
}

/// A value at its shortest round-trip decimal: a value that is a float32 (what PARAM_SET
/// carries) as the float32's shortest decimal (`1.2`, not `1.2000000476837158`), any other at
/// the f64's.
fn shortest(v: f64) -> String {
    #[allow(clippy::cast_possible_truncation)]
    let single = v as f32;
    if f64::from(single) == v {
        single.to_string()
    } else {
        v.to_string()
    }
}

#[cfg(test)]
#[path = "params_tests.rs"]
mod tests;
