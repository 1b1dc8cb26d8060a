//! Drawing: one function per view over a [`Snapshot`] of everything shown. Pure apart from the
//! chart cache, so whole frames render into ratatui's `TestBackend` for snapshot tests.

use std::collections::BTreeMap;
use std::fmt::Write as _;
use std::time::Instant;

use ratatui::Frame;
use ratatui::layout::{Alignment, Constraint, Layout, Rect};
use ratatui::style::{Color, Modifier, Style};
use ratatui::symbols::Marker;
use ratatui::text::{Line, Span};
use ratatui::widgets::canvas::{Canvas, Line as CLine};
use ratatui::widgets::{
    Axis, Block, Borders, Cell, Chart, Clear, Dataset, Gauge, GraphType, Paragraph, Row, Table,
    Wrap,
};
use vtol_link::dialect::MavState;
use vtol_link::{ComponentId, SystemId};

use super::app::{App, Confirm, Level, ParamStatus, SeriesKey, View};
use super::fields;
use crate::tap::Side;
use crate::tracker::history::{History, TimedFrame};
use crate::tracker::state::{LINK_TIMEOUT, VehicleState, VehicleView};

/// Smallest terminal the views are laid out for.
pub const MIN_SIZE: (u16, u16) = (80, 24);
/// Attitude or position older than this is marked stale.
const STALE_S: f64 = 1.0;

/// One link as the UI shows it.
#[derive(Debug, Clone)]
pub struct LinkRow {
    /// Link id.
    pub id: vtol_link::LinkId,
    /// Vehicle or client.
    pub side: Side,
    /// Peer.
    pub peer: String,
    /// Whether it is the daemon's own traffic (not a client).
    pub own: bool,
    /// Counters.
    pub stats: vtol_link::LinkStatsSnapshot,
    /// A client endpoint's policy when it is not the default, and what it did.
    pub policy: Option<(
        crate::trust::policy::EndpointPolicy,
        crate::trust::policy::PolicyCountersSnapshot,
    )>,
}

/// Router-wide counters.
#[derive(Debug, Clone, Copy, Default)]
pub struct RouterCounters {
    /// Frames in.
    pub frames_in: u64,
    /// Copies out.
    pub frames_out: u64,
    /// Targeted at a system never seen.
    pub unroutable: u64,
    /// SETUP_SIGNING withheld.
    pub withheld_signing: u64,
    /// Link closed between routing and queueing.
    pub dropped_link_closed: u64,
    /// Tracker behind.
    pub dropped_tap: u64,
    /// Vehicle frames refused by the signing check (0 without a key).
    pub signing_refused: u64,
    /// Vehicle frames refused because another vehicle link owns their system id.
    pub sysid_conflicts: u64,
    /// A system id two vehicle links claim now (the first, if several).
    pub conflict: Option<crate::tap::SysidConflict>,
}

/// The tlog as shown.
#[derive(Debug, Clone, Default)]
pub struct TlogInfo {
    /// File.
    pub path: String,
    /// Bytes written.
    pub bytes: u64,
    /// Records written.
    pub records: u64,
    /// Records dropped (writer behind).
    pub dropped: u64,
    /// Write errors.
    pub errors: u64,
    /// The write error while logging fails (a full disk); `None` while it writes.
    pub failing: Option<String>,
}

/// Everything one frame shows.
#[derive(Debug)]
pub struct Snapshot<'a> {
    /// The time the frame describes.
    pub now: Instant,
    /// Tracker state.
    pub state: &'a VehicleState,
    /// Recent past.
    pub history: &'a History,
    /// Live links.
    pub links: Vec<LinkRow>,
    /// Router counters.
    pub router: RouterCounters,
    /// The tlog, if logging.
    pub tlog: Option<TlogInfo>,
    /// Where the daemon serves clients.
    pub serving: Vec<String>,
}

/// Field series read incrementally from the history's raw frames (each frame decoded once).
#[derive(Debug, Default)]
pub struct SeriesCache {
    series: BTreeMap<SeriesKey, (u64, Vec<(f64, f64)>)>,
}

impl SeriesCache {
    /// The points of `key` in the history, decoding only frames not seen before.
    fn points(&mut self, key: &SeriesKey, history: &History) -> &[(f64, f64)] {
        let entry = self
            .series
            .entry(key.clone())
            .or_insert_with(|| (0, Vec::new()));
        let frames = history
            .frames
            .get(&(key.system, key.component, key.message));
        if let Some(frames) = frames {
            let oldest = frames.oldest_t_s().unwrap_or(0.0);
            entry.1.retain(|(t, _)| *t >= oldest);
            for TimedFrame { index, t_s, frame } in frames.since(entry.0) {
                if let Ok(msg) = frame.decode()
                    && let Some(v) = fields::value_at(&msg, &key.path)
                {
                    entry.1.push((t_s, v));
                }
                entry.0 = index + 1;
            }
        }
        &entry.1
    }
}

fn severity_style(sev: u8) -> Style {
    match sev {
        0..=3 => Style::new().fg(Color::Red).add_modifier(Modifier::BOLD),
        4 => Style::new().fg(Color::Yellow),
        5 => Style::new().fg(Color::Cyan),
        6 => Style::new(),
        _ => Style::new().fg(Color::DarkGray),
    }
}

fn level_style(l: Level) -> Style {
    match l {
        Level::Info => Style::new(),
        Level::Ok => Style::new().fg(Color::Green),
        Level::Error => Style::new().fg(Color::Red),
    }
}

/// Name of an output from its `SERVOn_FUNCTION` (ArduPilot's numbers), counting ESCs and
/// ailerons in output order; `SERVOn` when the function is unknown or not published.
#[must_use]
pub fn output_names(functions: &[Option<f32>]) -> Vec<String> {
    let (mut escs, mut ailerons) = (0, 0);
    functions
        .iter()
        .enumerate()
        .map(|(i, f)| match f.map(|v| v as i32) {
            Some(33..=40 | 70 | 73 | 74) => {
                escs += 1;
                format!("ESC{escs}")
            }
            Some(4) => {
                ailerons += 1;
                match ailerons {
                    1 => "left aileron".to_owned(),
                    2 => "right aileron".to_owned(),
                    n => format!("aileron {n}"),
                }
            }
            Some(19) => "elevator".to_owned(),
            Some(21) => "rudder".to_owned(),
            _ => format!("SERVO{}", i + 1),
        })
        .collect()
}

fn servo_names(app: &App) -> Vec<String> {
    let f: Vec<Option<f32>> = (1..=8)
        .map(|i| app.params.value(&format!("SERVO{i}_FUNCTION")))
        .collect();
    output_names(&f)
}

fn status_name(s: MavState) -> &'static str {
    match s {
        MavState::MAV_STATE_UNINIT => "UNINIT",
        MavState::MAV_STATE_BOOT => "BOOT",
        MavState::MAV_STATE_CALIBRATING => "CALIBRATING",
        MavState::MAV_STATE_STANDBY => "STANDBY",
        MavState::MAV_STATE_ACTIVE => "ACTIVE",
        MavState::MAV_STATE_CRITICAL => "CRITICAL",
        MavState::MAV_STATE_EMERGENCY => "EMERGENCY",
        MavState::MAV_STATE_POWEROFF => "POWEROFF",
        MavState::MAV_STATE_FLIGHT_TERMINATION => "TERMINATION",
    }
}

/// Draws the whole screen.
pub fn draw(f: &mut Frame<'_>, app: &mut App, snap: &Snapshot<'_>, cache: &mut SeriesCache) {
    let area = f.area();
    if area.width < MIN_SIZE.0 || area.height < MIN_SIZE.1 {
        let text = format!(
            "Terminal too small: {}x{}, need {}x{}. Enlarge it, or q to quit.",
            area.width, area.height, MIN_SIZE.0, MIN_SIZE.1
        );
        f.render_widget(
            Paragraph::new(text)
                .wrap(Wrap { trim: true })
                .style(Style::new().fg(Color::Yellow)),
            area,
        );
        return;
    }
    let fleet = if snap.state.vehicles.len() > 1 {
        vehicle_list_lines(app, snap, area.width)
    } else {
        Vec::new()
    };
    let list_rows = u16::try_from(fleet.len()).unwrap_or(u16::MAX);
    let [header, body, footer] = Layout::vertical([
        Constraint::Length(2 + list_rows),
        Constraint::Min(10),
        Constraint::Length(1),
    ])
    .areas(area);
    draw_header(f, app, snap, header);
    if !fleet.is_empty() {
        f.render_widget(
            Paragraph::new(fleet),
            Rect {
                y: header.y + 2,
                height: list_rows,
                ..header
            },
        );
    }
    match app.view {
        View::Flight => draw_flight(f, app, snap, body),
        View::Charts => draw_charts(f, app, snap, body),
        View::Links => draw_links(f, snap, body),
        View::Messages => draw_messages(f, app, snap, cache, body),
        View::Params => draw_params(f, app, body),
    }
    draw_footer(f, app, footer);
    if let Some(c) = &app.confirm {
        draw_confirm(f, app, c, area);
    }
    if app.help {
        draw_help(f, area);
    }
}

fn draw_header(f: &mut Frame<'_>, app: &App, snap: &Snapshot<'_>, area: Rect) {
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
            spans.push(if v.armed {
                Span::styled(
                    "ARMED",
                    Style::new().fg(Color::Red).add_modifier(Modifier::BOLD),
                )
            } else {
                Span::styled("disarmed", Style::new().fg(Color::Green))
            });
            spans.push(Span::raw(format!(" {}", status_name(v.system_status))));
            let flight = v
                .armed_since
                .map_or(0, |t| now.saturating_duration_since(t).as_secs());
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
    for l in vehicle_links.filter(|l| shown_link.is_none_or(|s| s == l.id)) {
        if let Some(h) = snap.state.links.get(&l.id) {
            spans.push(Span::raw(format!(
                " │ {:.0} Hz {:.1}% loss",
                h.rate_hz(now),
                h.loss_pct(now)
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
        "  Tab: next view  ?: help  q: quit",
        Style::new().fg(Color::DarkGray),
    ));
    f.render_widget(
        Paragraph::new(vec![Line::from(spans), Line::from(tabs)]),
        area,
    );
}

/// One line per fleet: each vehicle with its link health, the selected one highlighted.
/// Rows the vehicle list may take under the header; more vehicles than fit scroll so that the
/// selected one shows.
const VEHICLE_LIST_ROWS: usize = 3;

/// The vehicle list, wrapped to `width` over at most [`VEHICLE_LIST_ROWS`] rows. When the
/// vehicles do not all fit, the rows start at the selected one's row and say how many are
/// left out on each side.
fn vehicle_list_lines(app: &App, snap: &Snapshot<'_>, width: u16) -> Vec<Line<'static>> {
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
                format!(
                    " {} {} {} {:.0} Hz {:.1}% ",
                    v.system_id,
                    v.mode_name(),
                    if v.armed { "ARMED" } else { "disarmed" },
                    v.rate_hz(now),
                    v.loss_pct(now)
                )
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

fn draw_footer(f: &mut Frame<'_>, app: &App, area: Rect) {
    let line = match app.log.back() {
        Some((l, t)) => Line::from(Span::styled(format!(" {t}"), level_style(*l))),
        None => Line::from(Span::styled(
            " a arm  d disarm  t take off (QHOVER)  l land (QLAND)  p QLOITER  x/c/z push",
            Style::new().fg(Color::DarkGray),
        )),
    };
    f.render_widget(Paragraph::new(line), area);
}

fn centered(area: Rect, w: u16, h: u16) -> Rect {
    let w = w.min(area.width);
    let h = h.min(area.height);
    Rect {
        x: area.x + (area.width - w) / 2,
        y: area.y + (area.height - h) / 2,
        width: w,
        height: h,
    }
}

fn draw_confirm(f: &mut Frame<'_>, app: &App, c: &Confirm, area: Rect) {
    let mut lines = Vec::new();
    let title = match c {
        Confirm::Arm { force: false } => "Arm the vehicle?",
        Confirm::Arm { force: true } => "FORCE arm (skip pre-arm checks)?",
        Confirm::Disarm => "Disarm the vehicle (motors stop, even in the air)?",
        Confirm::Upload => "Upload these gains as one transaction?",
    };
    lines.push(Line::from(Span::styled(
        title,
        Style::new().add_modifier(Modifier::BOLD),
    )));
    if let (Confirm::Upload, Some(diff)) = (c, &app.params.diff) {
        for (name, now, wanted) in diff {
            let now = now.map_or_else(|| "(missing)".to_owned(), |v| v.to_string());
            lines.push(Line::raw(format!("  {name:<16} {now:>10} → {wanted}")));
        }
    }
    lines.push(Line::raw(""));
    lines.push(Line::raw("y: yes    any other key: cancel"));
    let h = (lines.len() as u16 + 2).min(area.height);
    let r = centered(area, 60, h);
    f.render_widget(Clear, r);
    f.render_widget(
        Paragraph::new(lines).block(
            Block::bordered()
                .title(" Confirm ")
                .border_style(Style::new().fg(Color::Yellow)),
        ),
        r,
    );
}

const HELP: &[(&str, &str)] = &[
    ("Tab / Shift-Tab", "next / previous view"),
    ("v / V", "next / previous vehicle (when several)"),
    ("?", "this help (any key closes it)"),
    ("q, Ctrl-C", "quit"),
    ("a / A / d", "arm / force arm / disarm (then y to confirm)"),
    ("t", "take off: QHOVER (climbs to HOVER_ALT when armed)"),
    ("l", "land: QLAND"),
    ("p / s", "QLOITER / QSTABILIZE"),
    (
        "arrows",
        "QLOITER: move the target 0.5 m north/south/east/west",
    ),
    ("PgUp / PgDn", "QLOITER: target 0.5 m up / down"),
    (
        "x X / c C / z Z",
        "push roll / pitch / yaw, + and - (SIM_PUSH_*)",
    ),
    ("+ / -", "chart window longer / shorter (5..120 s)"),
    ("Messages: ↑↓ ← →", "select message / field"),
    (
        "Messages: Enter",
        "add the field to the chart; n new chart; Del remove",
    ),
    ("Params: / Enter", "filter; edit the selected value"),
    (
        "Params: f / r",
        "load a gains file (diff, then upload) / download again",
    ),
    ("/ … Enter, Esc", "type a filter; Esc clears it"),
];

fn draw_help(f: &mut Frame<'_>, area: Rect) {
    let rows: Vec<Row> = HELP
        .iter()
        .map(|(k, v)| Row::new(vec![Cell::from(*k), Cell::from(*v)]))
        .collect();
    let r = centered(area, 78, HELP.len() as u16 + 2);
    f.render_widget(Clear, r);
    f.render_widget(
        Table::new(rows, [Constraint::Length(20), Constraint::Min(20)])
            .block(Block::bordered().title(" Keys ")),
        r,
    );
}

fn age_s(snap: &Snapshot<'_>, v: &VehicleView, msg: u32) -> Option<f64> {
    snap.state
        .messages
        .get(&(v.system_id, v.component_id, msg))
        .map(|m| snap.now.saturating_duration_since(m.last_at).as_secs_f64())
}

fn setpoint_ned(app: &App, v: &VehicleView) -> Option<[f32; 3]> {
    let hover = app.params.value("HOVER_ALT");
    match v.mode_name().as_str() {
        "QLOITER" => app
            .target_ned
            .or_else(|| hover.map(|h| [f32::NAN, f32::NAN, -h])),
        "QHOVER" => hover.map(|h| [f32::NAN, f32::NAN, -h]),
        _ => None,
    }
}

fn draw_flight(f: &mut Frame<'_>, app: &App, snap: &Snapshot<'_>, area: Rect) {
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
            if let Some(age) = stale_att {
                lines.push(Line::styled(
                    format!("attitude stale: last {age:.1} s ago"),
                    Style::new().fg(Color::Yellow),
                ));
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
            v.status_texts
                .iter()
                .rev()
                .take(h)
                .rev()
                .map(|(sev, t)| Line::styled(t.clone(), severity_style(*sev)))
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
fn pwm_bar(label: String, us: u16, width: usize) -> Line<'static> {
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

/// A chart series: name, colour, points (seconds before now, value).
type Series = (String, Color, Vec<(f64, f64)>);

/// One chart of several series over the window, y bounds from the data.
fn chart<'a>(title: String, series: &'a [Series], window_s: f64, unit: &str) -> Chart<'a> {
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

const COLOURS: [Color; 8] = [
    Color::Cyan,
    Color::Yellow,
    Color::Magenta,
    Color::Green,
    Color::Red,
    Color::Blue,
    Color::LightCyan,
    Color::LightYellow,
];

fn draw_charts(f: &mut Frame<'_>, app: &App, snap: &Snapshot<'_>, area: Rect) {
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

fn draw_links(f: &mut Frame<'_>, snap: &Snapshot<'_>, area: Rect) {
    let now = snap.now;
    let [table_area, rest] =
        Layout::vertical([Constraint::Min(6), Constraint::Length(9)]).areas(area);
    let header = Row::new([
        "id", "side", "peer", "rate Hz", "loss %", "heard", "rx", "tx", "dropped", "bad crc",
    ])
    .style(Style::new().add_modifier(Modifier::BOLD));
    let rows: Vec<Row> = snap
        .links
        .iter()
        .map(|l| {
            let h = snap.state.links.get(&l.id);
            let (rate, loss, heard, lost) = match h {
                Some(h) => (
                    format!("{:.1}", h.rate_hz(now)),
                    format!("{:.1}", h.loss_pct(now)),
                    format!(
                        "{:.1} s",
                        now.saturating_duration_since(h.last_heard).as_secs_f64()
                    ),
                    h.is_lost(now),
                ),
                None => ("0.0".into(), "-".into(), "never".into(), false),
            };
            let side = match (l.side, l.own) {
                (_, true) => "own",
                (Side::Vehicle, _) => "vehicle",
                (Side::Client, _) => "client",
            };
            let style = if lost {
                Style::new().fg(Color::Red)
            } else {
                Style::new()
            };
            // A policy shows beside the peer; rate-limit drops count with queue-full drops.
            let (peer, rate_dropped) = match &l.policy {
                Some((p, c)) => (format!("{} [{}]", l.peer, p.trust), c.dropped_rate),
                None => (l.peer.clone(), 0),
            };
            Row::new(vec![
                l.id.to_string(),
                side.to_owned(),
                peer,
                rate,
                loss,
                if lost { format!("LOST {heard}") } else { heard },
                l.stats.rx_frames.to_string(),
                l.stats.tx_frames.to_string(),
                (l.stats.tx_dropped_queue_full + rate_dropped).to_string(),
                l.stats.bad_crc.to_string(),
            ])
            .style(style)
        })
        .collect();
    f.render_widget(
        Table::new(
            rows,
            [
                Constraint::Length(8),
                Constraint::Length(8),
                Constraint::Min(14),
                Constraint::Length(8),
                Constraint::Length(7),
                Constraint::Length(11),
                Constraint::Length(8),
                Constraint::Length(8),
                Constraint::Length(8),
                Constraint::Length(8),
            ],
        )
        .header(header)
        .block(Block::bordered().title(" Links ")),
        table_area,
    );
    let [router, tlog] = Layout::horizontal([Constraint::Percentage(50); 2]).areas(rest);
    let r = snap.router;
    let clients = snap
        .links
        .iter()
        .filter(|l| l.side == Side::Client && !l.own)
        .count();
    // Refused vehicle frames share the signing line, shown only when there are some.
    let refused = if r.signing_refused > 0 {
        format!("  refused {}", r.signing_refused)
    } else {
        String::new()
    };
    let conflicts = if r.sysid_conflicts > 0 {
        format!("\nsysid conflict {}", r.sysid_conflicts)
    } else {
        String::new()
    };
    let text = format!(
        "clients        {clients}\nframes in      {}\ncopies out     {}\nunroutable     {}\nsigning held   {}{refused}\nlink closed    {}\ntracker behind {}{conflicts}",
        r.frames_in,
        r.frames_out,
        r.unroutable,
        r.withheld_signing,
        r.dropped_link_closed,
        r.dropped_tap
    );
    f.render_widget(
        Paragraph::new(text).block(Block::bordered().title(" Router ")),
        router,
    );
    let mut text = String::new();
    match &snap.tlog {
        Some(t) => {
            let _ = write!(
                text,
                "{}\n{:.1} kB, {} records\n{} dropped, {} write errors\n",
                t.path,
                t.bytes as f64 / 1000.0,
                t.records,
                t.dropped,
                t.errors
            );
            if let Some(why) = &t.failing {
                let _ = writeln!(text, "NOT WRITING: {why} (routing goes on)");
            }
        }
        None => text.push_str("not logging\n"),
    }
    for s in &snap.serving {
        let _ = writeln!(text, "serving {s}");
    }
    let _ = write!(
        text,
        "link lost after {} s of silence",
        LINK_TIMEOUT.as_secs()
    );
    f.render_widget(
        Paragraph::new(text)
            .wrap(Wrap { trim: false })
            .block(Block::bordered().title(" Log and endpoints ")),
        tlog,
    );
}

fn draw_messages(
    f: &mut Frame<'_>,
    app: &mut App,
    snap: &Snapshot<'_>,
    cache: &mut SeriesCache,
    area: Rect,
) {
    let now = snap.now;
    let m = &mut app.messages;
    let filter = m.filter.to_ascii_uppercase();
    let listed: Vec<(SystemId, ComponentId, u32)> = snap
        .state
        .messages
        .iter()
        .filter(|(_, s)| filter.is_empty() || s.last.message_name().unwrap_or("").contains(&filter))
        .map(|(k, _)| *k)
        .collect();
    m.selected = m.selected.min(listed.len().saturating_sub(1));
    let [top, charts_area] = if m.charts.is_empty() {
        [area, Rect::default()]
    } else {
        Layout::vertical([Constraint::Percentage(55), Constraint::Percentage(45)]).areas(area)
    };
    let [list_area, fields_area] =
        Layout::horizontal([Constraint::Length(44), Constraint::Min(20)]).areas(top);
    let visible = list_area.height.saturating_sub(3) as usize;
    let first = m.selected.saturating_sub(visible.saturating_sub(1));
    let rows: Vec<Row> = listed
        .iter()
        .enumerate()
        .skip(first)
        .take(visible)
        .map(|(i, k)| {
            let s = &snap.state.messages[k];
            let name = s.last.message_name().unwrap_or("?");
            let style = if i == m.selected {
                Style::new().add_modifier(Modifier::REVERSED)
            } else {
                Style::new()
            };
            Row::new(vec![
                format!("{}:{}", k.0, k.1),
                name.to_owned(),
                format!("{:.1}", s.window.rate_hz(now)),
            ])
            .style(style)
        })
        .collect();
    let title = if app.typing && app.view == View::Messages {
        format!(" Messages /{}▏ ", m.filter)
    } else if m.filter.is_empty() {
        format!(" Messages ({}) / filter ", listed.len())
    } else {
        format!(" Messages /{} ({}) ", m.filter, listed.len())
    };
    f.render_widget(
        Table::new(
            rows,
            [
                Constraint::Length(7),
                Constraint::Min(20),
                Constraint::Length(7),
            ],
        )
        .header(
            Row::new(["from", "message", "Hz"]).style(Style::new().add_modifier(Modifier::BOLD)),
        )
        .block(Block::bordered().title(title)),
        list_area,
    );
    let mut numeric = Vec::new();
    let mut lines = Vec::new();
    if let Some(k) = listed.get(m.selected) {
        let s = &snap.state.messages[k];
        match s.last.decode() {
            Ok(msg) => {
                let fs = fields::fields(&msg);
                let numeric_fields: Vec<_> = fs.iter().filter(|f| f.value.is_some()).collect();
                m.field = m.field.min(numeric_fields.len().saturating_sub(1));
                let visible = fields_area.height.saturating_sub(2) as usize;
                let selected_path = numeric_fields.get(m.field).map(|f| f.path.clone());
                for f in &fs {
                    let sel = m.in_fields && Some(&f.path) == selected_path.as_ref();
                    let style = if sel {
                        Style::new().add_modifier(Modifier::REVERSED)
                    } else if f.value.is_none() {
                        Style::new().fg(Color::DarkGray)
                    } else {
                        Style::new()
                    };
                    lines.push(Line::styled(format!("{:<24} {}", f.path, f.text), style));
                }
                numeric = numeric_fields.into_iter().map(|f| f.path.clone()).collect();
                // Keep the selected field in view.
                let sel_line = selected_path
                    .and_then(|p| fs.iter().position(|f| f.path == p))
                    .unwrap_or(0);
                let skip = sel_line.saturating_sub(visible.saturating_sub(1));
                lines.drain(..skip.min(lines.len()));
            }
            Err(e) => lines.push(Line::raw(format!("cannot decode: {e}"))),
        }
    }
    m.listed = listed;
    m.listed_fields = numeric;
    let title = if m.in_fields {
        " Fields (Enter: chart it, n: new chart, ← back) "
    } else {
        " Fields (→ to pick one) "
    };
    f.render_widget(
        Paragraph::new(lines).block(Block::bordered().title(title)),
        fields_area,
    );
    if m.charts.is_empty() {
        return;
    }
    let now_t = snap.history.t_s(now);
    let from = now_t - app.window_s;
    let areas = Layout::horizontal(vec![
        Constraint::Ratio(1, m.charts.len() as u32);
        m.charts.len()
    ])
    .split(charts_area);
    for (ci, chart_keys) in m.charts.iter().enumerate() {
        let series: Vec<Series> = chart_keys
            .iter()
            .enumerate()
            .map(|(i, k)| {
                let name = format!(
                    "{}.{}",
                    vtol_link::frame::message_name(k.message).unwrap_or("?"),
                    k.path
                );
                let pts = cache
                    .points(k, snap.history)
                    .iter()
                    .filter(|(t, _)| *t >= from)
                    .map(|(t, v)| (t - now_t, *v))
                    .collect();
                (name, COLOURS[i % COLOURS.len()], pts)
            })
            .collect();
        let title = format!(" Chart {} ({} series) ", ci + 1, series.len());
        f.render_widget(chart(title, &series, app.window_s, ""), areas[ci]);
    }
}

fn draw_params(f: &mut Frame<'_>, app: &App, area: Rect) {
    let p = &app.params;
    let [list_area, side] =
        Layout::horizontal([Constraint::Min(40), Constraint::Length(36)]).areas(area);
    let rows_data = p.filtered();
    let visible = list_area.height.saturating_sub(3) as usize;
    let first = p.selected.saturating_sub(visible.saturating_sub(1));
    let rows: Vec<Row> = rows_data
        .iter()
        .enumerate()
        .skip(first)
        .take(visible)
        .map(|(i, (_, (name, value)))| {
            let (status, style) = match p.status.get(name) {
                Some(ParamStatus::Pending(v)) => {
                    (format!("sent {v}…"), Style::new().fg(Color::Yellow))
                }
                Some(ParamStatus::Confirmed) => {
                    ("confirmed".to_owned(), Style::new().fg(Color::Green))
                }
                Some(ParamStatus::Refused(r)) => {
                    (format!("REFUSED: {r}"), Style::new().fg(Color::Red))
                }
                None => (String::new(), Style::new()),
            };
            let value = if i == p.selected
                && let Some(e) = &p.edit
            {
                format!("{e}▏")
            } else {
                value.to_string()
            };
            let row_style = if i == p.selected {
                Style::new().add_modifier(Modifier::REVERSED)
            } else {
                Style::new()
            };
            Row::new(vec![
                Cell::from(name.clone()),
                Cell::from(value),
                Cell::from(status).style(style),
            ])
            .style(row_style)
        })
        .collect();
    let title = if app.typing && p.edit.is_none() && p.file_prompt.is_none() {
        format!(" Parameters /{}▏ ", p.filter)
    } else if p.table.is_empty() {
        " Parameters (r: download) ".to_owned()
    } else {
        format!(" Parameters ({} of {}) ", rows_data.len(), p.table.len())
    };
    f.render_widget(
        Table::new(
            rows,
            [
                Constraint::Length(17),
                Constraint::Length(14),
                Constraint::Min(10),
            ],
        )
        .header(
            Row::new(["name", "value", "status"]).style(Style::new().add_modifier(Modifier::BOLD)),
        )
        .block(Block::bordered().title(title)),
        list_area,
    );
    let [prog, info] = Layout::vertical([Constraint::Length(3), Constraint::Min(3)]).areas(side);
    match &p.progress {
        Some((what, done, total)) => {
            let ratio = if *total == 0 {
                0.0
            } else {
                *done as f64 / *total as f64
            };
            f.render_widget(
                Gauge::default()
                    .block(Block::bordered().title(format!(" {what} ")))
                    .gauge_style(Style::new().fg(Color::Cyan))
                    .label(format!("{done}/{total}"))
                    .ratio(ratio.clamp(0.0, 1.0)),
                prog,
            );
        }
        None => f.render_widget(Block::bordered().title(" idle "), prog),
    }
    let mut lines = Vec::new();
    if let Some(path) = &p.file_prompt {
        lines.push(Line::raw("Gains file (Enter reads it):"));
        lines.push(Line::raw(format!("{path}▏")));
    } else if let Some(diff) = &p.diff {
        lines.push(Line::raw(format!("{} change(s):", diff.len())));
        for (n, now, want) in diff {
            let now = now.map_or_else(|| "-".to_owned(), |v| v.to_string());
            lines.push(Line::raw(format!("{n} {now} → {want}")));
        }
    } else if p.edit.is_some() {
        lines.push(Line::raw("Type the value, Enter sends it,"));
        lines.push(Line::raw("Esc cancels. Shown confirmed only"));
        lines.push(Line::raw("when the vehicle echoes it."));
    } else {
        lines.push(Line::raw("Enter: edit   /: filter"));
        lines.push(Line::raw("f: gains file   r: download"));
    }
    f.render_widget(
        Paragraph::new(lines)
            .alignment(Alignment::Left)
            .wrap(Wrap { trim: false })
            .block(Block::bordered().title(" Edit ").borders(Borders::ALL)),
        info,
    );
}
