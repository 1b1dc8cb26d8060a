//! Reading the sources of `log plot`: tlogs and `firmware-sim simulate` CSV, both into
//! [`FlightData`] in NED/FRD and SI units (the frame a figure is drawn in is chosen later).

use std::path::Path;

use vtol_link::protocol::{CONTROLLER_OUTPUT_NAMES, id};

use super::{Altitude, AltitudeRef, FlightData, Points};
use crate::log::{LogError, finish_read, open_tlog};
use crate::tracker::state::servo_outputs;

/// Reads a tlog or a `firmware-sim simulate` CSV (recognised by its `t,` header).
///
/// # Errors
/// The file cannot be read, or a CSV lacks the simulate columns.
pub fn load(path: &Path) -> Result<FlightData, LogError> {
    let mut head = [0u8; 2];
    let n = {
        use std::io::Read;
        let read_err = |source| LogError::Read {
            path: path.to_owned(),
            source,
        };
        let mut f = std::fs::File::open(path).map_err(read_err)?;
        f.read(&mut head).map_err(read_err)?
    };
    let mut data = if n == 2 && &head == b"t," {
        load_csv(path)?
    } else {
        load_tlog(path)?
    };
    data.label = path.file_name().map_or_else(
        || path.display().to_string(),
        |f| f.to_string_lossy().into_owned(),
    );
    Ok(data)
}

/// A simulate CSV is in the paper's frames (inertial z up, φ θ ψ); it is turned into NED/FRD
/// with the twin's frame map (x = −North, y = East, z = −Down; roll = −φ, pitch = θ, yaw = −ψ).
fn load_csv(path: &Path) -> Result<FlightData, LogError> {
    let csv_err = |message: String| LogError::Csv {
        path: path.to_owned(),
        message,
    };
    let mut r = csv::Reader::from_path(path).map_err(|e| csv_err(e.to_string()))?;
    let header = r.headers().map_err(|e| csv_err(e.to_string()))?.clone();
    let col = |name: &str| header.iter().position(|h| h == name);
    let need = |names: &[&str]| -> Option<Vec<usize>> { names.iter().map(|n| col(n)).collect() };
    let t_col = col("t").ok_or_else(|| csv_err("no column t".into()))?;
    let att = need(&["phi", "theta", "psi"]);
    let pos = need(&["x", "y", "z"]);
    let pwm = need(&["pwm1", "pwm2", "pwm3", "pwm4", "pwm5"]);
    let inp = need(&["tau_phi", "tau_theta", "tau_psi", "fz"]);
    // paper → NED/FRD, per column of each group
    let signs: [(&Option<Vec<usize>>, &[f64]); 4] = [
        (&att, &[-1.0, 1.0, -1.0]),
        (&pos, &[-1.0, 1.0, -1.0]),
        (&pwm, &[1.0; 5]),
        (&inp, &[1.0; 4]),
    ];
    let mut cols: Vec<Points> = vec![Vec::new(); header.len()];
    for (line, rec) in r.records().enumerate() {
        let rec = rec.map_err(|e| csv_err(e.to_string()))?;
        let num = |i: usize| -> Result<f64, LogError> {
            let s = rec.get(i).unwrap_or("");
            s.trim()
                .parse::<f64>()
                .ok()
                .filter(|v| v.is_finite())
                .ok_or_else(|| {
                    csv_err(format!(
                        "row {}: column {} is '{s}', not a finite number",
                        line + 2,
                        &header[i]
                    ))
                })
        };
        let t = num(t_col)?;
        for (group, sign) in signs {
            for (&i, s) in group.iter().flatten().zip(sign) {
                cols[i].push((t, s * num(i)?));
            }
        }
    }
    let mut take = |idx: &Option<Vec<usize>>| -> Option<Vec<Points>> {
        idx.as_ref()
            .map(|v| v.iter().map(|&i| std::mem::take(&mut cols[i])).collect())
    };
    let position: Option<[Points; 3]> = take(&pos).and_then(|v| v.try_into().ok());
    let altitude = position.as_ref().map(|p| Altitude {
        reference: AltitudeRef::Origin,
        points: p[2].iter().map(|&(t, d)| (t, -d)).collect(),
    });
    Ok(FlightData {
        attitude: take(&att).and_then(|v| v.try_into().ok()),
        position,
        altitude,
        pwm: take(&pwm).and_then(|v| v.try_into().ok()),
        inputs: take(&inp).and_then(|v| v.try_into().ok()),
        ..FlightData::default()
    })
}

/// What a tlog scan collects before it becomes a [`FlightData`].
#[derive(Default)]
struct Scan {
    att: [Points; 3],
    pos: [Points; 3],
    target: [Points; 3],
    pwm: [Points; 5],
    inputs: [Points; 4],
    airspeed: Points,
    throttle: Points,
    rel_alt: Points,
    amsl_alt: Points,
    vtol: Vec<(f64, String)>,
    servo_functions: [Option<f32>; 5],
}

impl Scan {
    fn message(&mut self, t: f64, msg: vtol_link::dialect::MavMessage) {
        use vtol_link::dialect::MavMessage as M;
        use vtol_link::dialect::PositionTargetTypemask as Mask;
        match msg {
            M::ATTITUDE(a) => {
                for (s, v) in self.att.iter_mut().zip([a.roll, a.pitch, a.yaw]) {
                    s.push((t, f64::from(v)));
                }
            }
            M::LOCAL_POSITION_NED(p) => {
                for (s, v) in self.pos.iter_mut().zip([p.x, p.y, p.z]) {
                    s.push((t, f64::from(v)));
                }
            }
            // The vehicle's own position target: the setpoint, where the log has one.
            M::POSITION_TARGET_LOCAL_NED(p) => {
                let ignore = [
                    Mask::POSITION_TARGET_TYPEMASK_X_IGNORE,
                    Mask::POSITION_TARGET_TYPEMASK_Y_IGNORE,
                    Mask::POSITION_TARGET_TYPEMASK_Z_IGNORE,
                ];
                for ((s, v), bit) in self.target.iter_mut().zip([p.x, p.y, p.z]).zip(ignore) {
                    if !p.type_mask.contains(bit) {
                        s.push((t, f64::from(v)));
                    }
                }
            }
            // The twin's controller outputs τ̃φ, τ̃θ, τ̃ψ, f_z (the paper's quantities).
            M::NAMED_VALUE_FLOAT(n) => {
                let name = n.name.to_str().unwrap_or("");
                if let Some(i) = CONTROLLER_OUTPUT_NAMES.iter().position(|c| *c == name) {
                    self.inputs[i].push((t, f64::from(n.value)));
                }
            }
            // What the outputs drive, for the PWM legends.
            M::PARAM_VALUE(p) => {
                let name = p.param_id.to_str().unwrap_or("");
                if let Some(n) = name
                    .strip_prefix("SERVO")
                    .and_then(|r| r.strip_suffix("_FUNCTION"))
                    .and_then(|n| n.parse::<usize>().ok())
                    .filter(|n| (1..=5).contains(n))
                {
                    self.servo_functions[n - 1] = Some(p.param_value);
                }
            }
            M::SERVO_OUTPUT_RAW(s) => {
                // The first five outputs: zip stops at the five series.
                for (p, v) in self.pwm.iter_mut().zip(servo_outputs(&s)) {
                    p.push((t, f64::from(v)));
                }
            }
            M::VFR_HUD(h) => {
                self.airspeed.push((t, f64::from(h.airspeed)));
                self.throttle.push((t, f64::from(h.throttle)));
                self.amsl_alt.push((t, f64::from(h.alt)));
            }
            M::GLOBAL_POSITION_INT(g) => self.rel_alt.push((t, f64::from(g.relative_alt) * 1e-3)),
            M::EXTENDED_SYS_STATE(e) => {
                // a vehicle that is no VTOL says UNDEFINED: nothing to mark
                if let Some(name) = vtol_state_name(e.vtol_state as u32)
                    && self.vtol.last().is_none_or(|(_, last)| last != name)
                {
                    self.vtol.push((t, name.to_owned()));
                }
            }
            _ => {}
        }
    }

    fn finish(self) -> FlightData {
        let some = |v: &[Points]| v.iter().any(|s| !s.is_empty());
        let altitude = if !self.rel_alt.is_empty() {
            Some(Altitude {
                reference: AltitudeRef::Home,
                points: self.rel_alt,
            })
        } else if !self.pos[2].is_empty() {
            Some(Altitude {
                reference: AltitudeRef::Origin,
                points: self.pos[2].iter().map(|&(t, d)| (t, -d)).collect(),
            })
        } else if !self.amsl_alt.is_empty() {
            Some(Altitude {
                reference: AltitudeRef::Amsl,
                points: self.amsl_alt,
            })
        } else {
            None
        };
        FlightData {
            label: String::new(),
            attitude: some(&self.att).then_some(self.att),
            position: some(&self.pos).then_some(self.pos),
            setpoint: some(&self.target).then_some(self.target),
            pwm: some(&self.pwm).then_some(self.pwm),
            inputs: some(&self.inputs).then_some(self.inputs),
            airspeed: (!self.airspeed.is_empty()).then_some(self.airspeed),
            throttle: (!self.throttle.is_empty()).then_some(self.throttle),
            altitude,
            vtol_states: self.vtol,
            servo_functions: self.servo_functions,
        }
    }
}

/// EXTENDED_SYS_STATE's `vtol_state` as a short label for the figures.
fn vtol_state_name(v: u32) -> Option<&'static str> {
    use num_traits::FromPrimitive;
    use vtol_link::dialect::MavVtolState as S;
    match S::from_u32(v)? {
        S::MAV_VTOL_STATE_TRANSITION_TO_FW => Some("to FW"),
        S::MAV_VTOL_STATE_TRANSITION_TO_MC => Some("to MC"),
        S::MAV_VTOL_STATE_MC => Some("MC"),
        S::MAV_VTOL_STATE_FW => Some("FW"),
        S::MAV_VTOL_STATE_UNDEFINED => None,
    }
}

fn load_tlog(path: &Path) -> Result<FlightData, LogError> {
    let mut directions = super::super::directions(path)?;
    let (mut reader, _) = open_tlog(path)?;
    let mut scan = Scan::default();
    let mut start = None;
    // The figures show one vehicle: the first system that sends one of these messages.
    let mut vehicle: Option<u8> = None;
    const WANTED: [u32; 8] = [
        id::ATTITUDE,
        id::GLOBAL_POSITION_INT,
        id::LOCAL_POSITION_NED,
        id::SERVO_OUTPUT_RAW,
        id::VFR_HUD,
        id::POSITION_TARGET_LOCAL_NED,
        id::EXTENDED_SYS_STATE,
        id::NAMED_VALUE_FLOAT,
    ];
    for (stamp, frame) in reader.by_ref() {
        let start = *start.get_or_insert(stamp);
        if !WANTED.contains(&frame.message_id()) || directions.to_vehicle(stamp, &frame) {
            continue;
        }
        if *vehicle.get_or_insert(frame.system_id()) != frame.system_id() {
            continue;
        }
        let t = stamp.saturating_sub(start) as f64 * 1e-6;
        if let Ok(l) = frame.decode_lenient() {
            scan.message(t, l.msg);
        }
    }
    finish_read(&mut reader, path)?;
    Ok(scan.finish())
}
