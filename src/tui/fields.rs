//! Every field of a decoded message as (path, text, number): what the message inspector lists
//! and what a chart series reads. The dialect has no field reflection, so this walks the
//! message's `Debug` text (`NAME(NAME_DATA { a: 1, b: [2, 3], c: MAV_X })`), which names every
//! field in declaration order; array elements become `b[0]`, `b[1]`, nested structs `s.x`.

/// One field: its path, its value as shown, and its number when it has one.
#[derive(Debug, Clone, PartialEq)]
pub struct Field {
    /// `name`, `name[3]` or `outer.inner`.
    pub path: String,
    /// The value as text.
    pub text: String,
    /// The value as a number (integers, floats and `true`/`false`), if it is one.
    pub value: Option<f64>,
}

/// Splits `s` at top-level commas (outside brackets, braces, parentheses and quotes).
fn split_top(s: &str) -> Vec<&str> {
    let mut parts = Vec::new();
    let (mut depth, mut in_str, mut escaped, mut start) = (0i32, false, false, 0usize);
    for (i, c) in s.char_indices() {
        if in_str {
            match (escaped, c) {
                (true, _) => escaped = false,
                (false, '\\') => escaped = true,
                (false, '"') => in_str = false,
                _ => {}
            }
            continue;
        }
        match c {
            '"' => in_str = true,
            '[' | '{' | '(' => depth += 1,
            ']' | '}' | ')' => depth -= 1,
            ',' if depth == 0 => {
                parts.push(s[start..i].trim());
                start = i + 1;
            }
            _ => {}
        }
    }
    let last = s[start..].trim();
    if !last.is_empty() {
        parts.push(last);
    }
    parts
}

fn number(text: &str) -> Option<f64> {
    match text {
        "true" => Some(1.0),
        "false" => Some(0.0),
        _ => text.parse::<f64>().ok(),
    }
}

fn walk(path: &str, value: &str, out: &mut Vec<Field>) {
    let value = value.trim();
    if let Some(inner) = value.strip_prefix('[').and_then(|v| v.strip_suffix(']')) {
        let items = split_top(inner);
        // A byte array that holds text (STATUSTEXT's `text`, PARAM_VALUE's `param_id`) is also
        // shown as one string, but its elements stay chartable.
        for (i, item) in items.iter().enumerate() {
            walk(&format!("{path}[{i}]"), item, out);
        }
        return;
    }
    if let Some(open) = value.find('{')
        && value.ends_with('}')
        && !value.starts_with('"')
    {
        for part in split_top(&value[open + 1..value.len() - 1]) {
            if let Some((k, v)) = part.split_once(':') {
                let sub = if path.is_empty() {
                    k.trim().to_owned()
                } else {
                    format!("{path}.{}", k.trim())
                };
                walk(&sub, v, out);
            }
        }
        return;
    }
    out.push(Field {
        path: path.to_owned(),
        text: flag_words(value)
            .or_else(|| enum_words(value))
            .unwrap_or_else(|| value.to_owned()),
        value: number(value),
    });
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

/// A bitmask's `Debug` text (`MavModeFlag(A | B)`, `MavModeFlag(0x0)`) in words: `A | B`,
/// `none`; `None` for anything else.
fn flag_words(value: &str) -> Option<String> {
    let open = value.find('(')?;
    let name = &value[..open];
    let inner = value[open + 1..].strip_suffix(')')?;
    if name.is_empty() || !name.chars().all(|c| c.is_ascii_alphanumeric()) {
        return None;
    }
    Some(match inner.trim() {
        "0x0" | "" => "none".to_owned(),
        words => words
            .split('|')
            .map(|w| enum_words(w.trim()).unwrap_or_else(|| w.trim().to_owned()))
            .collect::<Vec<_>>()
            .join(", "),
    })
}

/// The fields of a message from its `Debug` text.
#[must_use]
pub fn fields_of_debug(debug: &str) -> Vec<Field> {
    let mut out = Vec::new();
    // Strip the enum variant: `NAME(NAME_DATA { .. })` -> `NAME_DATA { .. }`.
    let body = match (debug.find('('), debug.strip_suffix(')')) {
        (Some(open), Some(_)) => &debug[open + 1..debug.len() - 1],
        _ => debug,
    };
    walk("", body, &mut out);
    out
}

/// The fields of a decoded message.
#[must_use]
pub fn fields(msg: &vtol_link::dialect::MavMessage) -> Vec<Field> {
    fields_of_debug(&format!("{msg:?}"))
}

/// The number at `path` in a decoded message, if the path exists and holds a number.
#[must_use]
pub fn value_at(msg: &vtol_link::dialect::MavMessage, path: &str) -> Option<f64> {
    fields(msg)
        .into_iter()
        .find(|f| f.path == path)
        .and_then(|f| f.value)
}

#[cfg(test)]
mod tests {
    use super::*;
    use vtol_link::dialect::{self, MavMessage};

    #[test]
    fn scalar_and_array_fields_of_real_messages() {
        let msg = MavMessage::ATTITUDE(dialect::ATTITUDE_DATA {
            time_boot_ms: 1234,
            roll: 0.25,
            pitch: -0.5,
            yaw: 1.0,
            rollspeed: 0.0,
            pitchspeed: 0.0,
            yawspeed: 0.125,
        });
        assert_eq!(value_at(&msg, "roll"), Some(0.25));
        assert_eq!(value_at(&msg, "pitch"), Some(-0.5));
        assert_eq!(value_at(&msg, "time_boot_ms"), Some(1234.0));
        assert_eq!(value_at(&msg, "nope"), None);

        let q = dialect::ATTITUDE_QUATERNION_DATA {
            repr_offset_q: [0.5, 0.25, 0.0, -1.0],
            ..Default::default()
        };
        let msg = MavMessage::ATTITUDE_QUATERNION(q);
        assert_eq!(value_at(&msg, "repr_offset_q[1]"), Some(0.25));
        assert_eq!(value_at(&msg, "repr_offset_q[3]"), Some(-1.0));
    }

    #[test]
    fn enums_are_text_not_numbers() {
        let msg = MavMessage::HEARTBEAT(dialect::HEARTBEAT_DATA::default());
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
        let mut hb = dialect::HEARTBEAT_DATA {
            base_mode: dialect::MavModeFlag::MAV_MODE_FLAG_CUSTOM_MODE_ENABLED
                | dialect::MavModeFlag::MAV_MODE_FLAG_SAFETY_ARMED,
            ..Default::default()
        };
        let f = fields(&MavMessage::HEARTBEAT(hb.clone()));
        let t = &f
            .iter()
            .find(|f| f.path == "base_mode")
            .expect("base_mode")
            .text;
        assert!(!t.contains("MavModeFlag"), "{t}");
        assert_eq!(t, "safety armed, custom mode enabled");
        hb.base_mode = dialect::MavModeFlag::empty();
        let f = fields(&MavMessage::HEARTBEAT(hb));
        let t = &f
            .iter()
            .find(|f| f.path == "base_mode")
            .expect("base_mode")
            .text;
        assert_eq!(t, "none");
    }

    #[test]
    fn nested_and_quoted_text() {
        let f = fields_of_debug(r#"X(X_DATA { s: "a, b", inner: Y { k: 3 }, v: [1, 2] })"#);
        let paths: Vec<_> = f.iter().map(|f| f.path.as_str()).collect();
        assert_eq!(paths, ["s", "inner.k", "v[0]", "v[1]"]);
        assert_eq!(f[1].value, Some(3.0));
        assert_eq!(f[0].text, r#""a, b""#);
    }
}
