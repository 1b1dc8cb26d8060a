//! The header (mode, state, link health, the fleet list) and the footer.

use ratatui::Frame;
use ratatui::layout::Rect;
use ratatui::style::{Color, Modifier, Style};
use ratatui::text::{Line, Span};
use ratatui::widgets::Paragraph;

use vtol_link::dialect::MavState;

use super::{Snapshot, level_style};
use crate::links::Side;
use crate::tracker::state::VehicleView;
use crate::tui::air::air;
use crate::tui::app::{App, View};
use crate::vitals::{Severity, Vitals, vitals};

pub(super) fn draw_header(f: &mut Frame<'_>, app: &App, snap: &Snapshot<'_>, area: Rect) {
    let now = snap.now;
    let mut spans = vec![Span::styled(
        " vtol-gcs ",
        Style::new().add_modifier(Modifier::REVERSED),
    )];
    match app.vehicle(snap.state) {
        None => spans.push(Span::styled(
            " waiting for a vehicle heartbeat",
            Style::new().fg(Color::Yellow),
        )),
        Some(v) => {
            let lost = v.is_lost(now);
            spans.push(Span::raw(format!(" sys {} ", v.system_id)));
            spans.push(Span::styled(
                v.mode_name(),
                Style::new().add_modifier(Modifier::BOLD),
            ));
            spans.push(Span::raw(" "));
            spans.push(Span::styled(
                crate::words::armed(v.armed),
                if v.armed {
                    Style::new().fg(Color::Red).add_modifier(Modifier::BOLD)
                } else {
                    Style::new().fg(Color::Green)
                },
            ));
            spans.push(Span::raw(" "));
            spans.push(Span::styled(
                crate::words::mav_state(v.system_status),
                status_style(v.system_status),
            ));
            if app.replay {
                spans.push(Span::styled(
                    " │ REPLAY",
                    Style::new().fg(Color::Cyan).add_modifier(Modifier::BOLD),
                ));
            }
            // A lost vehicle's clock stops at its last heartbeat: nothing says it still flies.
            let until = if lost { v.last_heartbeat } else { now };
            let flight = v
                .armed_since
                .map_or(0, |t| until.saturating_duration_since(t).as_secs());
            spans.push(Span::raw(format!(
                " │ flight {:02}:{:02}",
                flight / 60,
                flight % 60
            )));
            if lost {
                spans.push(Span::styled(
                    format!(
                        " │ LINK LOST {:.0} s ",
                        now.saturating_duration_since(v.last_heartbeat)
                            .as_secs_f64()
                    ),
                    Style::new()
                        .fg(Color::White)
                        .bg(Color::Red)
                        .add_modifier(Modifier::BOLD),
                ));
            }
        }
    }
    // With several vehicle links (a fleet over Zenoh, several UDP peers) the header shows the
    // health of the shown vehicle's link; the vehicle list has every vehicle's.
    let vehicle_links = snap.links.iter().filter(|l| l.side == Side::Vehicle);
    let shown_link = app
        .vehicle(snap.state)
        .map(|v| v.link)
        .filter(|_| vehicle_links.clone().count() > 1);
    // A lost vehicle shows no live figures: its link's rate belongs to the others on it.
    let shown_lost = app.vehicle(snap.state).is_some_and(|v| v.is_lost(now));
    for l in vehicle_links.filter(|l| !shown_lost && shown_link.is_none_or(|s| s == l.id)) {
        if let Some(h) = snap.state.links.get(&l.id) {
            spans.push(Span::raw(format!(
                " │ {:.0} Hz {:.1}% loss",
                h.window.rate_hz(now),
                h.window.loss_pct(now)
            )));
        }
    }
    if let Some(c) = snap.router.conflict {
        spans.push(Span::styled(
            format!(
                " │ CONFLICT sys {} on {} and {} ",
                c.system, c.owner, c.claimant
            ),
            Style::new()
                .fg(Color::White)
                .bg(Color::Red)
                .add_modifier(Modifier::BOLD),
        ));
    }
    let mut tabs = Vec::new();
    for v in View::all() {
        let style = if *v == app.view {
            Style::new().add_modifier(Modifier::REVERSED | Modifier::BOLD)
        } else {
            Style::new().fg(Color::DarkGray)
        };
        tabs.push(Span::styled(format!(" {} ", v.title()), style));
        tabs.push(Span::raw(" "));
    }
    tabs.push(Span::styled(
        "  ?: help  q: quit",
        Style::new().fg(Color::DarkGray),
    ));
    let mut lines = vec![Line::from(spans)];
    lines.extend(vitals_lines(app, snap, area.width));
    lines.push(Line::from(tabs));
    f.render_widget(Paragraph::new(lines), area);
}

/// The vitals rows of the shown vehicle, as many as `width` needs (one on a wide terminal).
pub(super) fn vitals_lines(app: &App, snap: &Snapshot<'_>, width: u16) -> Vec<Line<'static>> {
    match app.vehicle(snap.state) {
        None => vec![Line::raw("")],
        Some(v) if v.is_lost(snap.now) => vec![Line::styled(
            " no live figures: the link is lost",
            Style::new().fg(Color::DarkGray),
        )],
        Some(v) => {
            let mut items = vitals_items(&vitals(snap.state, v));
            items.push(air_item(app, snap, v));
            pack(items, width)
        }
    }
}

/// The VTOL state (with a transition's progress), airspeed and angle of attack; `-` for what
/// the vehicle does not report.
fn air_item(app: &App, snap: &Snapshot<'_>, v: &VehicleView) -> Vec<Span<'static>> {
    let a = air(
        snap.state,
        v,
        app.params.value("ARSPD_FBW_MIN"),
        super::tailsitter(app, v),
    );
    let grey = Style::new().fg(Color::DarkGray);
    let mut spans = Vec::new();
    match (a.vtol, a.progress) {
        (Some(s), Some(p)) => spans.push(Span::styled(
            format!("{} {:.0}%", s.label(), p * 100.0),
            Style::new().fg(Color::Yellow).add_modifier(Modifier::BOLD),
        )),
        (Some(s), None) => spans.push(Span::raw(s.label())),
        (None, _) => spans.push(Span::styled("VTOL -", grey)),
    }
    spans.push(Span::raw(" "));
    spans.push(match a.airspeed_m_s {
        Some(x) => Span::raw(format!("air {x:.1} m/s")),
        None => Span::styled("air -", grey),
    });
    spans.push(Span::raw(" "));
    spans.push(match a.aoa_deg {
        Some(x) => Span::raw(format!("AoA {x:+.1}°")),
        None => Span::styled("AoA -", grey),
    });
    spans
}

/// Lays items out left to right with separators, starting a new row where the next would not
/// fit.
fn pack(items: Vec<Vec<Span<'static>>>, width: u16) -> Vec<Line<'static>> {
    let width = usize::from(width);
    let mut lines = Vec::new();
    let mut row: Vec<Span<'static>> = vec![Span::raw(" ")];
    let mut used = 1;
    for item in items {
        let w: usize = item.iter().map(Span::width).sum();
        if used > 1 && used + 3 + w > width {
            lines.push(Line::from(std::mem::replace(
                &mut row,
                vec![Span::raw(" ")],
            )));
            used = 1;
        }
        if used > 1 {
            row.push(Span::raw(" │ "));
            used += 3;
        }
        row.extend(item);
        used += w;
    }
    lines.push(Line::from(row));
    lines
}

fn status_style(s: MavState) -> Style {
    match s {
        MavState::MAV_STATE_CRITICAL => Style::new().fg(Color::Yellow).add_modifier(Modifier::BOLD),
        MavState::MAV_STATE_EMERGENCY | MavState::MAV_STATE_FLIGHT_TERMINATION => {
            Style::new().fg(Color::Red).add_modifier(Modifier::BOLD)
        }
        _ => Style::new(),
    }
}

/// The colour of a severity.
pub(super) fn severity_colour(s: Severity) -> Style {
    match s {
        Severity::Ok => Style::new().fg(Color::Green),
        Severity::Warn => Style::new().fg(Color::Yellow).add_modifier(Modifier::BOLD),
        Severity::Bad => Style::new().fg(Color::Red).add_modifier(Modifier::BOLD),
    }
}

/// The vitals: a failsafe banner and the reason for a CRITICAL/EMERGENCY state first, then
/// battery, GPS, home and health, each coloured by its severity.
pub(super) fn vitals_items(v: &Vitals) -> Vec<Vec<Span<'static>>> {
    let alarm = Style::new()
        .fg(Color::White)
        .bg(Color::Red)
        .add_modifier(Modifier::BOLD);
    let grey = Style::new().fg(Color::DarkGray);
    let mut items = Vec::new();
    if let Some(fs) = &v.failsafe {
        items.push(vec![Span::styled(format!(" {fs} "), alarm)]);
    }
    if let Some(r) = &v.reason {
        items.push(vec![Span::styled(format!("why: {r}"), alarm)]);
    }
    items.push(vec![match &v.battery {
        Some(b) => Span::styled(format!("BAT {}", b.summary()), severity_colour(b.severity)),
        None => Span::styled("BAT -", grey),
    }]);
    items.push(vec![match v.gps {
        Some((fix, sats, sev)) => {
            Span::styled(format!("GPS {fix} {sats} sats"), severity_colour(sev))
        }
        None => Span::styled("GPS -", grey),
    }]);
    if let Some((d, b)) = v.home {
        items.push(vec![Span::raw(format!("home {d:.1} m {b:03.0}°"))]);
    }
    items.push(vec![if v.unhealthy.is_empty() {
        Span::styled("health ok", severity_colour(Severity::Ok))
    } else {
        Span::styled(
            format!("bad: {}", v.unhealthy.join(", ")),
            severity_colour(Severity::Bad),
        )
    }]);
    if v.rc == Some(false) {
        items.push(vec![Span::styled("no RC", grey)]);
    }
    items
}

/// One line per fleet: each vehicle with its link health, the selected one highlighted.
/// Rows the vehicle list may take under the header; more vehicles than fit scroll so that the
/// selected one shows.
pub(super) const VEHICLE_LIST_ROWS: usize = 3;

/// The vehicle list, wrapped to `width` over at most [`VEHICLE_LIST_ROWS`] rows. When the
/// vehicles do not all fit, the rows start at the selected one's row and say how many are
/// left out on each side.
pub(super) fn vehicle_list_lines(app: &App, snap: &Snapshot<'_>, width: u16) -> Vec<Line<'static>> {
    let now = snap.now;
    let selected = app
        .vehicle(snap.state)
        .map(|v| (v.system_id, v.component_id));
    let entries: Vec<(String, Style, bool)> = snap
        .state
        .vehicles
        .iter()
        .map(|(key, v)| {
            let text = if v.is_lost(now) {
                format!(
                    " {} LOST {:.0} s ",
                    v.system_id,
                    now.saturating_duration_since(v.last_heartbeat)
                        .as_secs_f64()
                )
            } else {
                format!(" {} ", v.summary(now))
            };
            let mut style = if v.is_lost(now) {
                Style::new().fg(Color::Red)
            } else if v.armed {
                Style::new().fg(Color::Yellow)
            } else {
                Style::new()
            };
            let is_selected = Some(*key) == selected;
            if is_selected {
                style = style.add_modifier(Modifier::REVERSED | Modifier::BOLD);
            }
            (text, style, is_selected)
        })
        .collect();
    let width = usize::from(width);
    let title = " vehicles (v/V) ";
    // Greedy rows of whole entries; a "+N" marker needs room at the end of a row.
    let marker = 8;
    let mut rows: Vec<Vec<usize>> = vec![Vec::new()];
    let mut used = title.len();
    for (i, (text, _, _)) in entries.iter().enumerate() {
        let w = text.chars().count() + 1;
        if used + w + marker > width && !rows.last().is_some_and(Vec::is_empty) {
            rows.push(Vec::new());
            used = 0;
        }
        used += w;
        if let Some(r) = rows.last_mut() {
            r.push(i);
        }
    }
    let sel_row = rows
        .iter()
        .position(|r| r.iter().any(|&i| entries[i].2))
        .unwrap_or(0);
    let first = if sel_row < VEHICLE_LIST_ROWS {
        0
    } else {
        sel_row + 1 - VEHICLE_LIST_ROWS
    };
    let shown = &rows[first..rows.len().min(first + VEHICLE_LIST_ROWS)];
    let before: usize = rows[..first].iter().map(Vec::len).sum();
    let after: usize = rows[first + shown.len()..].iter().map(Vec::len).sum();
    let dim = Style::new().fg(Color::DarkGray);
    let mut lines = Vec::new();
    for (n, row) in shown.iter().enumerate() {
        let mut spans = Vec::new();
        if n == 0 {
            spans.push(Span::styled(title, dim));
            if before > 0 {
                spans.push(Span::styled(format!("+{before} "), dim));
            }
        }
        for (k, &i) in row.iter().enumerate() {
            if k > 0 {
                spans.push(Span::raw("│"));
            }
            let (text, style, _) = &entries[i];
            spans.push(Span::styled(text.clone(), *style));
        }
        if n + 1 == shown.len() && after > 0 {
            spans.push(Span::styled(format!(" +{after} more"), dim));
        }
        lines.push(Line::from(spans));
    }
    lines
}

/// The footer's lines at `width`: the operator's last event, wrapped at words (a refusal's
/// reason whole, up to [`FOOTER_ROWS`] rows), else the keys.
pub(super) fn footer_lines(app: &App, width: u16) -> Vec<Line<'static>> {
    match app.log.back() {
        Some((l, t)) => {
            let mut rows = super::wrap(t, usize::from(width.saturating_sub(1)));
            if rows.len() > FOOTER_ROWS {
                rows.truncate(FOOTER_ROWS);
                if let Some(last) = rows.last_mut() {
                    last.push('…');
                }
            }
            rows.into_iter()
                .map(|r| Line::from(Span::styled(format!(" {r}"), level_style(*l))))
                .collect()
        }
        None if app.replay => vec![Line::from(Span::styled(
            " replay: a recorded log; no commands  Tab views  ? help  q quit",
            Style::new().fg(Color::DarkGray),
        ))],
        None => vec![Line::from(Span::styled(
            " a arm  d disarm  t QHOVER  l QLAND  p QLOITER  m modes  x/c/z push",
            Style::new().fg(Color::DarkGray),
        ))],
    }
}

/// Most rows the footer takes for a long event.
pub(super) const FOOTER_ROWS: usize = 3;

pub(super) fn draw_footer(f: &mut Frame<'_>, app: &App, area: Rect) {
    f.render_widget(Paragraph::new(footer_lines(app, area.width)), area);
}
