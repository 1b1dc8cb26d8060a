//! The Charts view and the chart helper the other views share.

use ratatui::Frame;
use ratatui::layout::{Constraint, Layout, Rect};
use ratatui::style::{Color, Style};
use ratatui::symbols::Marker;
use ratatui::widgets::{Axis, Block, Chart, Dataset, GraphType, Paragraph};

use super::flight::setpoint_ned;
use super::{Snapshot, servo_names};
use crate::tui::app::App;

/// A chart series: name, colour, points (seconds before now, value).
pub(super) type Series = (String, Color, Vec<(f64, f64)>);

/// One chart of several series over the window, y bounds from the data.
pub(super) fn chart<'a>(
    title: String,
    series: &'a [Series],
    window_s: f64,
    unit: &str,
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
    }
    let pad = (hi - lo) * 0.05;
    let (lo, hi) = (lo - pad, hi + pad);
    let datasets = series
        .iter()
        .map(|(name, colour, pts)| {
            // A lone series is named by the chart's title; a legend would only hide data.
            let d = Dataset::default();
            let d = if series.len() > 1 {
                d.name(name.clone())
            } else {
                d
            };
            d.marker(Marker::Braille)
                .graph_type(GraphType::Line)
                .style(Style::new().fg(*colour))
                .data(pts)
        })
        .collect();
    Chart::new(datasets)
        .block(Block::bordered().title(title))
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

pub(super) fn draw_charts(f: &mut Frame<'_>, app: &App, snap: &Snapshot<'_>, area: Rect) {
    let Some(v) = app.vehicle(snap.state) else {
        f.render_widget(Paragraph::new("no vehicle yet"), area);
        return;
    };
    let now_t = snap.history.t_s(snap.now);
    let from = now_t - app.window_s;
    let hist = snap.history.vehicles.get(&(v.system_id, v.component_id));
    let rel = |t: f64| t - now_t;
    let att_series = |i: usize| -> Vec<(f64, f64)> {
        hist.map(|h| {
            h.attitude
                .iter()
                .filter(|(t, _)| *t >= from)
                .map(|(t, a)| (rel(*t), f64::from(a[i]).to_degrees()))
                .collect()
        })
        .unwrap_or_default()
    };
    let servo_series = |i: usize| -> Vec<(f64, f64)> {
        hist.map(|h| {
            h.servo
                .iter()
                .filter(|(t, _)| *t >= from)
                .map(|(t, s)| (rel(*t), f64::from(s[i])))
                .collect()
        })
        .unwrap_or_default()
    };
    let pos_series = |i: usize, sign: f64| -> Vec<(f64, f64)> {
        hist.map(|h| {
            h.position
                .iter()
                .filter(|(t, _)| *t >= from)
                .map(|(t, p)| (rel(*t), sign * f64::from(p[i])))
                .collect()
        })
        .unwrap_or_default()
    };
    let names = servo_names(app);
    let [l, r] = Layout::horizontal([Constraint::Percentage(50); 2]).areas(area);
    let left = Layout::vertical([Constraint::Ratio(1, 3); 3]).split(l);
    let right = Layout::vertical([Constraint::Ratio(1, 3); 3]).split(r);
    for (i, name) in ["Roll", "Pitch", "Yaw"].iter().enumerate() {
        let s = vec![((*name).to_owned(), COLOURS[0], att_series(i))];
        f.render_widget(
            chart(format!(" {name} (°) "), &s, app.window_s, "°"),
            left[i],
        );
    }
    let escs: Vec<_> = (0..8)
        .filter(|i| names[*i].starts_with("ESC") || (*i < 2 && names[*i].starts_with("SERVO")))
        .filter(|i| v.servo_us[*i] != 0)
        .enumerate()
        .map(|(k, i)| (names[i].clone(), COLOURS[k % 8], servo_series(i)))
        .collect();
    f.render_widget(
        chart(" ESC PWM (µs) ".into(), &escs, app.window_s, "µs"),
        right[0],
    );
    let surfaces: Vec<_> = (0..8)
        .filter(|i| !escs.iter().any(|(n, _, _)| *n == names[*i]))
        .filter(|i| v.servo_us[*i] != 0)
        .enumerate()
        .map(|(k, i)| (names[i].clone(), COLOURS[(k + 2) % 8], servo_series(i)))
        .collect();
    f.render_widget(
        chart(" Surfaces PWM (µs) ".into(), &surfaces, app.window_s, "µs"),
        right[1],
    );
    let mut pos = vec![
        ("alt".to_owned(), COLOURS[0], pos_series(2, -1.0)),
        ("north".to_owned(), COLOURS[1], pos_series(0, 1.0)),
        ("east".to_owned(), COLOURS[2], pos_series(1, 1.0)),
    ];
    if let Some(sp) = setpoint_ned(app, v) {
        for (name, val, c) in [
            ("alt sp", -sp[2], COLOURS[3]),
            ("north sp", sp[0], COLOURS[4]),
            ("east sp", sp[1], COLOURS[5]),
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
    f.render_widget(
        chart(" Position vs setpoint (m) ".into(), &pos, app.window_s, "m"),
        right[2],
    );
}
