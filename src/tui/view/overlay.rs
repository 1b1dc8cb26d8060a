//! Overlays: the confirmation prompt and the help screen.

use ratatui::Frame;
use ratatui::layout::{Constraint, Rect};
use ratatui::style::{Color, Modifier, Style};
use ratatui::text::{Line, Span};
use ratatui::widgets::{Block, Cell, Clear, Paragraph, Row, Table, Wrap};

use crate::tracker::state::VehicleState;
use crate::tui::app::mission_keys::MissionPrompt;
use crate::tui::app::picker::Picker;
use crate::tui::app::{App, Confirm};

pub(super) fn centered(area: Rect, w: u16, h: u16) -> Rect {
    let w = w.min(area.width);
    let h = h.min(area.height);
    Rect {
        x: area.x + (area.width - w) / 2,
        y: area.y + (area.height - h) / 2,
        width: w,
        height: h,
    }
}

pub(super) fn draw_confirm(f: &mut Frame<'_>, app: &App, c: &Confirm, area: Rect) {
    let mut lines = Vec::new();
    let (title, consequence) = c.text();
    lines.push(Line::from(Span::styled(
        title,
        Style::new().add_modifier(Modifier::BOLD),
    )));
    if let Some(text) = consequence {
        lines.push(Line::from(Span::styled(
            text,
            Style::new().fg(Color::Red).add_modifier(Modifier::BOLD),
        )));
    }
    if let (Confirm::Upload, Some(diff)) = (c, &app.params.diff) {
        for (name, now, wanted) in diff {
            let now = now.map_or_else(|| "(missing)".to_owned(), |v| v.to_string());
            lines.push(Line::raw(format!("  {name:<16} {now:>10} → {wanted}")));
        }
    }
    lines.push(Line::raw(""));
    lines.push(Line::raw("y: yes    any other key: cancel"));
    // The consequence wraps inside the 60-column box: count its rows.
    let rows: u16 = lines
        .iter()
        .map(|l| (l.width() as u16).div_ceil(58).max(1))
        .sum();
    let h = (rows + 2).min(area.height);
    let r = centered(area, 60, h);
    f.render_widget(Clear, r);
    f.render_widget(
        Paragraph::new(lines).wrap(Wrap { trim: false }).block(
            Block::bordered()
                .title(" Confirm ")
                .border_style(Style::new().fg(Color::Yellow)),
        ),
        r,
    );
}

pub(super) const HELP: &[(&str, &str)] = &[
    ("Tab / Shift-Tab", "next / previous view"),
    ("v / V", "next / previous vehicle (when several)"),
    ("?", "this help (any key closes it)"),
    ("q, Ctrl-C", "quit"),
    ("a / A", "arm / force arm (then y to confirm)"),
    ("d / D", "disarm / FORCE disarm (y confirms, n cancels)"),
    ("R", "reboot the autopilot (disarmed; clears a crash)"),
    ("t", "take off: QHOVER (climbs to HOVER_ALT when armed)"),
    ("l", "land: QLAND"),
    ("p / s", "QLOITER / QSTABILIZE (asks first in the air)"),
    ("m", "mode picker: the vehicle's modes (↑↓ or type, Enter)"),
    (
        "arrows",
        "QLOITER: target 0.5 m N/S/E/W; Map: pan (f: follow)",
    ),
    ("PgUp / PgDn", "QLOITER: target 0.5 m up / down"),
    (
        "x X / c C / z Z",
        "push roll / pitch / yaw, + and - (SIM_PUSH_*)",
    ),
    ("+ / -", "chart window (5..120 s); Map: zoom in / out"),
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
    (
        "Map: u w g n r",
        "mission: upload / write a file / start / item / reload",
    ),
    (
        "Fleet: / ↑↓ Enter",
        "search; scroll (PgUp/PgDn); show and command it",
    ),
    ("/ … Enter, Esc", "type a filter; Esc clears it"),
];

/// The Map view's mission prompt: a box over the bottom of `area` with what is typed.
pub(super) fn draw_mission_prompt(f: &mut Frame<'_>, p: &MissionPrompt, area: Rect) {
    let h = 3.min(area.height);
    let r = Rect {
        y: area.y + area.height - h,
        height: h,
        ..area
    };
    f.render_widget(Clear, r);
    f.render_widget(
        Paragraph::new(format!("{}▏", p.text())).block(
            Block::bordered()
                .title(p.title())
                .border_style(Style::new().fg(Color::Yellow)),
        ),
        r,
    );
}

pub(super) fn draw_help(f: &mut Frame<'_>, area: Rect) {
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

/// The mode picker: the vehicle's modes with their numbers, the current one marked, the
/// selected one highlighted; a fixed-wing mode picked in hover is named as the forward
/// transition it starts, a Q mode in forward flight as the back transition.
pub(super) fn draw_picker(
    f: &mut Frame<'_>,
    app: &App,
    p: &Picker,
    state: &VehicleState,
    area: Rect,
) {
    let v = app.vehicle(state);
    let listed = p.listed(v);
    let current = v.map(|v| v.custom_mode);
    let hover = v.is_some_and(|v| crate::tui::attitude::in_hover(state, v));
    let h = area.height.saturating_sub(2).clamp(6, 26);
    let rows = usize::from(h.saturating_sub(4));
    // Scroll so that the selected row shows.
    let first = p.selected.saturating_sub(rows.saturating_sub(1));
    let mut lines = Vec::new();
    lines.push(Line::from(vec![
        Span::styled("filter: ", Style::new().fg(Color::DarkGray)),
        Span::raw(if p.filter.is_empty() {
            "(type to filter)".to_owned()
        } else {
            p.filter.clone()
        }),
    ]));
    if listed.is_empty() {
        lines.push(Line::styled(
            "no mode matches",
            Style::new().fg(Color::Yellow),
        ));
    }
    for (i, (name, number)) in listed.iter().enumerate().skip(first).take(rows) {
        let q = name.starts_with('Q');
        // What picking it does, on the selected row only (the list stays readable).
        let note = match (
            Some(*number) == current,
            i == p.selected && v.is_some(),
            q,
            hover,
        ) {
            (true, _, _, _) => "current",
            (false, true, false, true) => "forward transition",
            (false, true, true, false) => "back transition",
            _ => "",
        };
        let text = format!(" {name:<11} {number:>3}  {note}");
        let style = if i == p.selected {
            Style::new().add_modifier(Modifier::REVERSED | Modifier::BOLD)
        } else if Some(*number) == current {
            Style::new().fg(Color::Green)
        } else {
            Style::new()
        };
        lines.push(Line::styled(text, style));
    }
    lines.push(Line::styled(
        "Enter: switch  Esc: close",
        Style::new().fg(Color::DarkGray),
    ));
    let r = centered(area, 40, (lines.len() as u16 + 2).min(h + 2));
    f.render_widget(Clear, r);
    f.render_widget(
        Paragraph::new(lines).block(
            Block::bordered()
                .title(" Mode ")
                .border_style(Style::new().fg(Color::Cyan)),
        ),
        r,
    );
}
