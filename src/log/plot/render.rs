//! Drawing one panel: axes with clean ticks, then every line cut into runs at outages, reduced
//! to the pixel columns, clipped to the plotting area and stroked segment by segment (no
//! joins, so a sharp reversal cannot throw a miter spike out of the panel), solid, dashed or
//! dotted so that lines drawn over each other stay distinguishable.

use std::ops::Range;

use plotters::coord::Shift;
use plotters::coord::ranged1d::Ranged;
use plotters::coord::types::RangedCoordf64;
use plotters::prelude::*;

use super::panels::{Dash, Line, Panel, SETPOINT_COLOR};
use super::{FONT, PanelGeometry, Points};

/// A step longer than this many times the series' median step is an outage: the line is cut
/// there instead of being bridged.
pub const GAP_FACTOR: f64 = 5.0;

const LINE_WIDTH: u32 = 2;
/// Tick labels on a y axis: at most 6, one per 26 pixels of height.
const Y_LABELS: LabelDensity = LabelDensity::new(6, 26);
/// On the time axis: at most 10, one per 50 pixels of width.
const X_LABELS: LabelDensity = LabelDensity::new(10, 50);

/// How densely an axis is labelled: at most `most` tick labels, one per `px_each` pixels.
#[derive(Debug, Clone, Copy)]
struct LabelDensity {
    most: usize,
    px_each: u32,
}

impl LabelDensity {
    const fn new(most: usize, px_each: u32) -> Self {
        Self { most, px_each }
    }

    /// Labels on an axis of `px` pixels, `taken` of which go to the caption, margins and the
    /// other axis' labels: at least 2.
    fn count(self, px: u32, taken: u32) -> usize {
        usize::try_from(px.saturating_sub(taken) / self.px_each)
            .unwrap_or(self.most)
            .clamp(2, self.most)
    }
}

/// Splits a series into runs at outages (a step over [`GAP_FACTOR`] × the median step) and,
/// for angles, where the value wraps (a jump larger than `wrap`).
pub(super) fn split_runs(points: &[(f64, f64)], wrap: Option<f64>) -> Vec<&[(f64, f64)]> {
    if points.len() < 2 {
        return vec![points];
    }
    let mut steps: Vec<f64> = points
        .windows(2)
        .map(|w| w[1].0 - w[0].0)
        .filter(|d| *d > 0.0)
        .collect();
    let limit = if steps.is_empty() {
        f64::INFINITY
    } else {
        let mid = steps.len() / 2;
        let (_, median, _) = steps.select_nth_unstable_by(mid, f64::total_cmp);
        *median * GAP_FACTOR
    };
    let mut runs = Vec::new();
    let mut start = 0;
    for i in 1..points.len() {
        let dt = points[i].0 - points[i - 1].0;
        let jump = (points[i].1 - points[i - 1].1).abs();
        if dt > limit || wrap.is_some_and(|w| jump > w) {
            runs.push(&points[start..i]);
            start = i;
        }
    }
    runs.push(&points[start..]);
    runs
}

/// Min/max per pixel column: the same picture as every point, with at most 2 per column.
pub(super) fn decimate(points: &[(f64, f64)], x0: f64, x1: f64, columns: usize) -> Points {
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

/// The fewest decimals that write every tick of this step exactly (0.25 → 2, 5 → 0).
fn decimals_for(step: f64) -> usize {
    (0..=6)
        .find(|&d| {
            let s = step * 10f64.powi(d as i32);
            (s - s.round()).abs() < 1e-6 * s.abs().max(1.0)
        })
        .unwrap_or(6)
}

/// A tick label: `decimals` digits, never `-0`.
pub(super) fn tick_label(v: f64, decimals: usize) -> String {
    let s = format!("{v:.decimals$}");
    match s.strip_prefix('-') {
        Some(rest) if rest.chars().all(|c| c == '0' || c == '.') => rest.to_owned(),
        _ => s,
    }
}

/// Decimals for the ticks plotters draws on this range with at most `n` labels.
fn tick_decimals(range: Range<f64>, n: usize) -> usize {
    let kp = RangedCoordf64::from(range).key_points(n);
    match kp.as_slice() {
        [a, b, ..] => decimals_for(b - a),
        [a] => decimals_for(*a),
        [] => 0,
    }
}

/// Cuts the segment a–b to the box (Liang–Barsky); `None` if it lies outside.
fn clip(a: (f64, f64), b: (f64, f64), bx: (f64, f64), by: (f64, f64)) -> Option<[(f64, f64); 2]> {
    let (dx, dy) = (b.0 - a.0, b.1 - a.1);
    let (mut t0, mut t1) = (0.0_f64, 1.0_f64);
    for (p, q) in [
        (-dx, a.0 - bx.0),
        (dx, bx.1 - a.0),
        (-dy, a.1 - by.0),
        (dy, by.1 - a.1),
    ] {
        if p == 0.0 {
            if q < 0.0 {
                return None;
            }
        } else {
            let r = q / p;
            if p < 0.0 {
                t0 = t0.max(r);
            } else {
                t1 = t1.min(r);
            }
        }
    }
    (t0 <= t1).then_some([
        (a.0 + t0 * dx, a.1 + t0 * dy),
        (a.0 + t1 * dx, a.1 + t1 * dy),
    ])
}

/// Walks a polyline (pixels) and keeps the "on" parts of a dash pattern, carried across
/// segments so the pattern does not restart at every data point.
fn dashed(segments: &[[(f64, f64); 2]], on: f64, off: f64) -> Vec<[(f64, f64); 2]> {
    let mut out = Vec::new();
    let period = on + off;
    let mut phase = 0.0_f64;
    for [a, b] in segments {
        let len = ((b.0 - a.0).powi(2) + (b.1 - a.1).powi(2)).sqrt();
        if len == 0.0 {
            continue;
        }
        let at = |s: f64| (a.0 + (b.0 - a.0) * s / len, a.1 + (b.1 - a.1) * s / len);
        let mut s = 0.0;
        while s < len {
            let in_period = phase % period;
            let (is_on, left) = if in_period < on {
                (true, on - in_period)
            } else {
                (false, period - in_period)
            };
            let step = left.min(len - s);
            if is_on {
                out.push([at(s), at(s + step)]);
            }
            s += step;
            phase += step;
        }
    }
    out
}

/// Segments of one line in the plotting area's pixels, clipped to `[1, w−2] × [1, h−2]` so
/// that a 2 px stroke stays inside; single points (a run of one sample) as a zero-length
/// segment.
fn pixel_segments(
    run: &[(f64, f64)],
    x: (f64, f64),
    y: (f64, f64),
    w: f64,
    h: f64,
) -> Vec<[(f64, f64); 2]> {
    let to_px = |(t, v): (f64, f64)| {
        (
            (t - x.0) / (x.1 - x.0) * (w - 1.0),
            (h - 1.0) - (v - y.0) / (y.1 - y.0) * (h - 1.0),
        )
    };
    let (bx, by) = ((1.0, w - 2.0), (1.0, h - 2.0));
    if let [p] = run {
        let q = to_px(*p);
        let inside = (bx.0..=bx.1).contains(&q.0) && (by.0..=by.1).contains(&q.1);
        return if inside { vec![[q, q]] } else { Vec::new() };
    }
    run.windows(2)
        .filter_map(|s| clip(to_px(s[0]), to_px(s[1]), bx, by))
        .collect()
}

fn stroke<DB: DrawingBackend>(
    area: &DrawingArea<DB, Shift>,
    segments: &[[(f64, f64); 2]],
    style: ShapeStyle,
) -> Result<(), DrawingAreaErrorKind<DB::ErrorType>> {
    let px = |p: (f64, f64)| (p.0.round() as i32, p.1.round() as i32);
    for [a, b] in segments {
        let (a, b) = (px(*a), px(*b));
        if a == b {
            area.draw(&Rectangle::new([a, (a.0 + 1, a.1 + 1)], style.filled()))?;
        } else {
            area.draw(&PathElement::new(vec![a, b], style))?;
        }
    }
    Ok(())
}

/// The legend's sample of a line: three pieces (x from, x to), joined for a solid line.
fn legend_pieces(dash: Dash) -> [(i32, i32); 3] {
    match dash {
        Dash::Solid => [(0, 8), (8, 16), (16, 24)],
        Dash::Dashed => [(0, 7), (11, 18), (22, 24)],
        Dash::Dotted => [(0, 3), (10, 13), (20, 23)],
    }
}

/// Points every few pixels along the drawn segments: where the legend would hide data.
fn sample_ink(segments: &[[(f64, f64); 2]], ink: &mut Vec<(f64, f64)>) {
    for [a, b] in segments {
        let len = (b.0 - a.0).abs().max((b.1 - a.1).abs());
        let n = (len / 4.0).ceil().max(1.0) as usize;
        for k in 0..=n {
            let s = k as f64 / n as f64;
            ink.push((a.0 + (b.0 - a.0) * s, a.1 + (b.1 - a.1) * s));
        }
    }
}

/// The row a label from `x` to `x + width` takes: the first whose labels end before it (4 px
/// apart), else a new one below; `rows_end` keeps where each row is taken up to. Close changes
/// stack their labels instead of printing one over another.
fn label_row(rows_end: &mut Vec<f64>, x: f64, width: f64) -> usize {
    let k = rows_end
        .iter()
        .position(|end| *end + 4.0 <= x)
        .unwrap_or(rows_end.len());
    if k == rows_end.len() {
        rows_end.push(0.0);
    }
    rows_end[k] = x + width;
    k
}

/// A marker label's width in pixels at the 14 px font (about 8 px a character).
fn marker_label_width(label: &str) -> f64 {
    8.0 * label.chars().count() as f64
}

/// The corner where the legend's box covers the fewest drawn points (upper right on a tie).
fn legend_corner(ink: &[(f64, f64)], lines: &[Line], w: f64, h: f64) -> SeriesLabelPosition {
    let chars = lines
        .iter()
        .map(|l| l.label.chars().count())
        .max()
        .unwrap_or(0);
    // the legend's size as plotters lays it out with a 15 px font, plus its margin
    let bw = 60.0 + 8.5 * chars as f64;
    let bh = 15.0 + 20.0 * lines.len() as f64;
    let corners = [
        (SeriesLabelPosition::UpperRight, true, true),
        (SeriesLabelPosition::UpperLeft, false, true),
        (SeriesLabelPosition::LowerRight, true, false),
        (SeriesLabelPosition::LowerLeft, false, false),
    ];
    let covered = |right: bool, upper: bool| {
        ink.iter()
            .filter(|(px, py)| {
                let in_x = if right { *px > w - bw } else { *px < bw };
                let in_y = if upper { *py < bh } else { *py > h - bh };
                in_x && in_y
            })
            .count()
    };
    corners
        .into_iter()
        .min_by_key(|(_, right, upper)| covered(*right, *upper))
        .map_or(SeriesLabelPosition::UpperRight, |c| c.0)
}

/// Draws one panel and returns where its plotting area is.
// One pass over the panel's parts in drawing order (axes, lines, markers, legend); split, it
// would pass the chart and its ranges between functions for no gain in reading.
pub(super) fn draw_panel<DB: DrawingBackend>(
    area: &DrawingArea<DB, Shift>,
    panel: &Panel,
    t_end: f64,
) -> Result<PanelGeometry, DrawingAreaErrorKind<DB::ErrorType>> {
    let (pw, ph) = area.dim_in_pixel();
    // the plotting area is the panel less its caption, margins and label areas
    let y_labels = Y_LABELS.count(ph, 80);
    let x_labels = X_LABELS.count(pw, 112);
    let columns = usize::try_from(pw).unwrap_or(800).max(1);
    let lines: Vec<(Vec<Points>, &Line)> = panel
        .lines
        .iter()
        .map(|l| {
            let runs = split_runs(&l.points, panel.wrap)
                .into_iter()
                .map(|r| decimate(r, 0.0, t_end, columns))
                .collect();
            (runs, l)
        })
        .collect();
    let (mut lo, mut hi) = lines
        .iter()
        .flat_map(|(runs, _)| runs.iter().flatten().map(|q| q.1))
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
    let y = (lo - pad, hi + pad);
    let x = (0.0, t_end);
    let (xd, yd) = (
        tick_decimals(x.0..x.1, x_labels),
        tick_decimals(y.0..y.1, y_labels),
    );
    let x_fmt = move |v: &f64| tick_label(*v, xd);
    let y_fmt = move |v: &f64| tick_label(*v, yd);
    let mut chart = ChartBuilder::on(area)
        .caption(&panel.title, (FONT, 20))
        .margin_top(4)
        .margin_left(8)
        .margin_bottom(4)
        // room for the last x label, centred on the right edge
        .margin_right(26)
        .x_label_area_size(40)
        .y_label_area_size(78)
        .build_cartesian_2d(x.0..x.1, y.0..y.1)?;
    chart
        .configure_mesh()
        .x_labels(x_labels)
        .y_labels(y_labels)
        .x_label_formatter(&x_fmt)
        .y_label_formatter(&y_fmt)
        .x_desc("t (s)")
        .y_desc(panel.y_desc.as_str())
        .label_style((FONT, 15))
        .axis_desc_style((FONT, 16))
        .light_line_style(RGBColor(0xee, 0xee, 0xee))
        .draw()?;
    let plot = chart.plotting_area().strip_coord_spec();
    let (w, h) = plot.dim_in_pixel();
    let (w, h) = (f64::from(w), f64::from(h));
    let mut ink = Vec::new();
    for (runs, line) in &lines {
        let style = line.color.stroke_width(LINE_WIDTH);
        let segments: Vec<[(f64, f64); 2]> = runs
            .iter()
            .flat_map(|r| pixel_segments(r, x, y, w, h))
            .collect();
        sample_ink(&segments, &mut ink);
        match line.dash.pattern() {
            None => stroke(&plot, &segments, style)?,
            Some((on, off)) => stroke(&plot, &dashed(&segments, on, off), style)?,
        }
    }
    // Where each row of marker labels is taken up to, pixels.
    let mut rows_end: Vec<f64> = Vec::new();
    for (t, label) in &panel.markers {
        let px = ((t - x.0) / (x.1 - x.0) * (w - 1.0)).clamp(1.0, w - 2.0);
        let seg = [[(px, 1.0), (px, h - 2.0)]];
        stroke(
            &plot,
            &dashed(&seg, 4.0, 4.0),
            SETPOINT_COLOR.stroke_width(1),
        )?;
        // The marker's line is data too: the legend keeps off it.
        sample_ink(&seg, &mut ink);
        let (lx, lw) = (px + 4.0, marker_label_width(label));
        let k = label_row(&mut rows_end, lx, lw);
        let row = 4 + 16 * i32::try_from(k).unwrap_or(0);
        // the label's box, so that the legend avoids it
        let ly = f64::from(row);
        sample_ink(&[[(lx, ly), (lx + lw, ly + 14.0)]], &mut ink);
        plot.draw(&Text::new(
            label.clone(),
            (px.round() as i32 + 4, row),
            (FONT, 14).into_font().color(&SETPOINT_COLOR),
        ))?;
    }
    for (_, line) in &lines {
        let (color, dash) = (line.color, line.dash);
        chart
            .draw_series(std::iter::empty::<PathElement<(f64, f64)>>())?
            .label(line.label.clone())
            .legend(move |(x, y)| {
                let style = color.stroke_width(LINE_WIDTH);
                let [p, q, r] = legend_pieces(dash);
                // relative to the composition's anchor
                let piece = |(a, b): (i32, i32)| PathElement::new(vec![(a, 0), (b, 0)], style);
                EmptyElement::at((x, y)) + piece(p) + piece(q) + piece(r)
            });
    }
    chart
        .configure_series_labels()
        .label_font((FONT, 15))
        .background_style(WHITE.mix(0.85))
        .border_style(RGBColor(0xaa, 0xaa, 0xaa))
        .position(legend_corner(&ink, &panel.lines, w, h))
        .draw()?;
    let (px, py) = chart.plotting_area().get_pixel_range();
    Ok(PanelGeometry {
        title: panel.title.clone(),
        y_desc: panel.y_desc.clone(),
        lines: panel.lines.iter().map(|l| l.label.clone()).collect(),
        x_px: px,
        y_px: py,
        t_range: x,
        y_range: y,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn close_marker_labels_stack_and_far_ones_share_the_top_row() {
        let mut rows = Vec::new();
        let w = marker_label_width("to MC");
        // Three changes within a label's width of each other: three rows.
        assert_eq!(label_row(&mut rows, 10.0, w), 0);
        assert_eq!(label_row(&mut rows, 20.0, w), 1);
        assert_eq!(label_row(&mut rows, 30.0, w), 2);
        // Far to the right: the top row again.
        assert_eq!(label_row(&mut rows, 10.0 + w + 10.0, w), 0);
    }

    #[test]
    fn ticks_are_written_with_the_digits_of_their_step() {
        assert_eq!(decimals_for(0.25), 2);
        assert_eq!(decimals_for(5.0), 0);
        assert_eq!(decimals_for(0.1), 1);
        assert_eq!(tick_label(-0.0001, 2), "0.00");
        assert_eq!(tick_label(1000.0, 0), "1000");
        assert_eq!(tick_label(-0.5, 1), "-0.5");
        assert_eq!(tick_decimals(0.0..25.0, 10), 0);
    }

    #[test]
    fn outages_and_wraps_cut_a_series() {
        let mut p: Points = (0..100).map(|i| (f64::from(i) * 0.1, 0.0)).collect();
        p.extend((150..200).map(|i| (f64::from(i) * 0.1, 0.0)));
        let runs = split_runs(&p, None);
        assert_eq!(runs.len(), 2);
        assert_eq!(runs[0].len(), 100);
        let yaw = [(0.0, 179.0), (0.1, 179.5), (0.2, -179.8), (0.3, -179.0)];
        assert_eq!(split_runs(&yaw, Some(180.0)).len(), 2);
        assert_eq!(split_runs(&yaw, None).len(), 1);
    }

    #[test]
    fn clipping_keeps_segments_inside_and_dashes_keep_their_phase() {
        let c = clip((-10.0, 5.0), (10.0, 5.0), (0.0, 4.0), (0.0, 10.0)).unwrap();
        assert_eq!(c, [(0.0, 5.0), (4.0, 5.0)]);
        assert!(clip((-10.0, 50.0), (10.0, 50.0), (0.0, 4.0), (0.0, 10.0)).is_none());
        let d = dashed(
            &[[(0.0, 0.0), (10.0, 0.0)], [(10.0, 0.0), (20.0, 0.0)]],
            9.0,
            5.0,
        );
        // on 0–9, off 9–14, on 14–20 (in the second segment)
        assert_eq!(d.len(), 2);
        assert_eq!(d[1][0], (14.0, 0.0));
    }
}
