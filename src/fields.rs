//! A decoded message as named fields, through the dialect's serde derives: the one walk that
//! `log export` (CSV, MCAP), the message inspector and the charts all read.
//!
//! Fields come in definition order of the generated struct. Enum fields are the enum entry's
//! name (`MAV_TYPE_GCS`), bitmask fields their flag names joined by ` | `, character arrays
//! text, and numeric arrays one field per element, `name[i]`.
//!
//! Two spellings of the same walk: [`flatten`] and [`decode`] give the names of the MAVLink XML
//! definitions (`type`, which Rust spells `mavtype`, renamed back) with JSON values, as the
//! export writes them; [`fields`] gives the Rust names with the value as the inspector shows it
//! (enum and flag names in words) and its number for a chart.

use std::collections::HashMap;

use serde_json::{Map, Value};
use vtol_link::Frame;
use vtol_link::dialect::MavMessage;

/// One message's fields in definition order of the generated struct, flattened.
pub type Fields = Vec<(String, Value)>;

/// Decodes a frame and flattens it; `None` if the dialect does not know the message id. An enum
/// value the XML does not define is written as its number, as pymavlink reads it.
#[must_use]
pub fn decode(frame: &Frame) -> Option<(&'static str, Fields)> {
    let lenient = frame.decode_lenient().ok()?;
    let (name, mut fields) = flatten(&lenient.msg);
    for r in &lenient.replaced {
        let Some(key) = field_key(frame.message_id(), r.field) else {
            continue;
        };
        if let Some(slot) = fields.iter_mut().find(|(k, _)| *k == key) {
            slot.1 = Value::from(r.value);
        }
    }
    Some((name, fields))
}

/// The flattened name of an enum field at its place in the payload: the field whose value
/// changes when another value the enum defines is written there. Learnt once per field.
pub(crate) fn field_key(message_id: u32, field: vtol_link::frame::EnumField) -> Option<String> {
    use mavlink::{MavlinkVersion, Message};
    use std::sync::{Mutex, OnceLock};
    type Keys = Mutex<HashMap<(u32, u8), Option<String>>>;
    static KEYS: OnceLock<Keys> = OnceLock::new();
    let keys = KEYS.get_or_init(Keys::default);
    let at = (message_id, field.offset);
    if let Some(k) = keys.lock().ok()?.get(&at) {
        return k.clone();
    }
    let learn = || {
        let msg = MavMessage::default_message_from_id(message_id)?;
        let mut payload = [0u8; 255];
        msg.ser(MavlinkVersion::V2, &mut payload);
        let (_, before) = flatten(&msg);
        let span = usize::from(field.offset)..usize::from(field.offset) + usize::from(field.width);
        (0u32..=u32::from(u16::MAX)).find_map(|v| {
            payload[span.clone()].copy_from_slice(&v.to_le_bytes()[..span.len()]);
            let other = MavMessage::parse(MavlinkVersion::V2, message_id, &payload).ok()?;
            let (_, after) = flatten(&other);
            before
                .iter()
                .zip(&after)
                .find(|(b, a)| b.1 != a.1)
                .map(|(b, _)| b.0.clone())
        })
    };
    let key = learn();
    if let Ok(mut k) = keys.lock() {
        k.insert(at, key.clone());
    }
    key
}

/// The message's name and flattened fields, by the names of the XML definitions.
#[must_use]
pub fn flatten(msg: &MavMessage) -> (&'static str, Fields) {
    use mavlink::Message;
    let mut out = walk(msg);
    for (key, _) in &mut out {
        if key == "mavtype" {
            "type".clone_into(key);
        }
    }
    (msg.message_name(), out)
}

/// The message's flattened fields by their Rust names.
fn walk(msg: &MavMessage) -> Fields {
    let mut out = Vec::new();
    // The serde form is {"type": NAME, field: value, ...}; a failure here would be a bug in the
    // generated derives, and then the message simply has no fields.
    let Ok(mut json) = serde_json::to_value(msg) else {
        return out;
    };
    // JSON has no infinities: a non-finite float became null. CBOR's value keeps it, so where
    // there is a null its float is taken from there (the rest stays JSON's, which spells
    // bitmasks by name).
    if has_null(&json)
        && let Ok(cbor) = ciborium::Value::serialized(msg)
    {
        mark_non_finite(&mut json, &cbor);
    }
    if let Value::Object(map) = json {
        for (key, value) in map {
            if key != "type" {
                push_value(&mut out, key, value);
            }
        }
    }
    out
}

/// The key of the marker a non-finite float becomes in the JSON form:
/// `{"$float": "inf" | "-inf" | "NaN"}`.
const NON_FINITE: &str = "$float";

fn has_null(v: &Value) -> bool {
    match v {
        Value::Null => true,
        Value::Array(a) => a.iter().any(has_null),
        Value::Object(m) => m.values().any(has_null),
        _ => false,
    }
}

/// Each null of `json` whose counterpart in `cbor` is a non-finite float becomes its marker.
fn mark_non_finite(json: &mut Value, cbor: &ciborium::Value) {
    use ciborium::Value as C;
    match (json, cbor) {
        (j @ Value::Null, C::Float(f)) if !f.is_finite() => {
            *j = serde_json::json!({ NON_FINITE: format!("{f:?}") });
        }
        (Value::Array(a), C::Array(c)) => {
            for (j, c) in a.iter_mut().zip(c) {
                mark_non_finite(j, c);
            }
        }
        (Value::Object(m), C::Map(c)) => {
            for (k, c) in c {
                if let Some(j) = k.as_text().and_then(|k| m.get_mut(k)) {
                    mark_non_finite(j, c);
                }
            }
        }
        _ => {}
    }
}

/// A non-finite float's value, from its marker.
fn non_finite(v: &Value) -> Option<f64> {
    match v.as_object()?.get(NON_FINITE)?.as_str()? {
        "inf" => Some(f64::INFINITY),
        "-inf" => Some(f64::NEG_INFINITY),
        _ => Some(f64::NAN),
    }
}

fn push_value(out: &mut Fields, key: String, value: Value) {
    match value {
        v if non_finite(&v).is_some() => out.push((key, v)),
        // A unit enum entry serialises as {"type": "ENTRY_NAME"}.
        Value::Object(inner) => out.push((key, enum_name(inner))),
        Value::Array(items)
            if items
                .iter()
                .all(|v| v.is_number() || non_finite(v).is_some()) =>
        {
            for (i, v) in items.into_iter().enumerate() {
                out.push((format!("{key}[{i}]"), v));
            }
        }
        other => out.push((key, other)),
    }
}

fn enum_name(mut inner: Map<String, Value>) -> Value {
    match inner.remove("type") {
        Some(v) if inner.is_empty() => v,
        Some(v) => {
            inner.insert("type".into(), v);
            Value::Object(inner)
        }
        None => Value::Object(inner),
    }
}

/// A field value as CSV text: numbers as the shortest text that reads back to the same value,
/// strings as they are; a non-finite float as `inf`, `-inf` or `nan`.
#[must_use]
pub fn csv_text(v: &Value) -> String {
    if let Some(f) = non_finite(v) {
        return if f.is_nan() {
            "nan".to_owned()
        } else {
            format!("{f}")
        };
    }
    match v {
        Value::String(s) => s.clone(),
        Value::Null => "nan".to_owned(),
        other => other.to_string(),
    }
}

/// A field value as a number, if it is one (for plots and resampling).
#[must_use]
pub fn as_f64(v: &Value) -> Option<f64> {
    v.as_f64().or_else(|| non_finite(v))
}

/// One field as the inspector shows it and a chart reads it.
#[derive(Debug, Clone, PartialEq)]
pub struct Field {
    /// `name` or `name[3]`, by the Rust name (`mavtype`).
    pub path: String,
    /// The value as shown: numbers as Rust prints them, enum and flag names in words,
    /// character arrays as their text.
    pub text: String,
    /// The value as a number, if it is one.
    pub value: Option<f64>,
}

/// The fields of a decoded message, for the inspector and the charts.
#[must_use]
pub fn fields(msg: &MavMessage) -> Vec<Field> {
    use mavlink::Message;
    let id = msg.message_id();
    walk(msg)
        .into_iter()
        .map(|(path, value)| {
            let (text, number) = match &value {
                v if non_finite(v).is_some() => {
                    let f = non_finite(v).unwrap_or(f64::NAN);
                    (format!("{f:?}"), Some(f))
                }
                Value::Number(n) => (number_text(n), n.as_f64()),
                Value::Null => ("NaN".to_owned(), Some(f64::NAN)),
                Value::String(s) if is_named(id, &path) => (named_words(s), None),
                Value::String(s) => (s.clone(), None),
                other => (other.to_string(), None),
            };
            Field {
                path,
                text,
                value: number,
            }
        })
        .collect()
}

/// The number at `path` in a decoded message, if the path exists and holds a number.
#[must_use]
pub fn value_at(msg: &MavMessage, path: &str) -> Option<f64> {
    walk(msg)
        .into_iter()
        .find(|(p, _)| p == path)
        .and_then(|(_, v)| match v {
            Value::Null => Some(f64::NAN),
            v => as_f64(&v),
        })
}

/// A number as Rust prints the field's own type: a float that an `f32` holds exactly is
/// printed as that `f32` (`0.1`, not the `f64` widening of it).
fn number_text(n: &serde_json::Number) -> String {
    match (n.is_f64(), n.as_f64()) {
        #[allow(clippy::cast_possible_truncation)] // checked: the f32 holds it exactly
        (true, Some(f)) if f64::from(f as f32) == f => format!("{:?}", f as f32),
        (true, Some(f)) => format!("{f:?}"),
        _ => n.to_string(),
    }
}

/// Whether the string field at `key` of message `id` holds enum or flag names rather than
/// text: its value in the dialect's default message is a name (a default enum entry or
/// bitmask is its first entry; a default character array is empty). Learnt once per message.
fn is_named(id: u32, key: &str) -> bool {
    use mavlink::Message;
    use std::collections::HashSet;
    use std::sync::{Mutex, OnceLock};
    type Named = Mutex<HashMap<u32, HashSet<String>>>;
    static NAMED: OnceLock<Named> = OnceLock::new();
    let Ok(mut named) = NAMED.get_or_init(Named::default).lock() else {
        return false;
    };
    named
        .entry(id)
        .or_insert_with(|| {
            MavMessage::default_message_from_id(id)
                .map(|m| walk(&m))
                .unwrap_or_default()
                .into_iter()
                .filter(|(_, v)| v.as_str().is_some_and(|s| !s.is_empty()))
                .map(|(k, _)| k)
                .collect()
        })
        .contains(key)
}

/// Enum or flag names in words: `MAV_TYPE_VTOL_TAILSITTER_DUOROTOR` →
/// `vtol tailsitter duorotor`, `MAV_MODE_FLAG_SAFETY_ARMED | MAV_MODE_FLAG_CUSTOM_MODE_ENABLED`
/// → `safety armed, custom mode enabled`, no flags → `none`.
fn named_words(names: &str) -> String {
    if names.trim().is_empty() {
        return "none".to_owned();
    }
    names
        .split('|')
        .map(|w| enum_words(w.trim()).unwrap_or_else(|| w.trim().to_owned()))
        .collect::<Vec<_>>()
        .join(", ")
}

/// Prefixes of the dialect's enums, longest first: what an enum value's name starts with.
const ENUM_PREFIXES: &[&str] = &[
    "MAV_BATTERY_CHARGE_STATE_",
    "MAV_BATTERY_FUNCTION_",
    "MAV_SYS_STATUS_SENSOR_",
    "MAV_DISTANCE_SENSOR_",
    "MAV_ESTIMATOR_TYPE_",
    "MAV_LANDED_STATE_",
    "MAV_MISSION_TYPE_",
    "MAV_BATTERY_TYPE_",
    "MAV_PARAM_TYPE_",
    "MAV_VTOL_STATE_",
    "MAV_AUTOPILOT_",
    "MAV_MODE_FLAG_",
    "MAV_SEVERITY_",
    "MAV_MISSION_",
    "GPS_FIX_TYPE_",
    "MAV_RESULT_",
    "MAV_SYS_STATUS_",
    "MAV_FRAME_",
    "MAV_STATE_",
    "MAV_TYPE_",
    "MAV_CMD_",
    "MAV_COMP_ID_",
    "EKF_",
    "MAV_",
];

/// An enum value's or a flag's name in words: `MAV_TYPE_VTOL_TAILSITTER_DUOROTOR` →
/// `vtol tailsitter duorotor`, `MAV_MODE_FLAG_SAFETY_ARMED` → `safety armed`; `None` for
/// anything that is not such a name.
fn enum_words(value: &str) -> Option<String> {
    let is_name = value.len() > 2
        && value.contains('_')
        && value
            .chars()
            .all(|c| c.is_ascii_uppercase() || c.is_ascii_digit() || c == '_');
    if !is_name {
        return None;
    }
    let rest = ENUM_PREFIXES
        .iter()
        .find_map(|p| value.strip_prefix(p))
        .filter(|r| !r.is_empty())
        .unwrap_or(value);
    Some(rest.replace('_', " ").to_ascii_lowercase())
}

#[cfg(test)]
mod tests {
    use super::*;
    use vtol_link::dialect as apm;

    #[test]
    fn heartbeat_fields_carry_xml_names_and_enum_names() {
        let (name, f) = flatten(&vtol_link::gcs_heartbeat());
        assert_eq!(name, "HEARTBEAT");
        let get = |k: &str| f.iter().find(|(n, _)| n == k).map(|(_, v)| v.clone());
        assert_eq!(get("type"), Some(Value::String("MAV_TYPE_GCS".into())));
        assert!(get("mavtype").is_none());
        assert!(get("custom_mode").is_some_and(|v| v.is_number()));
    }

    /// A COMMAND_ACK of a command number the dialect lacks is written, the command as its
    /// number and every other field as usual.
    #[test]
    fn an_enum_value_the_dialect_lacks_is_written_as_its_number() {
        let ack = vtol_link::RawCommandAck {
            command: 31_337,
            result: 4,
            progress: 9,
            result_param2: 0,
            target_system: 255,
            target_component: 190,
        };
        let frame = ack.to_frame(vtol_link::SystemId(1), vtol_link::ComponentId(1), 0);
        let (name, f) = decode(&frame).unwrap();
        assert_eq!(name, "COMMAND_ACK");
        let get = |k: &str| f.iter().find(|(n, _)| n == k).map(|(_, v)| v.clone());
        assert_eq!(get("command"), Some(Value::from(31_337)));
        assert_eq!(
            get("result"),
            Some(Value::String("MAV_RESULT_FAILED".into()))
        );
        assert_eq!(get("progress"), Some(Value::from(9)));
    }

    #[test]
    fn a_nan_field_is_written_as_nan_not_left_empty() {
        let msg = apm::MavMessage::ATTITUDE(apm::ATTITUDE_DATA {
            roll: f32::NAN,
            ..Default::default()
        });
        let (_, f) = flatten(&msg);
        let roll = f
            .iter()
            .find(|(n, _)| n == "roll")
            .map(|(_, v)| csv_text(v));
        assert_eq!(roll.as_deref(), Some("nan"));
    }

    #[test]
    fn infinities_keep_their_sign_in_the_export_the_inspector_and_the_charts() {
        let msg = apm::MavMessage::ATTITUDE(apm::ATTITUDE_DATA {
            roll: f32::INFINITY,
            pitch: f32::NEG_INFINITY,
            yaw: 0.5,
            ..Default::default()
        });
        let (_, f) = flatten(&msg);
        let csv = |name: &str| f.iter().find(|(n, _)| n == name).map(|(_, v)| csv_text(v));
        assert_eq!(csv("roll").as_deref(), Some("inf"));
        assert_eq!(csv("pitch").as_deref(), Some("-inf"));
        assert_eq!(csv("yaw").as_deref(), Some("0.5"));
        let shown = fields(&msg);
        let at = |name: &str| {
            shown
                .iter()
                .find(|x| x.path == name)
                .cloned()
                .expect("field")
        };
        assert_eq!(at("roll").text, "inf");
        assert_eq!(at("pitch").text, "-inf");
        assert_eq!(at("roll").value, Some(f64::INFINITY));
        assert_eq!(value_at(&msg, "pitch"), Some(f64::NEG_INFINITY));
        assert_eq!(value_at(&msg, "yaw"), Some(0.5));
    }

    #[test]
    fn numeric_arrays_become_indexed_fields_and_floats_keep_their_f32_value() {
        let msg = apm::MavMessage::ATTITUDE_QUATERNION(apm::ATTITUDE_QUATERNION_DATA {
            q1: 0.1,
            repr_offset_q: [1.0, 0.0, 0.0, 0.5],
            ..Default::default()
        });
        let (_, f) = flatten(&msg);
        let get = |k: &str| f.iter().find(|(n, _)| n == k).map(|(_, v)| v.clone());
        assert_eq!(get("repr_offset_q[3]").and_then(|v| v.as_f64()), Some(0.5));
        let q1 = get("q1").and_then(|v| v.as_f64()).unwrap();
        #[allow(clippy::cast_possible_truncation)] // comparing at f32 precision on purpose
        let back = q1 as f32;
        assert_eq!(back, 0.1f32);
    }

    #[test]
    fn scalar_and_array_fields_of_real_messages() {
        let msg = MavMessage::ATTITUDE(apm::ATTITUDE_DATA {
            time_boot_ms: 1234,
            roll: 0.25,
            pitch: -0.5,
            yaw: 1.0,
            rollspeed: 0.1,
            pitchspeed: f32::INFINITY,
            yawspeed: 0.125,
        });
        assert_eq!(value_at(&msg, "roll"), Some(0.25));
        assert_eq!(value_at(&msg, "pitch"), Some(-0.5));
        assert_eq!(value_at(&msg, "time_boot_ms"), Some(1234.0));
        assert_eq!(value_at(&msg, "nope"), None);
        let f = fields(&msg);
        let text = |p: &str| f.iter().find(|f| f.path == p).map(|f| f.text.clone());
        assert_eq!(
            text("rollspeed").as_deref(),
            Some("0.1"),
            "the f32, as Rust prints it"
        );
        assert_eq!(text("yaw").as_deref(), Some("1.0"));
        assert_eq!(text("time_boot_ms").as_deref(), Some("1234"));
        assert_eq!(text("pitchspeed").as_deref(), Some("inf"));

        let q = apm::ATTITUDE_QUATERNION_DATA {
            repr_offset_q: [0.5, 0.25, 0.0, -1.0],
            ..Default::default()
        };
        let msg = MavMessage::ATTITUDE_QUATERNION(q);
        assert_eq!(value_at(&msg, "repr_offset_q[1]"), Some(0.25));
        assert_eq!(value_at(&msg, "repr_offset_q[3]"), Some(-1.0));
    }

    #[test]
    fn enums_are_text_not_numbers() {
        let msg = MavMessage::HEARTBEAT(apm::HEARTBEAT_DATA::default());
        let f = fields(&msg);
        let t = f.iter().find(|f| f.path == "mavtype").expect("mavtype");
        assert!(t.value.is_none(), "{t:?}");
        assert_eq!(t.text, "generic", "{t:?}");
        assert_eq!(
            f.iter()
                .find(|f| f.path == "custom_mode")
                .and_then(|f| f.value),
            Some(0.0)
        );
    }

    #[test]
    fn bitmasks_in_words() {
        let mut hb = apm::HEARTBEAT_DATA {
            base_mode: apm::MavModeFlag::MAV_MODE_FLAG_CUSTOM_MODE_ENABLED
                | apm::MavModeFlag::MAV_MODE_FLAG_SAFETY_ARMED,
            ..Default::default()
        };
        let f = fields(&MavMessage::HEARTBEAT(hb.clone()));
        let t = &f
            .iter()
            .find(|f| f.path == "base_mode")
            .expect("base_mode")
            .text;
        assert_eq!(t, "safety armed, custom mode enabled");
        hb.base_mode = apm::MavModeFlag::empty();
        let f = fields(&MavMessage::HEARTBEAT(hb));
        let t = &f
            .iter()
            .find(|f| f.path == "base_mode")
            .expect("base_mode")
            .text;
        assert_eq!(t, "none");
    }

    #[test]
    fn character_arrays_are_their_text_even_when_it_looks_like_a_name() {
        let msg = MavMessage::PARAM_VALUE(apm::PARAM_VALUE_DATA {
            param_id: "Q_TILT_ENABLE".into(),
            param_value: 1.0,
            ..Default::default()
        });
        let f = fields(&msg);
        let id = f.iter().find(|f| f.path == "param_id").expect("param_id");
        assert_eq!((id.text.as_str(), id.value), ("Q_TILT_ENABLE", None));
        let empty = MavMessage::STATUSTEXT(apm::STATUSTEXT_DATA::default());
        let f = fields(&empty);
        let text = f.iter().find(|f| f.path == "text").expect("text");
        assert_eq!(text.text, "");
    }
}
