//! Which panels a figure has, in the frame the user chose: titles, axis labels, the series
//! (converted from the sources' NED/FRD) and their styles.

use plotters::style::RGBColor;

use super::{AltitudeRef, FlightData, Frame, Kind, Points};
use crate::log::LogError;

/// One panel: a title, the y axis' label and its lines.
pub(super) struct Panel {
    pub title: String,
    pub y_desc: String,
    pub lines: Vec<Line>,
    /// Vertical markers with a label (VTOL state changes).
    pub markers: Vec<(f64, String)>,
    /// The series are angles that wrap at ± this value: a jump of more is not drawn.
    pub wrap: Option<f64>,
}

/// One line of a panel.
pub(super) struct Line {
    pub label: String,
    pub points: Points,
    pub color: RGBColor,
    pub dash: Dash,
}

/// How a line is stroked, so that lines drawn over each other stay distinguishable.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(super) enum Dash {
    Solid,
    Dashed,
    Dotted,
}

impl Dash {
    /// On and off lengths in px; `None` for a solid line.
    pub fn pattern(self) -> Option<(f64, f64)> {
        match self {
            Dash::Solid => None,
            Dash::Dashed => Some((9.0, 5.0)),
            Dash::Dotted => Some((3.0, 4.0)),
        }
    }
}

/// Line colours: primary source, then the compared one.
const COLORS: [[RGBColor; 3]; 2] = [
    [
        RGBColor(0x1f, 0x5f, 0xbf),
        RGBColor(0xe3, 0x6c, 0x0a),
        RGBColor(0x2c, 0xa0, 0x2c),
    ],
    [
        RGBColor(0xd6, 0x27, 0x28),
        RGBColor(0x94, 0x67, 0xbd),
        RGBColor(0x8c, 0x56, 0x4b),
    ],
];
const DASHES: [Dash; 3] = [Dash::Solid, Dash::Dashed, Dash::Dotted];
/// Setpoints: grey, dashed.
pub(super) const SETPOINT_COLOR: RGBColor = RGBColor(0x50, 0x50, 0x50);

fn has(d: &FlightData, k: Kind) -> bool {
    match k {
        Kind::Attitude => d.attitude.is_some(),
        Kind::Position => d.position.is_some(),
        Kind::Pwm => d.pwm.is_some(),
        Kind::Inputs => d.inputs.is_some(),
        Kind::Transition => missing_for_transition(d).is_empty(),
        Kind::All => false,
    }
}

fn missing_for_transition(d: &FlightData) -> Vec<&'static str> {
    let mut missing = Vec::new();
    if d.attitude.is_none() {
        missing.push("pitch (ATTITUDE)");
    }
    if d.airspeed.is_none() {
        missing.push("airspeed (VFR_HUD)");
    }
    if d.altitude.is_none() {
        missing.push("altitude (GLOBAL_POSITION_INT, LOCAL_POSITION_NED or VFR_HUD)");
    }
    if d.pwm.is_none() && d.throttle.is_none() {
        missing.push("thrust (SERVO_OUTPUT_RAW or VFR_HUD throttle)");
    }
    missing
}

/// The figures `kind` stands for, each one a column; an error names what the sources lack.
pub(super) fn kinds_of(kind: Kind, sources: &[&FlightData]) -> Result<Vec<Kind>, LogError> {
    let any = |k: Kind| sources.iter().any(|d| has(d, k));
    if kind == Kind::All {
        let ks: Vec<Kind> = [Kind::Attitude, Kind::Position, Kind::Inputs, Kind::Pwm]
            .into_iter()
            .filter(|&k| any(k))
            .collect();
        if ks.is_empty() {
            return Err(LogError::Unsupported(
                "nothing to plot: no ATTITUDE, LOCAL_POSITION_NED or SERVO_OUTPUT_RAW from a vehicle".into(),
            ));
        }
        return Ok(ks);
    }
    if !any(kind) {
        let what = match kind {
            Kind::Attitude => "no ATTITUDE (or phi/theta/psi columns)".to_owned(),
            Kind::Position => "no LOCAL_POSITION_NED (or x/y/z columns)".to_owned(),
            Kind::Pwm => "no SERVO_OUTPUT_RAW (or pwm1..pwm5 columns)".to_owned(),
            Kind::Inputs => {
                "no control inputs: a simulate CSV (tau_phi, tau_theta, tau_psi, fz) or the twin's NAMED_VALUE_FLOAT TAU_PHI, TAU_THETA, TAU_PSI, FZ".to_owned()
            }
            Kind::Transition => format!("no {}", missing_for_transition(sources[0]).join(", no ")),
            Kind::All => unreachable!("handled above"),
        };
        return Err(LogError::Unsupported(format!(
            "cannot plot {}: {what}",
            kind.name()
        )));
    }
    Ok(vec![kind])
}

/// Where a series comes from in a source.
#[derive(Clone, Copy)]
enum Source {
    Att(usize),
    Pos(usize),
    Inp(usize),
    Pwm(usize),
    Airspeed,
    Altitude,
    Throttle,
}

impl Source {
    fn get(self, d: &FlightData) -> Option<&Points> {
        match self {
            Source::Att(i) => d.attitude.as_ref().map(|a| &a[i]),
            Source::Pos(i) => d.position.as_ref().map(|a| &a[i]),
            Source::Inp(i) => d.inputs.as_ref().map(|a| &a[i]),
            Source::Pwm(i) => d.pwm.as_ref().map(|a| &a[i]),
            Source::Airspeed => d.airspeed.as_ref(),
            Source::Altitude => d.altitude.as_ref().map(|a| &a.points),
            Source::Throttle => d.throttle.as_ref(),
        }
    }
}

/// One series of a panel before styling: its name and where it comes from.
struct Spec {
    name: String,
    get: Source,
    /// Multiplies the source's value (frame change, unit).
    scale: f64,
}

fn spec(name: impl Into<String>, get: Source, scale: f64) -> Spec {
    Spec {
        name: name.into(),
        get,
        scale,
    }
}

/// PWM series: (output index, label).
type Labelled = Vec<(usize, String)>;

/// The PWM series split into motors and the rest, each (output index, label): named by the
/// log's `SERVOn_FUNCTION` ([`crate::outputs`]) when it has them, else the twin's wiring.
fn pwm_series(sources: &[&FlightData]) -> (Labelled, Labelled) {
    let known = sources
        .iter()
        .map(|d| d.servo_functions)
        .find(|f| f.iter().any(Option::is_some));
    let Some(functions) = known else {
        let motors = vec![(0, "ESC 1".to_owned()), (1, "ESC 2".to_owned())];
        let rest = ["aileron L", "aileron R", "elevator"]
            .iter()
            .enumerate()
            .map(|(i, n)| (i + 2, (*n).to_owned()))
            .collect();
        return (motors, rest);
    };
    let (motors, rest): (Vec<_>, Vec<_>) = crate::outputs::outputs(&functions)
        .into_iter()
        .enumerate()
        .partition(|(_, o)| o.motor);
    let named = |v: Vec<(usize, crate::outputs::Output)>| -> Labelled {
        v.into_iter().map(|(i, o)| (i, o.name)).collect()
    };
    (named(motors), named(rest))
}

/// Panels of one figure, for every source (the compared one in other colours).
// A table with one arm per figure and frame, then the same styling for every panel: long,
// but read top to bottom like the figure it lays out.
pub(super) fn panels_for(
    kind: Kind,
    frame: Frame,
    sources: &[&FlightData],
    setpoint: Option<[f64; 3]>,
    t_end: f64,
) -> Vec<Panel> {
    let ned = frame == Frame::Ned;
    let deg = 180.0 / std::f64::consts::PI;
    // (title, y label, series, position axis for setpoints)
    let mut out: Vec<(String, String, Vec<Spec>, Option<usize>)> = Vec::new();
    let mut push = |title: &str, y: &str, s: Vec<Spec>, axis: Option<usize>| {
        out.push((title.to_owned(), y.to_owned(), s, axis));
    };
    use Source::{Airspeed, Altitude, Att, Inp, Pos, Pwm, Throttle};
    let att = Att;
    let pos = Pos;
    let inp = Inp;
    let pwm = Pwm;
    match (kind, ned) {
        (Kind::Attitude, true) => {
            push(
                "roll",
                "roll, NED (°)",
                vec![spec("roll", att(0), deg)],
                None,
            );
            push(
                "pitch",
                "pitch, NED (°)",
                vec![spec("pitch", att(1), deg)],
                None,
            );
            push("yaw", "yaw, NED (°)", vec![spec("yaw", att(2), deg)], None);
        }
        (Kind::Attitude, false) => {
            push("φ", "φ = −roll (rad)", vec![spec("φ", att(0), -1.0)], None);
            push("θ", "θ = pitch (rad)", vec![spec("θ", att(1), 1.0)], None);
            push("ψ", "ψ = −yaw (rad)", vec![spec("ψ", att(2), -1.0)], None);
        }
        (Kind::Position, true) => {
            push(
                "North",
                "North (m)",
                vec![spec("North", pos(0), 1.0)],
                Some(0),
            );
            push("East", "East (m)", vec![spec("East", pos(1), 1.0)], Some(1));
            push("Down", "Down (m)", vec![spec("Down", pos(2), 1.0)], Some(2));
        }
        (Kind::Position, false) => {
            push(
                "x",
                "x = −North (m)",
                vec![spec("x", pos(0), -1.0)],
                Some(0),
            );
            push("y", "y = East (m)", vec![spec("y", pos(1), 1.0)], Some(1));
            push(
                "z (up)",
                "z = −Down (m)",
                vec![spec("z", pos(2), -1.0)],
                Some(2),
            );
        }
        (Kind::Inputs, true) => {
            let y = [
                "roll, −τφ (rad/s²)",
                "pitch, τθ (rad/s²)",
                "yaw, −τψ (rad/s²)",
            ];
            for (i, (t, s)) in [
                ("roll input", -1.0),
                ("pitch input", 1.0),
                ("yaw input", -1.0),
            ]
            .into_iter()
            .enumerate()
            {
                push(
                    t,
                    y[i],
                    vec![spec(["−τφ", "τθ", "−τψ"][i], inp(i), s)],
                    None,
                );
            }
            push("thrust", "f_z (N)", vec![spec("f_z", inp(3), 1.0)], None);
        }
        (Kind::Inputs, false) => {
            for (i, n) in ["τφ", "τθ", "τψ"].into_iter().enumerate() {
                push(
                    n,
                    &format!("{n} (rad/s²)"),
                    vec![spec(n, inp(i), 1.0)],
                    None,
                );
            }
            push("f_z", "f_z (N)", vec![spec("f_z", inp(3), 1.0)], None);
        }
        (Kind::Pwm, _) => {
            let (motors, surfaces) = pwm_series(sources);
            let esc = motors
                .into_iter()
                .map(|(i, n)| spec(n, pwm(i), 1.0))
                .collect();
            push("rotors", "ESC PWM (µs)", esc, None);
            let surfaces = surfaces
                .into_iter()
                .map(|(i, n)| spec(n, pwm(i), 1.0))
                .collect();
            push("control surfaces", "servo PWM (µs)", surfaces, None);
        }
        (Kind::Transition, _) => {
            if ned {
                push(
                    "pitch",
                    "pitch, NED (°)",
                    vec![spec("pitch", att(1), deg)],
                    None,
                );
            } else {
                push("θ", "θ = pitch (rad)", vec![spec("θ", att(1), 1.0)], None);
            }
            let airspeed = spec("airspeed", Airspeed, 1.0);
            push("airspeed", "true airspeed (m/s)", vec![airspeed], None);
            let reference = sources
                .iter()
                .find_map(|d| d.altitude.as_ref().map(|a| a.reference));
            let y = match reference {
                Some(AltitudeRef::Home) => "altitude above home (m)",
                Some(AltitudeRef::Origin) => "altitude, −Down (m)",
                _ => "altitude AMSL (m)",
            };
            let alt = spec("altitude", Altitude, 1.0);
            push("altitude", y, vec![alt], None);
            if sources.iter().any(|d| d.pwm.is_some()) {
                let (motors, _) = pwm_series(sources);
                let esc = motors
                    .into_iter()
                    .map(|(i, n)| spec(n, pwm(i), 1.0))
                    .collect();
                push("thrust", "ESC PWM (µs)", esc, None);
            } else {
                let thr = spec("throttle", Throttle, 1.0);
                push("thrust", "throttle (%)", vec![thr], None);
            }
        }
        (Kind::All, _) => {}
    }
    let several = sources.len() > 1;
    let markers: Vec<(f64, String)> = if kind == Kind::Transition {
        sources[0].vtol_states.clone()
    } else {
        Vec::new()
    };
    out.into_iter()
        .map(|(title, y_desc, specs, axis)| {
            let mut lines = Vec::new();
            for (si, d) in sources.iter().enumerate() {
                for (li, s) in specs.iter().enumerate() {
                    let Some(p) = s.get.get(d) else { continue };
                    if p.is_empty() {
                        continue;
                    }
                    lines.push(Line {
                        label: if several {
                            format!("{} ({})", s.name, d.label)
                        } else {
                            s.name.clone()
                        },
                        points: p.iter().map(|&(t, v)| (t, v * s.scale)).collect(),
                        color: COLORS[si.min(1)][li % 3],
                        dash: DASHES[(li + si) % 3],
                    });
                }
                // the vehicle's own position target, where the log has one
                if let (Some(i), Some(sp)) = (axis, d.setpoint.as_ref())
                    && !sp[i].is_empty()
                {
                    let scale = specs[0].scale;
                    lines.push(Line {
                        label: format!("{} target", specs[0].name),
                        points: sp[i].iter().map(|&(t, v)| (t, v * scale)).collect(),
                        color: SETPOINT_COLOR,
                        dash: Dash::Dashed,
                    });
                }
            }
            if let (Some(i), Some(sp)) = (axis, setpoint) {
                lines.push(Line {
                    label: "setpoint".to_owned(),
                    points: vec![(0.0, sp[i]), (t_end, sp[i])],
                    color: SETPOINT_COLOR,
                    dash: Dash::Dashed,
                });
            }
            let wrap = (matches!(kind, Kind::Attitude) && y_desc.contains("yaw"))
                .then_some(if ned { 180.0 } else { std::f64::consts::PI });
            Panel {
                title,
                y_desc,
                lines,
                markers: markers.clone(),
                wrap,
            }
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::{FlightData, pwm_series};

    #[test]
    fn pwm_series_are_named_by_the_logs_servo_functions() {
        let plain = FlightData::default();
        let (motors, rest) = pwm_series(&[&plain]);
        assert_eq!(motors[0].1, "ESC 1");
        assert_eq!(rest[2].1, "elevator");
        // ArduPlane's tailsitter: elevons on 1 and 2, the throttles on 3 and 4.
        let plane = FlightData {
            servo_functions: [Some(77.0), Some(78.0), Some(73.0), Some(74.0), None],
            ..FlightData::default()
        };
        let (motors, rest) = pwm_series(&[&plain, &plane]);
        assert_eq!(
            motors,
            [(2, "left motor".to_owned()), (3, "right motor".to_owned())]
        );
        assert_eq!(
            rest,
            [
                (0, "left elevon".to_owned()),
                (1, "right elevon".to_owned()),
                (4, "SERVO5".to_owned())
            ]
        );
    }
}
