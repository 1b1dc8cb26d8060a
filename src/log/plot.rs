//! `log plot`: PNG figures in the layout of the paper (Escareño, Salazar & Lozano, CDC 2006):
//! attitude φ, θ, ψ stacked (Fig. 3, and the angle panels of Figs. 8–10), position x, y, z
//! against the setpoint (Fig. 4), control inputs τφ, τθ, τψ, f_z (Fig. 5) and PWM (the PWM
//! panels of Figs. 8–10).
//!
//! Sources are tlogs (ATTITUDE, LOCAL_POSITION_NED, SERVO_OUTPUT_RAW and the twin's controller
//! outputs as NAMED_VALUE_FLOAT, from the vehicle) and `firmware-sim simulate` CSV. Both are drawn in the paper's frames (inertial z up, η = (ψ, θ,
//! φ)): a tlog's NED/FRD values go through the twin's own frame map, so an offline flight and
//! a logged one compare on the same axes (`--compare`).
//!
//! Text is drawn with a bundled DejaVu Sans through plotters' ab_glyph backend: no system font
//! library is needed. Series longer than the plot is wide are reduced to each pixel column's
//! minimum and maximum, which draws the same picture in a fraction of the time.

use std::path::{Path, PathBuf};
use std::sync::OnceLock;

use firmware_sim::model::frames::Euler;
use firmware_sim::model::frames::{euler_to_ned_rpy, ned_to_paper};
use nalgebra::Vector3;
use plotters::prelude::*;
use plotters::style::FontStyle;
use vtol_link::protocol::CONTROLLER_OUTPUT_NAMES;

use super::{LogError, finish_read, open_tlog};

/// Which figure.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum Kind {
    /// φ, θ, ψ (Fig. 3).
    Attitude,
    /// x, y, z against the setpoint (Fig. 4).
    Position,
    /// ESC and control-surface PWM (Figs. 8–10).
    Pwm,
    /// Control inputs τφ, τθ, τψ and f_z (Fig. 5; simulate CSV only).
    Inputs,
    /// Every figure the source has, one column each.
    All,
}

/// One time series, s against the panel's unit.
pub type Points = Vec<(f64, f64)>;

/// What a source holds for the figures, in the paper's frames and SI units.
#[derive(Debug, Clone, Default)]
pub struct FlightData {
    /// Legend name (the file name).
    pub label: String,
    /// φ, θ, ψ in rad.
    pub attitude: Option<[Points; 3]>,
    /// x, y, z in m (z up).
    pub position: Option<[Points; 3]>,
    /// PWM 1..5 in µs (ESC 1, ESC 2, aileron L, aileron R, elevator).
    pub pwm: Option<[Points; 5]>,
    /// τφ, τθ, τψ in rad/s², f_z in N.
    pub inputs: Option<[Points; 4]>,
}

/// Options of one figure.
#[derive(Debug, Clone)]
pub struct PlotOptions {
    /// Which figure.
    pub kind: Kind,
    /// Picture size, px; `None` picks one for the kind.
    pub size: Option<(u32, u32)>,
    /// Position setpoint (x, y, z), m, paper frame: drawn dashed on the position panels.
    pub setpoint: [f64; 3],
    /// Figure title; `None` names the kind and the source.
    pub title: Option<String>,
}

const FONT: &str = "sans-serif";
static FONT_BYTES: &[u8] = include_bytes!("../../assets/fonts/DejaVuSans.ttf");

fn register_font() -> Result<(), LogError> {
    static DONE: OnceLock<bool> = OnceLock::new();
    let ok = *DONE.get_or_init(|| {
        plotters::style::register_font(FONT, FontStyle::Normal, FONT_BYTES).is_ok()
    });
    if ok {
        Ok(())
    } else {
        Err(LogError::Unsupported(
            "the bundled font does not load".into(),
        ))
    }
}

/// Reads a tlog or a `firmware-sim simulate` CSV (recognised by its `t,` header).
///
/// # Errors
/// The file cannot be read, or a CSV lacks the simulate columns.
pub fn load(path: &Path) -> Result<FlightData, LogError> {
    let mut head = [0u8; 2];
    let n = {
        use std::io::Read;
        let mut f = std::fs::File::open(path).map_err(|source| LogError::Read {
            path: path.to_owned(),
            source,
        })?;
        f.read(&mut head).map_err(|source| LogError::Read {
            path: path.to_owned(),
            source,
        })?
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
        for group in [&att, &pos, &pwm, &inp].into_iter().flatten() {
            for &i in group {
                cols[i].push((t, num(i)?));
            }
        }
    }
    let take = |idx: &Option<Vec<usize>>, cols: &mut Vec<Points>| -> Option<Vec<Points>> {
        idx.as_ref()
            .map(|v| v.iter().map(|&i| std::mem::take(&mut cols[i])).collect())
    };
    let to3 = |v: Vec<Points>| -> Option<[Points; 3]> { v.try_into().ok() };
    Ok(FlightData {
        label: String::new(),
        attitude: take(&att, &mut cols).and_then(to3),
        position: take(&pos, &mut cols).and_then(to3),
        pwm: take(&pwm, &mut cols).and_then(|v| v.try_into().ok()),
        inputs: take(&inp, &mut cols).and_then(|v| v.try_into().ok()),
    })
}

fn load_tlog(path: &Path) -> Result<FlightData, LogError> {
    use vtol_link::dialect::MavMessage as M;
    let (mut reader, _) = open_tlog(path)?;
    let mut att: [Points; 3] = Default::default();
    let mut pos: [Points; 3] = Default::default();
    let mut pwm: [Points; 5] = Default::default();
    let mut inputs: [Points; 4] = Default::default();
    let mut start = None;
    // The figures show one vehicle: the first system that sends one of these messages.
    let mut vehicle: Option<u8> = None;
    // ATTITUDE, LOCAL_POSITION_NED, SERVO_OUTPUT_RAW, NAMED_VALUE_FLOAT
    const WANTED: [u32; 4] = [30, 32, 36, 251];
    for (stamp, frame) in reader.by_ref() {
        let start = *start.get_or_insert(stamp);
        if stamp & 3 == 3 || !WANTED.contains(&frame.message_id()) {
            continue;
        }
        if *vehicle.get_or_insert(frame.system_id()) != frame.system_id() {
            continue;
        }
        let t = stamp.saturating_sub(start) as f64 * 1e-6;
        match frame.decode() {
            Ok(M::ATTITUDE(a)) => {
                // MAVLink roll, pitch, yaw (NED/FRD) back to the paper's φ, θ, ψ; the map is
                // its own inverse up to the sign of each angle.
                let [phi, theta, psi] = euler_to_ned_rpy(&Euler::new(
                    f64::from(a.yaw),
                    f64::from(a.pitch),
                    f64::from(a.roll),
                ));
                att[0].push((t, phi));
                att[1].push((t, theta));
                att[2].push((t, psi));
            }
            Ok(M::LOCAL_POSITION_NED(p)) => {
                let v = ned_to_paper(&Vector3::new(
                    f64::from(p.x),
                    f64::from(p.y),
                    f64::from(p.z),
                ));
                for (i, s) in pos.iter_mut().enumerate() {
                    s.push((t, v[i]));
                }
            }
            // The twin's controller outputs τ̃φ, τ̃θ, τ̃ψ, f_z (already in the paper's frame).
            Ok(M::NAMED_VALUE_FLOAT(n)) => {
                let name = n.name.to_str().unwrap_or("");
                if let Some(i) = CONTROLLER_OUTPUT_NAMES.iter().position(|c| *c == name) {
                    inputs[i].push((t, f64::from(n.value)));
                }
            }
            Ok(M::SERVO_OUTPUT_RAW(s)) => {
                let raw = [
                    s.servo1_raw,
                    s.servo2_raw,
                    s.servo3_raw,
                    s.servo4_raw,
                    s.servo5_raw,
                ];
                for (i, v) in raw.into_iter().enumerate() {
                    pwm[i].push((t, f64::from(v)));
                }
            }
            _ => {}
        }
    }
    finish_read(&mut reader, path)?;
    let some = |v: &[Points]| v.iter().any(|s| !s.is_empty());
    Ok(FlightData {
        label: String::new(),
        attitude: some(&att).then_some(att),
        position: some(&pos).then_some(pos),
        pwm: some(&pwm).then_some(pwm),
        inputs: some(&inputs).then_some(inputs),
    })
}

/// One panel: a title, a unit and its lines.
struct Panel<'a> {
    title: &'static str,
    unit: &'static str,
    lines: Vec<Line<'a>>,
}

struct Line<'a> {
    label: String,
    points: &'a [(f64, f64)],
    color: RGBColor,
}

/// Line colours: primary source, then the compared one.
const COLORS: [[RGBColor; 3]; 2] = [
    [
        RGBColor(0x1f, 0x5f, 0xbf),
        RGBColor(0x2c, 0xa0, 0x2c),
        RGBColor(0x94, 0x67, 0xbd),
    ],
    [
        RGBColor(0xd6, 0x27, 0x28),
        RGBColor(0xff, 0x7f, 0x0e),
        RGBColor(0x8c, 0x56, 0x4b),
    ],
];
const SETPOINT_COLOR: RGBColor = RGBColor(0x50, 0x50, 0x50);

fn kinds_of(kind: Kind, sources: &[&FlightData]) -> Result<Vec<Kind>, LogError> {
    let has = |k: Kind| {
        sources.iter().any(|d| match k {
            Kind::Attitude => d.attitude.is_some(),
            Kind::Position => d.position.is_some(),
            Kind::Pwm => d.pwm.is_some(),
            Kind::Inputs => d.inputs.is_some(),
            Kind::All => false,
        })
    };
    if kind == Kind::All {
        let ks: Vec<Kind> = [Kind::Attitude, Kind::Position, Kind::Inputs, Kind::Pwm]
            .into_iter()
            .filter(|&k| has(k))
            .collect();
        if ks.is_empty() {
            return Err(LogError::Unsupported(
                "nothing to plot: no ATTITUDE, LOCAL_POSITION_NED or SERVO_OUTPUT_RAW from a vehicle".into(),
            ));
        }
        return Ok(ks);
    }
    if !has(kind) {
        let what = match kind {
            Kind::Attitude => "no ATTITUDE (or phi/theta/psi columns)",
            Kind::Position => "no LOCAL_POSITION_NED (or x/y/z columns)",
            Kind::Pwm => "no SERVO_OUTPUT_RAW (or pwm1..pwm5 columns)",
            Kind::Inputs => {
                "no control inputs: a simulate CSV (tau_phi, tau_theta, tau_psi, fz) or the twin's NAMED_VALUE_FLOAT TAU_PHI, TAU_THETA, TAU_PSI, FZ"
            }
            Kind::All => unreachable!("handled above"),
        };
        let name = format!("{kind:?}").to_lowercase();
        return Err(LogError::Unsupported(format!("cannot plot {name}: {what}")));
    }
    Ok(vec![kind])
}

fn panels_for<'a>(kind: Kind, sources: &[&'a FlightData]) -> Vec<Panel<'a>> {
    let spec: &[(&'static str, &'static str, &[usize], &[&'static str])] = match kind {
        Kind::Attitude => &[
            ("φ (roll)", "rad", &[0], &["φ"]),
            ("θ (pitch)", "rad", &[1], &["θ"]),
            ("ψ (yaw)", "rad", &[2], &["ψ"]),
        ],
        Kind::Position => &[
            ("x", "m", &[0], &["x"]),
            ("y", "m", &[1], &["y"]),
            ("z (up)", "m", &[2], &["z"]),
        ],
        Kind::Inputs => &[
            ("τφ", "rad/s²", &[0], &["τφ"]),
            ("τθ", "rad/s²", &[1], &["τθ"]),
            ("τψ", "rad/s²", &[2], &["τψ"]),
            ("f_z", "N", &[3], &["f_z"]),
        ],
        Kind::Pwm => &[
            ("rotors (ESC 1, ESC 2)", "µs", &[0, 1], &["ESC 1", "ESC 2"]),
            (
                "control surfaces",
                "µs",
                &[2, 3, 4],
                &["aileron L", "aileron R", "elevator"],
            ),
        ],
        Kind::All => &[],
    };
    let series = |d: &'a FlightData, i: usize| -> Option<&'a Points> {
        match kind {
            Kind::Attitude => d.attitude.as_ref().map(|a| &a[i]),
            Kind::Position => d.position.as_ref().map(|a| &a[i]),
            Kind::Inputs => d.inputs.as_ref().map(|a| &a[i]),
            Kind::Pwm => d.pwm.as_ref().map(|a| &a[i]),
            Kind::All => None,
        }
    };
    let several = sources.len() > 1;
    spec.iter()
        .map(|(title, unit, idx, names)| {
            let mut lines = Vec::new();
            for (si, d) in sources.iter().enumerate() {
                for (li, (&i, name)) in idx.iter().zip(names.iter()).enumerate() {
                    if let Some(p) = series(d, i) {
                        let label = if several {
                            format!("{name} ({})", d.label)
                        } else {
                            (*name).to_owned()
                        };
                        lines.push(Line {
                            label,
                            points: p,
                            color: COLORS[si.min(1)][li.min(2)],
                        });
                    }
                }
            }
            Panel { title, unit, lines }
        })
        .collect()
}

/// Min/max per pixel column: the same picture as every point, with at most 2 per column.
fn decimate(points: &[(f64, f64)], x0: f64, x1: f64, columns: usize) -> Points {
    if points.len() <= columns * 4 || x1 <= x0 {
        return points.to_vec();
    }
    let mut out = Vec::with_capacity(columns * 2 + 2);
    let width = (x1 - x0) / columns as f64;
    let mut i = 0;
    while i < points.len() {
        let col = ((points[i].0 - x0) / width).floor();
        let (mut lo, mut hi) = (points[i], points[i]);
        let mut j = i + 1;
        while j < points.len() && ((points[j].0 - x0) / width).floor() == col {
            if points[j].1 < lo.1 {
                lo = points[j];
            }
            if points[j].1 > hi.1 {
                hi = points[j];
            }
            j += 1;
        }
        if lo.0 <= hi.0 {
            out.push(lo);
            if hi != lo {
                out.push(hi);
            }
        } else {
            out.push(hi);
            out.push(lo);
        }
        i = j;
    }
    out
}

fn draw_err(path: &Path, e: impl std::fmt::Display) -> LogError {
    LogError::Write {
        path: path.to_owned(),
        message: e.to_string(),
    }
}

/// Draws the figure of `opts.kind` for `main` (and `compare`, on the same axes) into a PNG.
/// Returns the number of panels drawn.
///
/// # Errors
/// The sources lack what the figure needs, or the PNG cannot be written.
pub fn draw(
    main: &FlightData,
    compare: Option<&FlightData>,
    out: &Path,
    opts: &PlotOptions,
) -> Result<usize, LogError> {
    register_font()?;
    let sources: Vec<&FlightData> = std::iter::once(main).chain(compare).collect();
    let kinds = kinds_of(opts.kind, &sources)?;
    let columns: Vec<(Kind, Vec<Panel>)> = kinds
        .iter()
        .map(|&k| (k, panels_for(k, &sources)))
        .collect();
    let rows = columns.iter().map(|c| c.1.len()).max().unwrap_or(1);
    let (w, h) = opts.size.unwrap_or_else(|| {
        let cols = u32::try_from(columns.len()).unwrap_or(1);
        (760 * cols, 90 + 260 * u32::try_from(rows).unwrap_or(3))
    });
    let t_end = sources
        .iter()
        .flat_map(|d| {
            [
                d.attitude.as_ref().map(|a| a.as_slice()),
                d.position.as_ref().map(|a| a.as_slice()),
                d.pwm.as_ref().map(|a| a.as_slice()),
                d.inputs.as_ref().map(|a| a.as_slice()),
            ]
        })
        .flatten()
        .flatten()
        .filter_map(|s| s.last().map(|p| p.0))
        .fold(0.0_f64, f64::max)
        .max(1e-3);
    let title = opts.title.clone().unwrap_or_else(|| {
        let what = kinds
            .iter()
            .map(|k| format!("{k:?}").to_lowercase())
            .collect::<Vec<_>>()
            .join(", ");
        match compare {
            Some(c) => format!("{what}: {} vs {}", main.label, c.label),
            None => format!("{what}: {}", main.label),
        }
    });
    let root = BitMapBackend::new(out, (w, h)).into_drawing_area();
    root.fill(&WHITE).map_err(|e| draw_err(out, e))?;
    let root = root
        .titled(&title, (FONT, 26))
        .map_err(|e| draw_err(out, e))?;
    let col_areas = root.split_evenly((1, columns.len()));
    let mut drawn = 0;
    for ((kind, panels), col_area) in columns.iter().zip(col_areas) {
        let areas = col_area.split_evenly((rows, 1));
        for (i, (panel, area)) in panels.iter().zip(areas).enumerate() {
            let setpoint = (*kind == Kind::Position).then(|| opts.setpoint[i]);
            draw_panel(&area, panel, t_end, setpoint).map_err(|e| draw_err(out, e))?;
            drawn += 1;
        }
    }
    root.present().map_err(|e| draw_err(out, e))?;
    Ok(drawn)
}

fn draw_panel<DB: DrawingBackend>(
    area: &DrawingArea<DB, plotters::coord::Shift>,
    panel: &Panel,
    t_end: f64,
    setpoint: Option<f64>,
) -> Result<(), DrawingAreaErrorKind<DB::ErrorType>> {
    let (pw, _) = area.dim_in_pixel();
    let columns = usize::try_from(pw).unwrap_or(800).max(1);
    let data: Vec<(Points, &Line)> = panel
        .lines
        .iter()
        .map(|l| (decimate(l.points, 0.0, t_end, columns), l))
        .collect();
    let (mut lo, mut hi) = data
        .iter()
        .flat_map(|(p, _)| p.iter().map(|q| q.1))
        .chain(setpoint)
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), v| {
            (a.min(v), b.max(v))
        });
    if !lo.is_finite() || !hi.is_finite() {
        (lo, hi) = (-1.0, 1.0);
    }
    let pad = if hi - lo < 1e-9 {
        lo.abs().max(1.0) * 0.05
    } else {
        (hi - lo) * 0.08
    };
    let mut chart = ChartBuilder::on(area)
        .caption(panel.title, (FONT, 20))
        .margin(10)
        .x_label_area_size(38)
        .y_label_area_size(72)
        .build_cartesian_2d(0.0..t_end, (lo - pad)..(hi + pad))?;
    chart
        .configure_mesh()
        .x_desc("t (s)")
        .y_desc(panel.unit)
        .label_style((FONT, 15))
        .axis_desc_style((FONT, 16))
        .light_line_style(RGBColor(0xee, 0xee, 0xee))
        .draw()?;
    for (points, line) in &data {
        let color = line.color;
        chart
            .draw_series(LineSeries::new(
                points.iter().copied(),
                color.stroke_width(2),
            ))?
            .label(line.label.clone())
            .legend(move |(x, y)| {
                PathElement::new(vec![(x, y), (x + 22, y)], color.stroke_width(2))
            });
    }
    if let Some(sp) = setpoint {
        chart
            .draw_series(DashedLineSeries::new(
                [(0.0, sp), (t_end, sp)],
                8,
                6,
                SETPOINT_COLOR.stroke_width(1),
            ))?
            .label("setpoint")
            .legend(|(x, y)| PathElement::new(vec![(x, y), (x + 22, y)], SETPOINT_COLOR));
    }
    chart
        .configure_series_labels()
        .label_font((FONT, 15))
        .background_style(WHITE.mix(0.85))
        .border_style(RGBColor(0xaa, 0xaa, 0xaa))
        .position(SeriesLabelPosition::UpperRight)
        .draw()?;
    Ok(())
}

/// Where a figure goes when `-o` names a directory: `DIR/<kind>.png`.
#[must_use]
pub fn default_name(dir: &Path, kind: Kind) -> PathBuf {
    dir.join(format!("{}.png", format!("{kind:?}").to_lowercase()))
}
