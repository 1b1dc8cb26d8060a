//! What the twin says it is: the autopilot and vehicle type of its HEARTBEAT and the
//! AUTOPILOT_VERSION that answers MAV_CMD_REQUEST_AUTOPILOT_CAPABILITIES and
//! MAV_CMD_REQUEST_MESSAGE(148).
//!
//! The twin flies ArduPlane's custom modes and speaks ArduPlane's parameter, mission and command
//! conventions, so it says `MAV_AUTOPILOT_ARDUPILOTMEGA`: ground stations and SDKs choose their
//! ArduPilot support from that field (QGroundControl its firmware plugin, MAVSDK its mode
//! encoding, DroneKit and pymavlink their mode tables). The vehicle type is
//! `MAV_TYPE_FIXED_WING`, what ArduPlane reports for a two-motor tailsitter as it comes: its
//! `QuadPlane::get_mav_type` returns `Q_MAV_TYPE`, or FIXED_WING while that parameter is 0, its
//! default. It is also the only type for which MAVSDK reads and sets ArduPlane's mode numbers:
//! with any other (a VTOL type included) it takes the vehicle for ArduCopter and sends copter
//! modes (GUIDED as 4, AUTO as 3), which ArduPlane and the twin refuse.
//!
//! The capability bits are those of what the twin serves: missions as MISSION_ITEM and
//! MISSION_ITEM_INT, COMMAND_INT, parameters as floats (C-cast integers, as ArduPilot encodes
//! them), both SET_POSITION_TARGET messages, MAVLink 2. Not FTP: the twin only NAKs it (`ftp`).
//! The UID is stable per system id, so a ground station recognises the same twin again.

use mavlink::dialects::ardupilotmega as apm;
use vtol_link::SystemId;

/// HEARTBEAT `autopilot`.
pub const AUTOPILOT: apm::MavAutopilot = apm::MavAutopilot::MAV_AUTOPILOT_ARDUPILOTMEGA;

/// HEARTBEAT `type`: ArduPlane's for a two-motor tailsitter (`Q_MAV_TYPE` = 0, the default).
pub const MAV_TYPE: apm::MavType = apm::MavType::MAV_TYPE_FIXED_WING;

/// The UID of the twin with system id `sysid` (`AUTOPILOT_VERSION.uid`).
#[must_use]
pub fn uid(sysid: SystemId) -> u64 {
    0x7654_0000 + u64::from(sysid.0)
}

/// The capability bits the twin honours. PARAM_FLOAT is deprecated in common.xml but ArduPilot
/// still sets it, and DroneKit reads it (`capabilities.param_float`).
#[must_use]
#[allow(deprecated)]
pub fn capabilities() -> apm::MavProtocolCapability {
    use apm::MavProtocolCapability as C;
    C::MAV_PROTOCOL_CAPABILITY_MISSION_FLOAT
        | C::MAV_PROTOCOL_CAPABILITY_PARAM_FLOAT
        | C::MAV_PROTOCOL_CAPABILITY_MISSION_INT
        | C::MAV_PROTOCOL_CAPABILITY_COMMAND_INT
        | C::MAV_PROTOCOL_CAPABILITY_PARAM_ENCODE_C_CAST
        | C::MAV_PROTOCOL_CAPABILITY_SET_POSITION_TARGET_LOCAL_NED
        | C::MAV_PROTOCOL_CAPABILITY_SET_POSITION_TARGET_GLOBAL_INT
        | C::MAV_PROTOCOL_CAPABILITY_MAVLINK2
}

/// `flight_sw_version` in ArduPilot's layout: major.minor.patch.type, type 255 =
/// FIRMWARE_VERSION_TYPE_OFFICIAL; the twin's crate version.
#[must_use]
pub fn flight_sw_version() -> u32 {
    let mut it = env!("CARGO_PKG_VERSION")
        .split('.')
        .map(|s| s.parse::<u32>().unwrap_or(0));
    let (major, minor, patch) = (
        it.next().unwrap_or(0),
        it.next().unwrap_or(0),
        it.next().unwrap_or(0),
    );
    (major << 24) | (minor << 16) | (patch << 8) | 255
}

/// AUTOPILOT_VERSION of the twin with system id `sysid`.
#[must_use]
pub fn autopilot_version(sysid: SystemId) -> apm::MavMessage {
    let mut custom = [0u8; 8];
    custom[..7].copy_from_slice(b"vtoltwn");
    let mut uid2 = [0u8; 18];
    uid2[..8].copy_from_slice(&uid(sysid).to_le_bytes());
    apm::MavMessage::AUTOPILOT_VERSION(apm::AUTOPILOT_VERSION_DATA {
        capabilities: capabilities(),
        uid: uid(sysid),
        flight_sw_version: flight_sw_version(),
        middleware_sw_version: 0,
        os_sw_version: 0,
        board_version: 0,
        vendor_id: 0,
        product_id: 0,
        flight_custom_version: custom,
        middleware_custom_version: [0; 8],
        os_custom_version: [0; 8],
        uid2,
    })
}
