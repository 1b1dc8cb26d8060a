//! Parameter sets as a ground station holds them: the value table ([`ParamSet`]), the three
//! file formats ([`file`]), the difference between two sets ([`diff`]) and the transactional
//! upload planner ([`plan`]). Everything here is pure: no I/O beyond reading and writing files.

pub mod file;
pub mod plan;

use std::collections::BTreeMap;

pub use file::{FileError, Format};
pub use plan::{ParamOutcome, PushReport, Rules, TwinRules, order_writes};
pub use vtol_link::dialect::MavParamType;

/// One parameter: its value as the vehicle sends it (a float32, integers C-cast) and its type.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Param {
    /// The value on the wire.
    pub value: f32,
    /// How the vehicle stores it.
    pub ty: MavParamType,
}

/// A parameter table, ordered by name: what a pull returns and what a file holds.
pub type ParamSet = BTreeMap<String, Param>;

/// The value a vehicle stores for a write of `value` to a parameter of type `ty`: integers are
/// rounded to nearest and held to the type's range (ArduPilot clamps, and truncates after
/// adding 0.01, which agrees for every whole number), floats are kept as float32.
/// A write is confirmed only by an echo equal to this.
#[must_use]
pub fn stored_value(ty: MavParamType, value: f32) -> f32 {
    match integer_range(ty) {
        Some((lo, hi)) => value.round().clamp(lo, hi),
        None => value,
    }
}

/// The range of an integer parameter type (as float32s), `None` for floats.
#[must_use]
pub fn integer_range(ty: MavParamType) -> Option<(f32, f32)> {
    use MavParamType as T;
    Some(match ty {
        T::MAV_PARAM_TYPE_UINT8 => (0.0, f32::from(u8::MAX)),
        T::MAV_PARAM_TYPE_INT8 => (f32::from(i8::MIN), f32::from(i8::MAX)),
        T::MAV_PARAM_TYPE_UINT16 => (0.0, f32::from(u16::MAX)),
        T::MAV_PARAM_TYPE_INT16 => (f32::from(i16::MIN), f32::from(i16::MAX)),
        T::MAV_PARAM_TYPE_UINT32 => (0.0, u32::MAX as f32),
        T::MAV_PARAM_TYPE_INT32 => (i32::MIN as f32, i32::MAX as f32),
        T::MAV_PARAM_TYPE_UINT64 => (0.0, u64::MAX as f32),
        T::MAV_PARAM_TYPE_INT64 => (i64::MIN as f32, i64::MAX as f32),
        _ => return None,
    })
}

/// Whether a parameter type holds integers.
#[must_use]
pub fn is_integer(ty: MavParamType) -> bool {
    !matches!(
        ty,
        MavParamType::MAV_PARAM_TYPE_REAL32 | MavParamType::MAV_PARAM_TYPE_REAL64
    )
}

/// Two wire values are the same parameter value: equal as float32s, or apart by no more than
/// float32's own rounding (a relative `f32::EPSILON`), which is how ArduPilot's `is_equal`
/// and QGroundControl compare a value read back. A value written is compared as the float32
/// the vehicle holds (0.26 is 0.25999999), never as the decimal or a float64.
#[must_use]
pub fn same_value(a: f32, b: f32) -> bool {
    a.to_bits() == b.to_bits() || a == b || (a - b).abs() <= f32::EPSILON * a.abs().max(b.abs())
}

/// One difference between the vehicle and a wanted set.
#[derive(Debug, Clone, PartialEq)]
pub struct Change {
    /// Parameter id.
    pub name: String,
    /// Value now on the vehicle.
    pub old: f32,
    /// Wanted value (already as the vehicle will store it).
    pub new: f32,
    /// The vehicle's type for it.
    pub ty: MavParamType,
}

/// The changes that turn `current` into `wanted`, in name order. Names in `wanted` that
/// `current` lacks are not changes: [`unknown_names`] reports them (a push refuses them).
/// The wanted value is compared after the vehicle's type conversion, so `5.0` for an integer
/// parameter holding 5 is no change.
#[must_use]
pub fn diff(current: &ParamSet, wanted: &ParamSet) -> Vec<Change> {
    wanted
        .iter()
        .filter_map(|(name, w)| {
            let c = current.get(name)?;
            let new = stored_value(c.ty, w.value);
            (!same_value(c.value, new)).then(|| Change {
                name: name.clone(),
                old: c.value,
                new,
                ty: c.ty,
            })
        })
        .collect()
}

/// Names of `wanted` the vehicle (`current`) does not have.
#[must_use]
pub fn unknown_names(current: &ParamSet, wanted: &ParamSet) -> Vec<String> {
    wanted
        .keys()
        .filter(|n| !current.contains_key(*n))
        .cloned()
        .collect()
}

/// A parameter name the vehicle can carry: 1–16 printable ASCII characters, no spaces, and
/// neither `,` nor `#`, which would split or end the name's line in a parameter file.
#[must_use]
pub fn valid_name(name: &str) -> bool {
    (1..=16).contains(&name.len())
        && name
            .bytes()
            .all(|b| b.is_ascii_graphic() && b != b',' && b != b'#')
}

#[cfg(test)]
mod tests {
    use super::*;

    fn set(items: &[(&str, f32, MavParamType)]) -> ParamSet {
        items
            .iter()
            .map(|(n, v, t)| ((*n).to_owned(), Param { value: *v, ty: *t }))
            .collect()
    }

    #[test]
    fn diff_compares_after_the_vehicle_conversion() {
        use MavParamType::{MAV_PARAM_TYPE_INT16 as I16, MAV_PARAM_TYPE_REAL32 as F32};
        let current = set(&[("A", 5.0, I16), ("B", 0.1, F32), ("C", 1.0, F32)]);
        let wanted = set(&[
            ("A", 5.2, F32),
            ("B", 0.1, F32),
            ("C", 1.5, F32),
            ("X", 1.0, F32),
        ]);
        let d = diff(&current, &wanted);
        assert_eq!(d.len(), 1, "{d:?}");
        assert_eq!(d[0].name, "C");
        assert_eq!((d[0].old, d[0].new), (1.0, 1.5));
        assert_eq!(unknown_names(&current, &wanted), vec!["X".to_owned()]);
    }

    #[test]
    fn float32_rounding_is_no_difference_and_a_real_change_is() {
        let v: f64 = 0.26;
        // The float32 nearest 0.26 against the float32 of that float64 printed and re-read.
        assert!(same_value(
            v as f32,
            (v as f32).to_string().parse().unwrap()
        ));
        assert!(same_value(0.26, f32::from_bits(0.26f32.to_bits() + 1)));
        assert!(!same_value(0.26, 0.2601));
        assert!(!same_value(0.25, 0.26));
        assert!(!same_value(0.0, 1e-30));
    }

    #[test]
    fn integer_writes_round_like_the_vehicle() {
        assert_eq!(
            stored_value(MavParamType::MAV_PARAM_TYPE_INT8, 300.0),
            127.0
        );
        assert_eq!(
            stored_value(MavParamType::MAV_PARAM_TYPE_INT16, -4e4),
            -32768.0
        );
        assert_eq!(stored_value(MavParamType::MAV_PARAM_TYPE_INT8, 0.6), 1.0);
        let v = 0.1f32;
        assert_eq!(
            stored_value(MavParamType::MAV_PARAM_TYPE_REAL32, v).to_bits(),
            v.to_bits()
        );
    }
}
