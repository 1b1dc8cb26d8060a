//! Protocol constants read from the dialect's generated code, so that no message id is typed by
//! hand: one table for the daemon, the twin and the tools. And the names the twin gives the
//! controller outputs it sends as NAMED_VALUE_FLOAT, which the daemon's plots read back.

use mavlink::MessageData;

use crate::dialect as apm;

/// Message ids.
pub mod id {
    use super::{MessageData, apm};
    /// HEARTBEAT.
    pub const HEARTBEAT: u32 = <apm::HEARTBEAT_DATA as MessageData>::ID;
    /// SYS_STATUS.
    pub const SYS_STATUS: u32 = <apm::SYS_STATUS_DATA as MessageData>::ID;
    /// SYSTEM_TIME.
    pub const SYSTEM_TIME: u32 = <apm::SYSTEM_TIME_DATA as MessageData>::ID;
    /// PARAM_REQUEST_READ.
    pub const PARAM_REQUEST_READ: u32 = <apm::PARAM_REQUEST_READ_DATA as MessageData>::ID;
    /// PARAM_VALUE.
    pub const PARAM_VALUE: u32 = <apm::PARAM_VALUE_DATA as MessageData>::ID;
    /// PARAM_SET.
    pub const PARAM_SET: u32 = <apm::PARAM_SET_DATA as MessageData>::ID;
    /// GPS_RAW_INT.
    pub const GPS_RAW_INT: u32 = <apm::GPS_RAW_INT_DATA as MessageData>::ID;
    /// SCALED_IMU.
    pub const SCALED_IMU: u32 = <apm::SCALED_IMU_DATA as MessageData>::ID;
    /// RAW_IMU.
    pub const RAW_IMU: u32 = <apm::RAW_IMU_DATA as MessageData>::ID;
    /// ATTITUDE.
    pub const ATTITUDE: u32 = <apm::ATTITUDE_DATA as MessageData>::ID;
    /// ATTITUDE_QUATERNION.
    pub const ATTITUDE_QUATERNION: u32 = <apm::ATTITUDE_QUATERNION_DATA as MessageData>::ID;
    /// LOCAL_POSITION_NED.
    pub const LOCAL_POSITION_NED: u32 = <apm::LOCAL_POSITION_NED_DATA as MessageData>::ID;
    /// GLOBAL_POSITION_INT.
    pub const GLOBAL_POSITION_INT: u32 = <apm::GLOBAL_POSITION_INT_DATA as MessageData>::ID;
    /// SERVO_OUTPUT_RAW.
    pub const SERVO_OUTPUT_RAW: u32 = <apm::SERVO_OUTPUT_RAW_DATA as MessageData>::ID;
    /// MISSION_ITEM (deprecated by MAVLink, still sent by older ground stations).
    #[allow(deprecated)]
    pub const MISSION_ITEM: u32 = <apm::MISSION_ITEM_DATA as MessageData>::ID;
    /// MISSION_CURRENT.
    pub const MISSION_CURRENT: u32 = <apm::MISSION_CURRENT_DATA as MessageData>::ID;
    /// NAV_CONTROLLER_OUTPUT.
    pub const NAV_CONTROLLER_OUTPUT: u32 = <apm::NAV_CONTROLLER_OUTPUT_DATA as MessageData>::ID;
    /// RC_CHANNELS.
    pub const RC_CHANNELS: u32 = <apm::RC_CHANNELS_DATA as MessageData>::ID;
    /// MISSION_ITEM_INT.
    pub const MISSION_ITEM_INT: u32 = <apm::MISSION_ITEM_INT_DATA as MessageData>::ID;
    /// VFR_HUD.
    pub const VFR_HUD: u32 = <apm::VFR_HUD_DATA as MessageData>::ID;
    /// COMMAND_INT.
    pub const COMMAND_INT: u32 = <apm::COMMAND_INT_DATA as MessageData>::ID;
    /// COMMAND_LONG.
    pub const COMMAND_LONG: u32 = <apm::COMMAND_LONG_DATA as MessageData>::ID;
    /// COMMAND_ACK.
    pub const COMMAND_ACK: u32 = <apm::COMMAND_ACK_DATA as MessageData>::ID;
    /// POSITION_TARGET_LOCAL_NED.
    pub const POSITION_TARGET_LOCAL_NED: u32 =
        <apm::POSITION_TARGET_LOCAL_NED_DATA as MessageData>::ID;
    /// POSITION_TARGET_GLOBAL_INT.
    pub const POSITION_TARGET_GLOBAL_INT: u32 =
        <apm::POSITION_TARGET_GLOBAL_INT_DATA as MessageData>::ID;
    /// RADIO_STATUS.
    pub const RADIO_STATUS: u32 = <apm::RADIO_STATUS_DATA as MessageData>::ID;
    /// AHRS2: ArduPilot's secondary attitude estimate, always in the wing frame.
    pub const AHRS2: u32 = <apm::AHRS2_DATA as MessageData>::ID;
    /// BATTERY_STATUS.
    pub const BATTERY_STATUS: u32 = <apm::BATTERY_STATUS_DATA as MessageData>::ID;
    /// AUTOPILOT_VERSION.
    pub const AUTOPILOT_VERSION: u32 = <apm::AUTOPILOT_VERSION_DATA as MessageData>::ID;
    /// HOME_POSITION.
    pub const HOME_POSITION: u32 = <apm::HOME_POSITION_DATA as MessageData>::ID;
    /// EXTENDED_SYS_STATE.
    pub const EXTENDED_SYS_STATE: u32 = <apm::EXTENDED_SYS_STATE_DATA as MessageData>::ID;
    /// NAMED_VALUE_FLOAT.
    pub const NAMED_VALUE_FLOAT: u32 = <apm::NAMED_VALUE_FLOAT_DATA as MessageData>::ID;
    /// SETUP_SIGNING.
    pub const SETUP_SIGNING: u32 = <apm::SETUP_SIGNING_DATA as MessageData>::ID;
    /// STATUSTEXT.
    pub const STATUSTEXT: u32 = <apm::STATUSTEXT_DATA as MessageData>::ID;
    /// AOA_SSA (ardupilotmega).
    pub const AOA_SSA: u32 = <apm::AOA_SSA_DATA as MessageData>::ID;
}

/// CRC_EXTRA of COMMAND_ACK.
pub const CRC_EXTRA_COMMAND_ACK: u8 = <apm::COMMAND_ACK_DATA as MessageData>::EXTRA_CRC;

/// Names of the controller's outputs the twin sends as NAMED_VALUE_FLOAT, in order: τ̃φ, τ̃θ,
/// τ̃ψ (rad/s², the paper's frame, Fig 5) and the thrust f_z (N).
pub const CONTROLLER_OUTPUT_NAMES: [&str; 4] = ["TAU_PHI", "TAU_THETA", "TAU_PSI", "FZ"];
