//! The Params view: the parameter table and its editor.

use ratatui::Frame;
use ratatui::layout::{Alignment, Constraint, Layout, Rect};
use ratatui::style::{Color, Modifier, Style};
use ratatui::text::Line;
use ratatui::widgets::{Block, Borders, Cell, Gauge, Paragraph, Row, Table, Wrap};

use crate::tui::app::{App, ParamStatus};

pub(super) fn draw_params(f: &mut Frame<'_>, app: &App, area: Rect) {
    let p = &app.params;
    let [list_area, side] = Layout::horizontal([
        Constraint::Min(40),
        Constraint::Length(side_width(area.width)),
    ])
    .areas(area);
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
                Some(ParamStatus::NotSent(r)) => {
                    (format!("not sent: {r}"), Style::new().fg(Color::Magenta))
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
        // The selected row's whole status: the table's column may cut a refusal's reason.
        if let Some((_, (name, _))) = rows_data.get(p.selected)
            && let Some(s) = p.status.get(name)
        {
            lines.push(Line::raw(""));
            lines.push(Line::raw(format!("{name}:")));
            lines.push(Line::raw(match s {
                ParamStatus::Pending(v) => format!("sent {v}, no echo yet"),
                ParamStatus::Confirmed => "confirmed by the vehicle".to_owned(),
                ParamStatus::Refused(r) => format!("refused: {r}"),
                ParamStatus::NotSent(r) => format!("not sent: {r}"),
            }));
        }
    }
    f.render_widget(
        Paragraph::new(lines)
            .alignment(Alignment::Left)
            .wrap(Wrap { trim: false })
            .block(Block::bordered().title(" Edit ").borders(Borders::ALL)),
        info,
    );
}

/// The side panel's width: narrow on a small terminal so the table keeps its status column.
fn side_width(width: u16) -> u16 {
    if width >= 120 { 36 } else { 26 }
}
