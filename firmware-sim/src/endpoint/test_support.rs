//! Helpers of the endpoint's state-machine tests: an endpoint with one GCS link, frames in
//! both MAVLink versions, and readers of what comes out.

pub(super) use mavlink::dialects::ardupilotmega as apm;
pub(super) use mavlink::types::CharArray;

pub(super) use super::*;
pub(super) use crate::nav::params::TABLE;
pub(super) use vtol_link::{FrameDecoder, MavlinkVersion};

pub(super) const GCS: LinkKey = LinkKey(1);
pub(super) const GCS_SYSID: u8 = 255;
pub(super) const GCS_COMPID: u8 = 190;

/// A mission item at a point `north_m`, `east_m` from the origin, `alt` m above home.
#[allow(deprecated)] // MAV_FRAME_GLOBAL_RELATIVE_ALT_INT, as ground stations still send it
pub(super) fn item(
    command: u16,
    north_m: f64,
    east_m: f64,
    alt: f32,
) -> crate::nav::mission::MissionItem {
    let o = Params::new().origin();
    let p = o.to_global(&nalgebra::Vector3::new(north_m, east_m, 0.0));
    crate::nav::mission::MissionItem {
        params: [0.0, 0.0, 0.0, f32::NAN],
        x: p.lat_e7,
        y: p.lon_e7,
        z: alt,
        command,
        frame: apm::MavFrame::MAV_FRAME_GLOBAL_RELATIVE_ALT_INT as u8,
        current: 0,
        autocontinue: 1,
    }
}

/// The start of a VTOL mission: home (item 0) and a VTOL take-off to `alt` m where it stands.
pub(super) fn home_and_vtol_takeoff(alt: f32) -> [crate::nav::mission::MissionItem; 2] {
    use apm::MavCmd;
    [
        item(MavCmd::MAV_CMD_NAV_WAYPOINT as u16, 0.0, 0.0, 0.0),
        crate::nav::mission::MissionItem {
            x: 0,
            y: 0,
            ..item(MavCmd::MAV_CMD_NAV_VTOL_TAKEOFF as u16, 0.0, 0.0, alt)
        },
    ]
}

/// A DO_VTOL_TRANSITION item to forward flight (MAV_VTOL_STATE_FW).
pub(super) fn transition_to_fw() -> crate::nav::mission::MissionItem {
    use apm::{MavCmd, MavFrame};
    crate::nav::mission::MissionItem {
        x: 0,
        y: 0,
        frame: MavFrame::MAV_FRAME_MISSION as u8,
        params: [4.0, 0.0, 0.0, f32::NAN],
        ..item(MavCmd::MAV_CMD_DO_VTOL_TRANSITION as u16, 0.0, 0.0, 0.0)
    }
}

pub(super) fn endpoint() -> Endpoint {
    let mut config = EndpointConfig::default();
    config.vehicle.ideal_sensors = true;
    let mut ep = Endpoint::new(config);
    ep.add_link(GCS);
    ep
}

pub(super) fn v2(msg: &apm::MavMessage) -> Frame {
    Frame::encode_v2(
        vtol_link::SystemId(GCS_SYSID),
        vtol_link::ComponentId(GCS_COMPID),
        7,
        msg,
    )
}

/// A raw payload of `message_id` framed (v2, sequence number `seq`) as the test's ground
/// station sends it.
pub(super) fn from_gcs(seq: u8, message_id: u32, payload: &[u8]) -> Frame {
    Frame::encode_payload_v2(
        vtol_link::SystemId(GCS_SYSID),
        vtol_link::ComponentId(GCS_COMPID),
        seq,
        message_id,
        payload,
    )
    .unwrap()
}

pub(super) fn v1(msg: &apm::MavMessage) -> Frame {
    Frame::encode_v1(
        vtol_link::SystemId(GCS_SYSID),
        vtol_link::ComponentId(GCS_COMPID),
        3,
        msg,
    )
    .expect("a MAVLink 1 message")
}

/// Every outbound frame must be MAVLink 2 from (1, 1); returns the typed messages.
pub(super) fn decode(out: &[Outbound]) -> Vec<apm::MavMessage> {
    out.iter()
        .filter_map(|o| {
            assert_eq!(o.frame.version(), MavlinkVersion::V2, "always MAVLink 2");
            let f = &o.frame;
            assert_eq!((f.system_id(), f.component_id()), (1, COMPID.0));
            f.decode().ok()
        })
        .collect()
}

/// A COMMAND_LONG to the twin (system 1, any component).
pub(super) fn command_long(command: apm::MavCmd, p: [f32; 7], confirmation: u8) -> apm::MavMessage {
    vtol_link::command_long(
        (vtol_link::SystemId(1), vtol_link::ComponentId(0)),
        command,
        p,
        confirmation,
    )
}

/// (command, result) of every COMMAND_ACK, read from raw bytes (unknown ids do not decode).
pub(super) fn acks(out: &[Outbound]) -> Vec<(u16, u8)> {
    out.iter()
        .map(|o| &o.frame)
        .filter(|f| f.message_id() == vtol_link::protocol::id::COMMAND_ACK)
        .map(|f| {
            let p: [u8; 10] = f.payload_padded();
            assert_eq!(
                (p[8], p[9]),
                (GCS_SYSID, GCS_COMPID),
                "ACK targets the sender"
            );
            (u16::from_le_bytes([p[0], p[1]]), p[2])
        })
        .collect()
}

pub(super) fn heartbeat_of(msgs: &[apm::MavMessage]) -> apm::HEARTBEAT_DATA {
    msgs.iter()
        .rev()
        .find_map(|m| match m {
            apm::MavMessage::HEARTBEAT(h) => Some(h.clone()),
            _ => None,
        })
        .expect("a heartbeat")
}

pub(super) fn param_set(name: &str, value: f32) -> apm::MavMessage {
    apm::MavMessage::PARAM_SET(apm::PARAM_SET_DATA {
        param_value: value,
        target_system: 1,
        target_component: 1,
        param_id: CharArray::from(name),
        param_type: apm::MavParamType::MAV_PARAM_TYPE_REAL32,
    })
}

/// Every message of the slice `$msgs` of the variant named, mapped by the expression, in order:
/// `each!(msgs, PARAM_VALUE(v) => v.param_value)`.
macro_rules! each {
    ($msgs:expr, $variant:ident($v:pat) => $f:expr) => {
        $msgs
            .iter()
            .filter_map(|m| match m {
                apm::MavMessage::$variant($v) => Some($f),
                _ => None,
            })
            .collect::<Vec<_>>()
    };
}
pub(super) use each;

pub(super) fn param_values(msgs: &[apm::MavMessage]) -> Vec<apm::PARAM_VALUE_DATA> {
    each!(msgs, PARAM_VALUE(v) => v.clone())
}

pub(super) fn param_errors(msgs: &[apm::MavMessage]) -> Vec<apm::PARAM_ERROR_DATA> {
    each!(msgs, PARAM_ERROR(v) => v.clone())
}

pub(super) fn texts(msgs: &[apm::MavMessage]) -> Vec<String> {
    each!(msgs, STATUSTEXT(t) => t.text.to_str().unwrap_or("").to_owned())
}

/// Ticks in 5 ms steps up to `until_us`, collecting everything.
pub(super) fn run_until(ep: &mut Endpoint, until_us: u64) -> Vec<Outbound> {
    let mut out = Vec::new();
    let mut t = ep.now_us();
    while t < until_us {
        t = (t + 5_000).min(until_us);
        out.extend(ep.tick(t));
    }
    out
}

/// A COMMAND_LONG (`message_id` 76, 33 bytes) or COMMAND_INT (75, 35 bytes) from the test's
/// ground station to system 1, with any command number (the dialect's enum lacks some): `p` are
/// its leading float params (x, y, z of a COMMAND_INT stay 0).
pub(super) fn raw_command(message_id: u32, len: usize, command: u16, p: &[f32]) -> Frame {
    let mut payload = vec![0u8; len];
    for (k, v) in p.iter().enumerate() {
        payload[4 * k..4 * k + 4].copy_from_slice(&v.to_le_bytes());
    }
    payload[28..30].copy_from_slice(&command.to_le_bytes());
    payload[30] = 1;
    from_gcs(5, message_id, &payload)
}
