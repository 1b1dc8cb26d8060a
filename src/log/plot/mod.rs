//! `log plot`: PNG figures in the layout of the paper (Escareño, Salazar & Lozano, CDC 2006):
//! attitude stacked (Fig. 3, and the angle panels of Figs. 8–10), position against the
//! setpoint where the log has one (Fig. 4), control inputs τφ, τθ, τψ, f_z (Fig. 5), PWM (the
//! PWM panels of Figs. 8–10), and a transition: pitch, airspeed, altitude and thrust.
//!
//! Sources are tlogs (the vehicle's ATTITUDE, LOCAL_POSITION_NED, POSITION_TARGET_LOCAL_NED,
//! SERVO_OUTPUT_RAW, VFR_HUD, GLOBAL_POSITION_INT, EXTENDED_SYS_STATE and the twin's controller
//! outputs as NAMED_VALUE_FLOAT) and `firmware-sim simulate` CSV. Both are read into NED/FRD;
//! a figure is drawn in the frame the user picks: NED (North, East, Down, roll, pitch, yaw in
//! degrees, as the terminal UI shows them) or the paper's (x = −North, y = East, z up,
//! φ = −roll, θ = pitch, ψ = −yaw, in rad), and every axis says which.
//!
//! Every line is clipped to its panel, cut where the stream had an outage (never bridged), and
//! lines drawn over each other are told apart by their dashes ([`render`]). The picture is
//! drawn in memory and written as a PNG here, so a write error is the system's own words.
//! Text is drawn with a bundled DejaVu Sans through plotters' ab_glyph backend: no system font
//! library is needed.

mod load;
mod panels;
mod render;

use std::ops::Range;
use std::path::{Path, PathBuf};
use std::sync::OnceLock;

use plotters::coord::ranged1d::Ranged;
use plotters::coord::types::RangedCoordf64;
use plotters::prelude::*;
use plotters::style::FontStyle;

pub use load::load;
pub use render::GAP_FACTOR;

use super::LogError;

/// Which figure.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum Kind {
    /// Roll, pitch, yaw (Fig. 3).
    Attitude,
    /// Position against the setpoint, where the log has one (Fig. 4).
    Position,
    /// ESC and control-surface PWM (Figs. 8–10).
    Pwm,
    /// Control inputs τφ, τθ, τψ and f_z (Fig. 5).
    Inputs,
    /// Pitch, airspeed, altitude and thrust over a transition, with the VTOL state's changes.
    Transition,
    /// Every figure of the paper the source has, one column each (not the transition).
    All,
}

impl Kind {
    /// The name on the command line.
    #[must_use]
    pub fn name(self) -> &'static str {
        match self {
            Kind::Attitude => "attitude",
            Kind::Position => "position",
            Kind::Pwm => "pwm",
            Kind::Inputs => "inputs",
            Kind::Transition => "transition",
            Kind::All => "all",
        }
    }
}

/// The frame a figure is drawn in.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, clap::ValueEnum)]
pub enum Frame {
    /// North, East, Down (m); roll, pitch, yaw (°): as the terminal UI shows them.
    #[default]
    Ned,
    /// The paper's: x = −North, y = East, z = −Down (up); φ = −roll, θ = pitch, ψ = −yaw (rad).
    Paper,
}

/// One time series: (s from the log's start, value).
pub type Points = Vec<(f64, f64)>;

/// What the altitude of a transition figure is measured from.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum AltitudeRef {
    /// GLOBAL_POSITION_INT's `relative_alt`.
    Home,
    /// −Down of LOCAL_POSITION_NED.
    Origin,
    /// VFR_HUD's `alt`.
    Amsl,
}

/// An altitude series and its reference.
#[derive(Debug, Clone)]
pub struct Altitude {
    /// Where it is measured from.
    pub reference: AltitudeRef,
    /// Metres, up.
    pub points: Points,
}

/// What a source holds for the figures, in NED/FRD and SI units.
#[derive(Debug, Clone, Default)]
pub struct FlightData {
    /// Legend name (the file name).
    pub label: String,
    /// Roll, pitch, yaw in rad (NED/FRD).
    pub attitude: Option<[Points; 3]>,
    /// North, East, Down in m.
    pub position: Option<[Points; 3]>,
    /// The vehicle's position target (POSITION_TARGET_LOCAL_NED), North, East, Down in m.
    pub setpoint: Option<[Points; 3]>,
    /// PWM 1..5 in µs (ESC 1, ESC 2, aileron L, aileron R, elevator).
    pub pwm: Option<[Points; 5]>,
    /// The paper's controller outputs τφ, τθ, τψ in rad/s², f_z in N.
    pub inputs: Option<[Points; 4]>,
    /// VFR_HUD's true airspeed, m/s.
    pub airspeed: Option<Points>,
    /// VFR_HUD's throttle, %.
    pub throttle: Option<Points>,
    /// Altitude, from the best reference the log has.
    pub altitude: Option<Altitude>,
    /// EXTENDED_SYS_STATE's `vtol_state` at each change: (s, "MC", "to FW", "FW", "to MC").
    pub vtol_states: Vec<(f64, String)>,
    /// `SERVO1..5_FUNCTION` as the log's PARAM_VALUEs last said (labels of the PWM series).
    pub servo_functions: [Option<f32>; 5],
}

/// Options of one figure.
#[derive(Debug, Clone)]
pub struct PlotOptions {
    /// Which figure.
    pub kind: Kind,
    /// The frame of the axes.
    pub frame: Frame,
    /// Picture size, px; `None` picks one for the kind.
    pub size: Option<(u32, u32)>,
    /// A constant position setpoint to draw, in `frame`'s axes (m); a log's own position
    /// target is drawn anyway.
    pub setpoint: Option<[f64; 3]>,
    /// Figure title; `None` names the kind and the source.
    pub title: Option<String>,
}

/// Where one panel was drawn: its plotting area in the picture's pixels and its axes' ranges.
#[derive(Debug, Clone)]
pub struct PanelGeometry {
    /// The panel's title.
    pub title: String,
    /// The y axis' label (quantity, frame, unit).
    pub y_desc: String,
    /// The legend's entries, in drawing order.
    pub lines: Vec<String>,
    /// Columns of the plotting area (inside the axes).
    pub x_px: Range<i32>,
    /// Rows of the plotting area.
    pub y_px: Range<i32>,
    /// Time axis, s.
    pub t_range: (f64, f64),
    /// Value axis.
    pub y_range: (f64, f64),
}

impl PanelGeometry {
    /// The picture's column of time `t`.
    #[must_use]
    pub fn column_of(&self, t: f64) -> f64 {
        let (t0, t1) = self.t_range;
        let w = f64::from(self.x_px.end - self.x_px.start - 1);
        f64::from(self.x_px.start) + (t - t0) / (t1 - t0) * w
    }
}

/// What [`draw`] drew.
#[derive(Debug, Clone)]
pub struct Figure {
    /// Every panel, column by column.
    pub panels: Vec<PanelGeometry>,
}

pub(crate) const FONT: &str = "sans-serif";
static FONT_BYTES: &[u8] = include_bytes!("../../../assets/fonts/DejaVuSans.ttf");

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

fn draw_err(path: &Path, e: impl std::fmt::Display) -> LogError {
    LogError::Write {
        path: path.to_owned(),
        message: e.to_string(),
    }
}

fn t_end_of(sources: &[&FlightData]) -> f64 {
    let mut ends = Vec::new();
    for d in sources {
        let groups: [&[Points]; 5] = [
            d.attitude.as_ref().map_or(&[], |a| a.as_slice()),
            d.position.as_ref().map_or(&[], |a| a.as_slice()),
            d.pwm.as_ref().map_or(&[], |a| a.as_slice()),
            d.inputs.as_ref().map_or(&[], |a| a.as_slice()),
            d.airspeed.as_slice(),
        ];
        ends.extend(
            groups
                .iter()
                .flat_map(|g| g.iter())
                .filter_map(|s| s.last().map(|p| p.0)),
        );
        ends.extend(
            d.altitude
                .as_ref()
                .and_then(|a| a.points.last().map(|p| p.0)),
        );
    }
    let end = ends.into_iter().fold(0.0_f64, f64::max).max(1e-3);
    // a log that stops just short of a tick (7.98 s) ends its axis on that tick (8 s)
    let step = match RangedCoordf64::from(0.0..end).key_points(10).as_slice() {
        [a, b, ..] => b - a,
        _ => return end,
    };
    let nice = (end / step - 1e-9).ceil() * step;
    if nice - end <= 0.05 * end { nice } else { end }
}

/// Draws the figure of `opts.kind` for `main` (and `compare`, on the same axes) into a PNG.
///
/// # Errors
/// The sources lack what the figure needs ([`LogError::Unsupported`], naming the messages),
/// or the PNG cannot be written ([`LogError::Write`], with the system's reason).
pub fn draw(
    main: &FlightData,
    compare: Option<&FlightData>,
    out: &Path,
    opts: &PlotOptions,
) -> Result<Figure, LogError> {
    register_font()?;
    let sources: Vec<&FlightData> = std::iter::once(main).chain(compare).collect();
    let kinds = panels::kinds_of(opts.kind, &sources)?;
    let t_end = t_end_of(&sources);
    let columns: Vec<Vec<panels::Panel>> = kinds
        .iter()
        .map(|&k| panels::panels_for(k, opts.frame, &sources, opts.setpoint, t_end))
        .collect();
    let rows = columns.iter().map(Vec::len).max().unwrap_or(1);
    let (w, h) = opts.size.unwrap_or_else(|| {
        let cols = u32::try_from(columns.len()).unwrap_or(1);
        (760 * cols, 90 + 260 * u32::try_from(rows).unwrap_or(3))
    });
    let title = opts.title.clone().unwrap_or_else(|| {
        let what: Vec<&str> = kinds.iter().map(|k| k.name()).collect();
        let frame = match opts.frame {
            Frame::Ned => "NED",
            Frame::Paper => "paper frame",
        };
        match compare {
            Some(c) => format!(
                "{} ({frame}): {} vs {}",
                what.join(", "),
                main.label,
                c.label
            ),
            None => format!("{} ({frame}): {}", what.join(", "), main.label),
        }
    });
    let mut buf = vec![0u8; w as usize * h as usize * 3];
    let mut geometry = Vec::new();
    {
        let root = BitMapBackend::with_buffer(&mut buf, (w, h)).into_drawing_area();
        root.fill(&WHITE).map_err(|e| draw_err(out, e))?;
        let root = root
            .titled(&title, (FONT, 26))
            .map_err(|e| draw_err(out, e))?;
        for (panels, col_area) in columns.iter().zip(root.split_evenly((1, columns.len()))) {
            // each column shares its height among its own panels: no half-empty column
            for (panel, area) in panels.iter().zip(col_area.split_evenly((panels.len(), 1))) {
                geometry
                    .push(render::draw_panel(&area, panel, t_end).map_err(|e| draw_err(out, e))?);
            }
        }
        root.present().map_err(|e| draw_err(out, e))?;
    }
    write_png(out, w, h, &buf)?;
    Ok(Figure { panels: geometry })
}

fn write_png(out: &Path, w: u32, h: u32, rgb: &[u8]) -> Result<(), LogError> {
    let file = vtol_link::text_file::Output::create(out).map_err(|e| draw_err(out, e))?;
    let mut buf = std::io::BufWriter::new(file);
    {
        let mut enc = png::Encoder::new(&mut buf, w, h);
        enc.set_color(png::ColorType::Rgb);
        enc.set_depth(png::BitDepth::Eight);
        let mut writer = enc.write_header().map_err(|e| draw_err(out, e))?;
        writer.write_image_data(rgb).map_err(|e| draw_err(out, e))?;
        writer.finish().map_err(|e| draw_err(out, e))?;
    }
    buf.into_inner()
        .map_err(std::io::IntoInnerError::into_error)
        .and_then(vtol_link::text_file::Output::finish)
        .map_err(|e| draw_err(out, e))
}

/// Where a figure goes when `-o` names a directory: `DIR/<kind>.png`.
#[must_use]
pub fn default_name(dir: &Path, kind: Kind) -> PathBuf {
    dir.join(format!("{}.png", kind.name()))
}
