//! The Charts view and the chart helper the other views share.

use ratatui::Frame;
use ratatui::layout::{Constraint, Layout, Rect};
use ratatui::style::{Color, Style};
use ratatui::symbols::Marker;
use ratatui::text::{Line, Span};
use ratatui::widgets::{Axis, Block, Chart, Dataset, GraphType, Paragraph};

use super::setpoint::{setpoint_ned, shown_attitude};
use super::{Snapshot, servo_outputs};
use crate::tracker::state::VehicleView;
use crate::tui::app::App;
use crate::tui::attitude::{AttFrame, wing_to_hover};

/// A chart series: name, colour, points (seconds before now, value).
pub(super) type Series = (String, Color, Vec<(f64, f64)>);

/// A short name for a legend that must fit a narrow title.
fn short(name: &str) -> &str {
    match name {
        "left aileron" => "L ail",
        "right aileron" => "R ail",
        "left elevon" => "L elvn",
        "right elevon" => "R elvn",
        "left motor" => "L mot",
        "right motor" => "R mot",
        "elevator" => "elev",
        "north" => "N",
        "east" => "E",
        _ => name.rsplit('.').next().unwrap_or(name),
    }
}

/// The title with the legend in it: each series' name in its colour, a setpoint (a series named
/// `… sp`, drawn dotted) once as `··· setpoint`. Full names when they fit `width`, short ones
/// otherwise; `None` when not even those fit (ratatui's own legend is then used).
fn title_with_legend(title: &str, series: &[Series], width: u16) -> Option<Line<'static>> {
    let fits = |names: &[String], sp: bool| {
        let w = title.chars().count()
            + names.iter().map(|n| n.chars().count() + 1).sum::<usize>()
            + if sp { 12 } else { 0 }
            + 1;
        w + 2 <= usize::from(width)
    };
    let has_sp = series.iter().any(|(n, _, _)| n.ends_with(" sp"));
    let measured: Vec<&Series> = series
        .iter()
        .filter(|(n, _, _)| !n.ends_with(" sp"))
        .collect();
    let full: Vec<String> = measured.iter().map(|(n, _, _)| n.clone()).collect();
    let names = if fits(&full, has_sp) {
        full
    } else {
        let brief: Vec<String> = measured
            .iter()
            .map(|(n, _, _)| short(n).to_owned())
            .collect();
        if !fits(&brief, has_sp) {
            return None;
        }
        brief
    };
    let mut spans = vec![Span::raw(title.trim_end().to_owned()), Span::raw(":")];
    for (name, (_, colour, _)) in names.into_iter().zip(&measured) {
        spans.push(Span::raw(" "));
        spans.push(Span::styled(name, Style::new().fg(*colour)));
    }
    if has_sp {
        spans.push(Span::styled(" ··· setpoint", Style::new().fg(Color::Gray)));
    }
    spans.push(Span::raw(" "));
    Some(Line::from(spans))
}

/// One chart of several series over the window, y bounds from the data. With several series
/// the legend goes into the title where it fits `width` (ratatui hides its own legend on a
/// small chart); a setpoint series (`… sp`) is drawn dotted in its quantity's colour.
pub(super) fn chart<'a>(
    title: String,
    series: &'a [Series],
    window_s: f64,
    unit: &str,
    width: u16,
) -> Chart<'a> {
    let (mut lo, mut hi) = (f64::INFINITY, f64::NEG_INFINITY);
    for (_, _, pts) in series {
        for (_, y) in pts {
            lo = lo.min(*y);
            hi = hi.max(*y);
        }
    }
    if !lo.is_finite() {
        (lo, hi) = (-1.0, 1.0);
    }
    if hi - lo < 1e-6 {
        lo -= 1.0;
        hi += 1.0;
    } else if hi - lo < 0.2 {
        // Hundredths are a float's noise (an angle converted near 90° of pitch), not motion.
        let mid = (hi + lo) / 2.0;
        (lo, hi) = (mid - 0.1, mid + 0.1);
    }
    let pad = (hi - lo) * 0.05;
    let (lo, hi) = (lo - pad, hi + pad);
    let legend_title = (series.len() > 1)
        .then(|| title_with_legend(&title, series, width))
        .flatten();
    let own_legend = series.len() > 1 && legend_title.is_none();
    let datasets = series
        .iter()
        .map(|(name, colour, pts)| {
            // A lone series is named by the chart's title; a legend would only hide data.
            let d = Dataset::default();
            let d = if own_legend { d.name(name.clone()) } else { d };
            let marker = if name.ends_with(" sp") {
                Marker::Dot
            } else {
                Marker::Braille
            };
            d.marker(marker)
                .graph_type(GraphType::Line)
                .style(Style::new().fg(*colour))
                .data(pts)
        })
        .collect();
    let block = match legend_title {
        Some(t) => Block::bordered().title(t),
        None => Block::bordered().title(title),
    };
    Chart::new(datasets)
        .block(block)
        // Show the legend whenever it fits: with several series it is the only key.
        .hidden_legend_constraints((Constraint::Ratio(1, 2), Constraint::Ratio(1, 1)))
        .x_axis(
            Axis::default()
                .bounds([-window_s, 0.0])
                .labels([format!("-{window_s:.0} s"), "now".to_owned()]),
        )
        .y_axis(
            Axis::default()
                .bounds([lo, hi])
                .labels([format!("{lo:.1}"), format!("{hi:.1} {unit}")]),
        )
}

pub(super) const COLOURS: [Color; 8] = [
    Color::Cyan,
    Color::Yellow,
    Color::Magenta,
    Color::Green,
    Color::Red,
    Color::Blue,
    Color::LightCyan,
    Color::LightYellow,
];

/// The shown vehicle's recent past as chart series, times relative to now.
struct Past<'h> {
    hist: Option<&'h crate::tracker::history::VehicleHistory>,
    now_t: f64,
    from: f64,
    /// The frame the attitude is shown in now (a tailsitter's hover frame is converted).
    frame: AttFrame,
    /// Whether ATTITUDE's history is turned into that hover frame (not when the vehicle
    /// reports ATTITUDE in its VTOL view already, as ArduPilot does).
    turn: bool,
}

impl Past<'_> {
    fn attitude(&self, i: usize) -> Vec<(f64, f64)> {
        self.hist.map_or_else(Vec::new, |h| {
            h.attitude
                .iter()
                .filter(|(t, _)| *t >= self.from)
                .map(|(t, a)| {
                    let a = if self.frame == AttFrame::Hover && self.turn {
                        let [r, p, y] = [a[0], a[1], a[2]].map(f64::from);
                        let q = wing_to_hover(nalgebra::UnitQuaternion::from_euler_angles(r, p, y));
                        let (r, p, y) = q.euler_angles();
                        [r, p, y]
                    } else {
                        [a[0], a[1], a[2]].map(f64::from)
                    };
                    (t - self.now_t, a[i].to_degrees())
                })
                .collect()
        })
    }

    fn servo(&self, i: usize) -> Vec<(f64, f64)> {
        self.hist.map_or_else(Vec::new, |h| {
            h.servo
                .iter()
                .filter(|(t, _)| *t >= self.from)
                .map(|(t, s)| (t - self.now_t, f64::from(s[i])))
                .collect()
        })
    }

    fn position(&self, i: usize, sign: f64) -> Vec<(f64, f64)> {
        self.hist.map_or_else(Vec::new, |h| {
            h.position
                .iter()
                .filter(|(t, _)| *t >= self.from)
                .map(|(t, p)| (t - self.now_t, sign * f64::from(p[i])))
                .collect()
        })
    }
}

fn past<'h>(app: &App, snap: &Snapshot<'h>, v: &VehicleView) -> Past<'h> {
    let now_t = snap.history.t_s(snap.now);
    Past {
        hist: snap.history.vehicles.get(&(v.system_id, v.component_id)),
        now_t,
        from: now_t - app.window_s,
        frame: shown_attitude(app, snap, v).map_or(AttFrame::Body, |s| s.frame),
        turn: crate::tui::attitude::turn_history(snap.state, v),
    }
}

/// Altitude, north and east with their setpoints (dotted, in the same colours).
fn position_series(app: &App, snap: &Snapshot<'_>, v: &VehicleView, p: &Past<'_>) -> Vec<Series> {
    let mut pos = vec![
        ("alt".to_owned(), COLOURS[0], p.position(2, -1.0)),
        ("north".to_owned(), COLOURS[1], p.position(0, 1.0)),
        ("east".to_owned(), COLOURS[2], p.position(1, 1.0)),
    ];
    if let Some((sp, _)) = setpoint_ned(app, snap, v) {
        for (name, val, c) in [
            ("alt sp", -sp[2], COLOURS[0]),
            ("north sp", sp[0], COLOURS[1]),
            ("east sp", sp[1], COLOURS[2]),
        ] {
            if val.is_finite() {
                pos.push((
                    name.to_owned(),
                    c,
                    vec![(-app.window_s, f64::from(val)), (0.0, f64::from(val))],
                ));
            }
        }
    }
    pos
}

/// The Flight view's chart column on a wide terminal: attitude, and position against the
/// setpoint.
pub(super) fn draw_flight_charts(
    f: &mut Frame<'_>,
    app: &App,
    snap: &Snapshot<'_>,
    v: &VehicleView,
    area: Rect,
) {
    let p = past(app, snap, v);
    let [att, pos] = Layout::vertical([Constraint::Percentage(50); 2]).areas(area);
    let s: Vec<Series> = ["roll", "pitch", "yaw"]
        .iter()
        .enumerate()
        .map(|(i, n)| ((*n).to_owned(), COLOURS[i], p.attitude(i)))
        .collect();
    f.render_widget(
        chart(
            match p.frame.label() {
                Some(l) => format!(" Attitude (°, {l}) "),
                None => " Attitude (°) ".into(),
            },
            &s,
            app.window_s,
            "°",
            att.width,
        ),
        att,
    );
    let s = position_series(app, snap, v, &p);
    f.render_widget(
        chart(" Position (m) ".into(), &s, app.window_s, "m", pos.width),
        pos,
    );
}

pub(super) fn draw_charts(f: &mut Frame<'_>, app: &App, snap: &Snapshot<'_>, area: Rect) {
    let Some(v) = app.vehicle(snap.state) else {
        f.render_widget(Paragraph::new("no vehicle yet"), area);
        return;
    };
    let p = past(app, snap, v);
    let outputs = servo_outputs(app);
    let names: Vec<&str> = outputs.iter().map(|o| o.name.as_str()).collect();
    let [l, r] = Layout::horizontal([Constraint::Percentage(50); 2]).areas(area);
    let left = Layout::vertical([Constraint::Ratio(1, 3); 3]).split(l);
    let right = Layout::vertical([Constraint::Ratio(1, 3); 3]).split(r);
    let frame = p
        .frame
        .label()
        .map_or_else(String::new, |l| format!(", {l}"));
    for (i, name) in ["Roll", "Pitch", "Yaw"].iter().enumerate() {
        let s = vec![((*name).to_owned(), COLOURS[0], p.attitude(i))];
        f.render_widget(
            chart(
                format!(" {name} (°{frame}) "),
                &s,
                app.window_s,
                "°",
                left[i].width,
            ),
            left[i],
        );
    }
    let escs: Vec<_> = (0..8)
        .filter(|i| outputs[*i].motor || (*i < 2 && names[*i].starts_with("SERVO")))
        .filter(|i| v.servo_us[*i] != 0)
        .enumerate()
        .map(|(k, i)| (names[i].to_owned(), COLOURS[k % 8], p.servo(i)))
        .collect();
    f.render_widget(
        chart(
            " Motors (µs) ".into(),
            &escs,
            app.window_s,
            "µs",
            right[0].width,
        ),
        right[0],
    );
    let surfaces: Vec<_> = (0..8)
        .filter(|i| !escs.iter().any(|(n, _, _)| *n == names[*i]))
        .filter(|i| v.servo_us[*i] != 0)
        .enumerate()
        .map(|(k, i)| (names[i].to_owned(), COLOURS[(k + 2) % 8], p.servo(i)))
        .collect();
    f.render_widget(
        chart(
            " Surfaces (µs) ".into(),
            &surfaces,
            app.window_s,
            "µs",
            right[1].width,
        ),
        right[1],
    );
    let pos = position_series(app, snap, v, &p);
    f.render_widget(
        chart(
            " Position (m) ".into(),
            &pos,
            app.window_s,
            "m",
            right[2].width,
        ),
        right[2],
    );
}
