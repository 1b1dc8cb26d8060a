//! A decoded message as named fields, the one shape both the CSV and the MCAP export write.
//!
//! The names are those of the MAVLink XML definitions (the dialect's serde derives keep them,
//! except `type`, which Rust spells `mavtype`: it is renamed back). Enum fields are written as
//! the enum entry's name (`MAV_TYPE_GCS`), bitmask fields as their flag names joined by ` | `,
//! character arrays as text, and numeric arrays as one field per element, `name[i]`.

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

/// The message's name and flattened fields.
#[must_use]
pub fn flatten(msg: &MavMessage) -> (&'static str, Fields) {
    use mavlink::Message;
    let name = msg.message_name();
    let mut out = Vec::new();
    // The serde form is {"type": NAME, field: value, ...}; a failure here would be a bug in the
    // generated derives, and then the message simply has no fields.
    if let Ok(Value::Object(map)) = serde_json::to_value(msg) {
        for (key, value) in map {
            if key == "type" {
                continue;
            }
            let key = if key == "mavtype" {
                "type".to_owned()
            } else {
                key
            };
            push_value(&mut out, key, value);
        }
    }
    (name, out)
}

fn push_value(out: &mut Fields, key: String, value: Value) {
    match value {
        // A unit enum entry serialises as {"type": "ENTRY_NAME"}.
        Value::Object(inner) => out.push((key, enum_name(inner))),
        Value::Array(items) if items.iter().all(Value::is_number) => {
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
/// strings as they are. A non-finite float is `nan`: the JSON form has no infinities, so ±inf
/// and NaN arrive alike (as null, the only way a message field becomes null).
#[must_use]
pub fn csv_text(v: &Value) -> String {
    match v {
        Value::String(s) => s.clone(),
        Value::Null => "nan".to_owned(),
        other => other.to_string(),
    }
}

/// A field value as a number, if it is one (for plots and resampling).
#[must_use]
pub fn as_f64(v: &Value) -> Option<f64> {
    v.as_f64()
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
}
