//! The Flight view: attitude, position, setpoint, outputs and the heading tape.

use ratatui::Frame;
use ratatui::layout::{Constraint, Layout, Rect};
use ratatui::style::{Color, Modifier, Style};
use ratatui::symbols::Marker;
use ratatui::text::{Line, Span};
use ratatui::widgets::canvas::{Canvas, Line as CLine};
use ratatui::widgets::{Block, Paragraph, Wrap};

use super::{STALE_S, Snapshot, age_s, level_style, servo_names, severity_style};
use vtol_link::protocol::id::{ATTITUDE, LOCAL_POSITION_NED};

use super::setpoint::{setpoint_ned, shown_attitude};
use crate::tracker::state::VehicleView;
use crate::tui::app::App;

/// Width from which the Flight view adds a column of charts.
const WIDE: u16 = 160;

/// Rows of the message panes under the instruments: none on a crowded screen, more on a tall one.
fn bottom_rows(height: u16) -> u16 {
    let rows = if height >= 40 {
        height / 4
    } else {
        height.saturating_sub(14).min(8)
    };
    if rows < 3 { 0 } else { rows }
}

pub(super) fn draw_flight(f: &mut Frame<'_>, app: &App, snap: &Snapshot<'_>, area: Rect) {
    let [top, bottom] = Layout::vertical([
        Constraint::Min(12),
        Constraint::Length(bottom_rows(area.height)),
    ])
    .areas(area);
    let vehicle = app.vehicle(snap.state);
    let outputs: Vec<usize> = vehicle
        .map(|v| (0..8).filter(|i| v.servo_us[*i] != 0).collect())
        .unwrap_or_default();
    let (left, right, charts) = if area.width >= WIDE {
        let [l, r, c] = Layout::horizontal([
            Constraint::Percentage(28),
            Constraint::Percentage(30),
            Constraint::Percentage(42),
        ])
        .areas(top);
        (l, r, Some(c))
    } else {
        let [l, r] =
            Layout::horizontal([Constraint::Percentage(45), Constraint::Percentage(55)]).areas(top);
        (l, r, None)
    };
    // The outputs under the horizon, every one on its row; the numbers take the other column.
    let out_rows = u16::try_from(outputs.len().max(1)).unwrap_or(8) + 2;
    let [horizon_area, pwm] =
        Layout::vertical([Constraint::Min(5), Constraint::Length(out_rows)]).areas(left);
    let shown = vehicle.and_then(|v| shown_attitude(app, snap, v));
    draw_horizon(f, snap, vehicle, shown, horizon_area);
    let title = match shown.and_then(|s| s.frame.label()) {
        Some(frame) => format!(" Attitude ({frame}) and position "),
        None => " Attitude and position ".to_owned(),
    };
    f.render_widget(
        Paragraph::new(numbers(
            app,
            snap,
            vehicle,
            shown,
            right.width.saturating_sub(2),
        ))
        .block(Block::bordered().title(title)),
        right,
    );
    draw_outputs(f, app, vehicle, &outputs, pwm);
    if let (Some(c), Some(v)) = (charts, vehicle) {
        super::charts::draw_flight_charts(f, app, snap, v, c);
    }
    if bottom.height > 0 {
        draw_texts(f, app, vehicle, bottom);
    }
}

fn draw_horizon(
    f: &mut Frame<'_>,
    snap: &Snapshot<'_>,
    vehicle: Option<&VehicleView>,
    att: Option<crate::tui::attitude::Shown>,
    area: Rect,
) {
    let stale_att = vehicle
        .and_then(|v| age_s(snap, v, ATTITUDE))
        .filter(|a| *a > STALE_S);
    let title = match att.and_then(|a| a.frame.label()) {
        Some(frame) => format!(" Horizon ({frame}) "),
        None => " Horizon ".to_owned(),
    };
    let block = Block::bordered().title(title);
    let inner = block.inner(area);
    f.render_widget(block, area);
    let [tape, horizon] =
        Layout::vertical([Constraint::Length(2), Constraint::Min(2)]).areas(inner);
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
}

/// The attitude, position against the setpoint, air data, VTOL state and the mission's
/// progress, one line each, in `width` columns.
fn numbers(
    app: &App,
    snap: &Snapshot<'_>,
    vehicle: Option<&VehicleView>,
    shown: Option<crate::tui::attitude::Shown>,
    width: u16,
) -> Vec<Line<'static>> {
    let mut lines = Vec::new();
    let (v, a) = match (vehicle, shown) {
        (Some(v), Some(a)) => (v, a),
        (Some(_), None) => return vec![Line::raw("no attitude yet")],
        (None, _) => return vec![Line::raw("no vehicle yet")],
    };
    // A lost vehicle's figures are history: said so first, greyed, and no air data.
    let lost = v.is_lost(snap.now);
    if lost {
        lines.push(Line::styled(
            format!(
                "LINK LOST {:.0} s: last known values",
                snap.now
                    .saturating_duration_since(v.last_heartbeat)
                    .as_secs_f64()
            ),
            Style::new().fg(Color::Red).add_modifier(Modifier::BOLD),
        ));
    }
    let d = |x: f32| f64::from(x).to_degrees();
    for (i, name) in ["Roll", "Pitch", "Yaw"].iter().enumerate() {
        lines.push(Line::raw(format!(
            "{name:<6}{:+8.1}°   rate {:+7.1}°/s",
            d(a.rpy_rad[i]),
            d(a.rates_rad_s[i])
        )));
    }
    let stale_att = age_s(snap, v, ATTITUDE).filter(|a| *a > STALE_S);
    let stale_pos = age_s(snap, v, LOCAL_POSITION_NED).filter(|a| *a > STALE_S);
    let stale = match (stale_att, stale_pos) {
        (Some(a), Some(p)) => Some(format!("STALE: attitude {a:.1} s, position {p:.1} s old")),
        (Some(a), None) => Some(format!("attitude stale: last {a:.1} s ago")),
        (None, Some(p)) => Some(format!("position stale: last {p:.1} s ago")),
        (None, None) => None,
    };
    if let Some(s) = stale {
        lines.push(Line::styled(s, Style::new().fg(Color::Yellow)));
    }
    lines.extend(position_lines(app, snap, v));
    if lost {
        lines = lines
            .into_iter()
            .enumerate()
            .map(|(i, l)| {
                if i == 0 {
                    l
                } else {
                    l.style(Style::new().fg(Color::DarkGray))
                }
            })
            .collect();
        lines.push(Line::styled(
            "Air       - m/s  AoA      -  SSA      -",
            Style::new().fg(Color::DarkGray),
        ));
        lines.push(Line::styled("VTOL  -", Style::new().fg(Color::DarkGray)));
    } else {
        lines.extend(air_lines(app, snap, v));
        let mission = app.map.mission.as_deref();
        if let Some(m) = crate::tui::progress::mission_line(snap.state, v, mission, snap.now) {
            lines.push(Line::raw(m.text(usize::from(width))));
        }
    }
    lines
}

/// Altitude, north and east against the setpoint, where the setpoint comes from, the velocity.
fn position_lines(app: &App, snap: &Snapshot<'_>, v: &VehicleView) -> Vec<Line<'static>> {
    let mut lines = Vec::new();
    let sp = setpoint_ned(app, snap, v);
    match v.position {
        Some(p) => {
            let [n, e, dn] = p.pos_ned_m;
            let fmt_sp = |x: Option<f32>| {
                x.filter(|x| x.is_finite())
                    .map_or_else(|| "      -".to_owned(), |x| format!("{x:+7.2}"))
            };
            let t = sp.map(|(t, _)| t);
            lines.push(Line::raw(format!(
                "Alt   {:+7.2} m  setpoint {} m",
                -dn,
                fmt_sp(t.map(|s| -s[2]))
            )));
            lines.push(Line::raw(format!(
                "North {n:+7.2} m  setpoint {} m",
                fmt_sp(t.map(|s| s[0]))
            )));
            lines.push(Line::raw(format!(
                "East  {e:+7.2} m  setpoint {} m",
                fmt_sp(t.map(|s| s[1]))
            )));
            if let Some((_, src)) = sp {
                lines.push(Line::styled(
                    src.words().to_owned(),
                    Style::new().fg(Color::DarkGray),
                ));
            }
            lines.push(Line::raw(format!(
                "Vel   {:+5.2} {:+5.2} {:+5.2} m/s (N E D)",
                p.vel_ned_m_s[0], p.vel_ned_m_s[1], p.vel_ned_m_s[2]
            )));
        }
        None => lines.push(Line::raw("no position yet")),
    }
    lines
}

/// Airspeed, angle of attack and sideslip; the VTOL state and a transition's progress.
fn air_lines(app: &App, snap: &Snapshot<'_>, v: &VehicleView) -> Vec<Line<'static>> {
    let min = app.params.value("ARSPD_FBW_MIN");
    let air = crate::tui::air::air(snap.state, v, min, super::tailsitter(app, v));
    let num = |x: Option<f32>, f: &dyn Fn(f32) -> String| x.map_or_else(|| "-".to_owned(), f);
    let air_line = format!(
        "Air   {:>5} m/s  AoA {:>6}  SSA {:>6}",
        num(air.airspeed_m_s, &|a| format!("{a:.1}")),
        num(air.aoa_deg, &|a| format!("{a:+.1}°")),
        num(air.ssa_deg, &|a| format!("{a:+.1}°")),
    );
    let vtol = match (air.vtol, air.progress) {
        (None, _) => Line::raw("VTOL  -"),
        (Some(s), Some(p)) => Line::styled(
            format!(
                "VTOL  {:<3}  transition {:>3.0}% {}",
                s.label(),
                p * 100.0,
                match s {
                    crate::tui::air::Vtol::ToFw => format!(
                        "(of {:.0} m/s)",
                        min.unwrap_or(crate::tui::air::ARSPD_FBW_MIN_DEFAULT)
                    ),
                    _ => "(nose up)".to_owned(),
                }
            ),
            Style::new().fg(Color::Yellow),
        ),
        (Some(s), None) => Line::raw(format!("VTOL  {}", s.label())),
    };
    vec![Line::raw(air_line), vtol]
}

fn draw_outputs(
    f: &mut Frame<'_>,
    app: &App,
    vehicle: Option<&VehicleView>,
    used: &[usize],
    area: Rect,
) {
    let block = Block::bordered().title(" Outputs (PWM) ");
    let inner = block.inner(area);
    f.render_widget(block, area);
    let Some(v) = vehicle else { return };
    let names = servo_names(app);
    // One row each, in output order, as many as fit.
    let rows = (0..inner.height).map(|k| Rect {
        y: inner.y + k,
        height: 1,
        ..inner
    });
    let w = used
        .iter()
        .map(|i| names[*i].chars().count())
        .max()
        .unwrap_or(0);
    for (row, i) in rows.zip(used) {
        let us = v.servo_us[*i];
        let label = format!("{:<w$} {us:>4} µs ", names[*i]);
        let width = usize::from(row.width).saturating_sub(label.chars().count());
        f.render_widget(Paragraph::new(pwm_bar(label, us, width)), row);
    }
}

/// Messages from the vehicle and what the operator did.
fn draw_texts(f: &mut Frame<'_>, app: &App, vehicle: Option<&VehicleView>, area: Rect) {
    let [texts, events] =
        Layout::horizontal([Constraint::Percentage(55), Constraint::Percentage(45)]).areas(area);
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
