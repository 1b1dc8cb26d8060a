//! The Flight view: attitude, position, setpoint, outputs and the heading tape.

use ratatui::Frame;
use ratatui::layout::{Constraint, Layout, Rect};
use ratatui::style::{Color, Style};
use ratatui::symbols::Marker;
use ratatui::text::{Line, Span};
use ratatui::widgets::canvas::{Canvas, Line as CLine};
use ratatui::widgets::{Block, Paragraph, Wrap};

use super::{STALE_S, Snapshot, age_s, level_style, servo_names, severity_style};
use crate::tracker::state::VehicleView;
use crate::tui::app::App;

pub(super) fn setpoint_ned(app: &App, v: &VehicleView) -> Option<[f32; 3]> {
    let hover = app.params.value("HOVER_ALT");
    match v.mode_name().as_str() {
        "QLOITER" => app
            .target_ned
            .or_else(|| hover.map(|h| [f32::NAN, f32::NAN, -h])),
        "QHOVER" => hover.map(|h| [f32::NAN, f32::NAN, -h]),
        _ => None,
    }
}

pub(super) fn draw_flight(f: &mut Frame<'_>, app: &App, snap: &Snapshot<'_>, area: Rect) {
    // On a small terminal the message panes give way to the instruments.
    let bottom_rows = if area.height < 26 { 5 } else { 8 };
    let [top, bottom] =
        Layout::vertical([Constraint::Min(12), Constraint::Length(bottom_rows)]).areas(area);
    let [left, right] =
        Layout::horizontal([Constraint::Percentage(45), Constraint::Percentage(55)]).areas(top);
    let vehicle = app.vehicle(snap.state);
    let att = vehicle.and_then(|v| v.attitude);
    let stale_att = vehicle
        .and_then(|v| age_s(snap, v, 30))
        .filter(|a| *a > STALE_S);

    // Horizon with a heading tape.
    let block = Block::bordered().title(" Horizon ");
    let inner = block.inner(left);
    f.render_widget(block, left);
    let [tape, horizon] =
        Layout::vertical([Constraint::Length(2), Constraint::Min(4)]).areas(inner);
    let yaw_deg = att.map_or(0.0, |a| f64::from(a.rpy_rad[2]).to_degrees());
    f.render_widget(Paragraph::new(heading_tape(yaw_deg, tape.width)), tape);
    let (roll, pitch) = att.map_or((0.0, 0.0), |a| {
        (f64::from(a.rpy_rad[0]), f64::from(a.rpy_rad[1]))
    });
    let colour = if stale_att.is_some() || att.is_none() {
        Color::DarkGray
    } else {
        Color::Cyan
    };
    let canvas = Canvas::default()
        .marker(Marker::Braille)
        .x_bounds([-1.0, 1.0])
        .y_bounds([-1.0, 1.0])
        .paint(move |ctx| {
            // Pitch moves the horizon: 30° is the half-height. Roll turns it the other way.
            let (s, c) = (-roll).sin_cos();
            for (deg, len) in [
                (0.0, 3.0),
                (10.0, 0.3),
                (-10.0, 0.3),
                (20.0, 0.2),
                (-20.0, 0.2),
            ] {
                let off = (-pitch.to_degrees() + deg) / 30.0;
                let (cx, cy) = (-off * s, off * c);
                ctx.draw(&CLine {
                    x1: cx - len * c,
                    y1: cy - len * s,
                    x2: cx + len * c,
                    y2: cy + len * s,
                    color: if deg == 0.0 { colour } else { Color::Gray },
                });
            }
            // The aircraft symbol, fixed.
            for (x1, y1, x2, y2) in [
                (-0.5, 0.0, -0.15, 0.0),
                (0.15, 0.0, 0.5, 0.0),
                (-0.15, 0.0, 0.0, -0.1),
                (0.0, -0.1, 0.15, 0.0),
            ] {
                ctx.draw(&CLine {
                    x1,
                    y1,
                    x2,
                    y2,
                    color: Color::Yellow,
                });
            }
        });
    f.render_widget(canvas, horizon);

    // Numbers.
    let [nums, pwm] = Layout::vertical([Constraint::Length(9), Constraint::Min(4)]).areas(right);
    let mut lines = Vec::new();
    match (vehicle, att) {
        (Some(v), Some(a)) => {
            let d = |x: f32| f64::from(x).to_degrees();
            for (i, name) in ["Roll", "Pitch", "Yaw"].iter().enumerate() {
                lines.push(Line::raw(format!(
                    "{name:<6}{:+8.1}°   rate {:+7.1}°/s",
                    d(a.rpy_rad[i]),
                    d(a.rates_rad_s[i])
                )));
            }
            let stale_pos = age_s(snap, v, 32).filter(|a| *a > STALE_S);
            match (stale_att, stale_pos) {
                (Some(a), Some(p)) => lines.push(Line::styled(
                    format!("STALE: attitude {a:.1} s, position {p:.1} s old"),
                    Style::new().fg(Color::Yellow),
                )),
                (Some(a), None) => lines.push(Line::styled(
                    format!("attitude stale: last {a:.1} s ago"),
                    Style::new().fg(Color::Yellow),
                )),
                (None, Some(p)) => lines.push(Line::styled(
                    format!("position stale: last {p:.1} s ago"),
                    Style::new().fg(Color::Yellow),
                )),
                (None, None) => {}
            }
            let sp = setpoint_ned(app, v);
            match v.position {
                Some(p) => {
                    let [n, e, dn] = p.pos_ned_m;
                    let fmt_sp = |x: Option<f32>| {
                        x.filter(|x| x.is_finite())
                            .map_or_else(|| "      -".to_owned(), |x| format!("{x:+7.2}"))
                    };
                    lines.push(Line::raw(format!(
                        "Alt   {:+7.2} m  setpoint {} m",
                        -dn,
                        fmt_sp(sp.map(|s| -s[2]))
                    )));
                    lines.push(Line::raw(format!(
                        "North {n:+7.2} m  setpoint {} m",
                        fmt_sp(sp.map(|s| s[0]))
                    )));
                    lines.push(Line::raw(format!(
                        "East  {e:+7.2} m  setpoint {} m",
                        fmt_sp(sp.map(|s| s[1]))
                    )));
                    lines.push(Line::raw(format!(
                        "Vel   {:+5.2} {:+5.2} {:+5.2} m/s (N E D)",
                        p.vel_ned_m_s[0], p.vel_ned_m_s[1], p.vel_ned_m_s[2]
                    )));
                }
                None => lines.push(Line::raw("no position yet")),
            }
        }
        (Some(_), None) => lines.push(Line::raw("no attitude yet")),
        (None, _) => lines.push(Line::raw("no vehicle yet")),
    }
    f.render_widget(
        Paragraph::new(lines).block(Block::bordered().title(" Attitude and position ")),
        nums,
    );

    // PWM bars.
    let block = Block::bordered().title(" Outputs (PWM) ");
    let inner = block.inner(pwm);
    f.render_widget(block, pwm);
    if let Some(v) = vehicle {
        let names = servo_names(app);
        let used: Vec<usize> = (0..8).filter(|i| v.servo_us[*i] != 0).collect();
        // One row each, in output order, as many as fit.
        let rows = (0..inner.height).map(|k| Rect {
            y: inner.y + k,
            height: 1,
            ..inner
        });
        for (row, i) in rows.zip(&used) {
            let us = v.servo_us[*i];
            let label = format!("{:<13} {us:>4} µs ", names[*i]);
            let width = usize::from(row.width).saturating_sub(label.chars().count());
            f.render_widget(Paragraph::new(pwm_bar(label, us, width)), row);
        }
    }

    // Messages from the vehicle and what the operator did.
    let [texts, events] =
        Layout::horizontal([Constraint::Percentage(55), Constraint::Percentage(45)]).areas(bottom);
    let h = texts.height.saturating_sub(2) as usize;
    let lines: Vec<Line> = vehicle
        .map(|v| {
            informative_texts(&v.status_texts)
                .into_iter()
                .rev()
                .take(h)
                .rev()
                .map(|(sev, t)| Line::styled(t.to_owned(), severity_style(sev)))
                .collect()
        })
        .unwrap_or_default();
    f.render_widget(
        Paragraph::new(lines).block(Block::bordered().title(" Vehicle messages ")),
        texts,
    );
    let lines: Vec<Line> = app
        .log
        .iter()
        .rev()
        .take(h)
        .rev()
        .map(|(l, t)| Line::styled(t.clone(), level_style(*l)))
        .collect();
    f.render_widget(
        Paragraph::new(lines)
            .wrap(Wrap { trim: true })
            .block(Block::bordered().title(" Operator ")),
        events,
    );
}

/// One output as a text bar over 1000–2000 µs: readable without colour.
pub(super) fn pwm_bar(label: String, us: u16, width: usize) -> Line<'static> {
    let ratio = ((f64::from(us) - 1000.0) / 1000.0).clamp(0.0, 1.0);
    let filled = (ratio * width as f64).round() as usize;
    Line::from(vec![
        Span::raw(label),
        Span::styled("█".repeat(filled), Style::new().fg(Color::Cyan)),
        Span::styled(
            "░".repeat(width - filled.min(width)),
            Style::new().fg(Color::DarkGray),
        ),
    ])
}

/// A compass tape of `width` columns centred on `yaw_deg`: labels above ticks, 2° a column.
#[must_use]
pub fn heading_tape(yaw_deg: f64, width: u16) -> Vec<Line<'static>> {
    let w = usize::from(width);
    let mut labels = vec![' '; w];
    let mut ticks = vec!['·'; w];
    let mid = w / 2;
    let step = 2.0;
    for (i, tick) in ticks.iter_mut().enumerate() {
        let a = yaw_deg + (i as f64 - mid as f64) * step;
        let a_round = (a / step).round() * step;
        let deg = a_round.rem_euclid(360.0).round() as i64 % 360;
        if deg % 10 == 0 {
            *tick = '|';
            let label = match deg {
                0 => "N".to_owned(),
                90 => "E".to_owned(),
                180 => "S".to_owned(),
                270 => "W".to_owned(),
                d if d % 30 == 0 => format!("{:02}", d / 10),
                _ => String::new(),
            };
            let start = i.saturating_sub(label.len() / 2);
            for (k, ch) in label.chars().enumerate() {
                if let Some(slot) = labels.get_mut(start + k) {
                    *slot = ch;
                }
            }
        }
    }
    if let Some(t) = ticks.get_mut(mid) {
        *t = '▼';
    }
    let hdg = format!("{:03}°", (yaw_deg.round() as i64).rem_euclid(360));
    let start = mid.saturating_sub(2);
    let mut labels: String = labels.into_iter().collect();
    if start + hdg.chars().count() <= w {
        let prefix: String = labels.chars().take(start).collect();
        let suffix: String = labels.chars().skip(start + hdg.chars().count()).collect();
        labels = format!("{prefix}{hdg}{suffix}");
    }
    vec![
        Line::styled(labels, Style::new().fg(Color::Yellow)),
        Line::raw(ticks.into_iter().collect::<String>()),
    ]
}

/// The vehicle's texts without repeats of an informational one (a version banner sent again at
/// every parameter download) since the last boot; warnings and refusals always show.
fn informative_texts(texts: &std::collections::VecDeque<(u8, String)>) -> Vec<(u8, &str)> {
    let mut seen = std::collections::HashSet::new();
    let mut out = Vec::new();
    for (sev, t) in texts {
        if t == "Rebooted" {
            seen.clear();
        }
        if *sev >= 6 && !seen.insert(t.as_str()) {
            continue;
        }
        out.push((*sev, t.as_str()));
    }
    out
}
