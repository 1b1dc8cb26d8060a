//! The Params view: the parameter table and its editor.

use ratatui::Frame;
use ratatui::layout::{Alignment, Constraint, Layout, Rect};
use ratatui::style::{Color, Modifier, Style};
use ratatui::text::{Line, Text};
use ratatui::widgets::{Block, Borders, Cell, Gauge, Paragraph, Row, Table, Wrap};

use super::wrap;
use crate::tui::app::{App, ParamStatus};

/// Width from which the editor is a side panel; below it, a strip under the table so the
/// table keeps every column whole.
const SIDE_PANEL_FROM: u16 = 120;
/// Columns of the name and value.
const NAME_W: u16 = 17;
const VALUE_W: u16 = 14;

fn status_text(s: &ParamStatus) -> (String, Style) {
    match s {
        ParamStatus::Pending(v) => (format!("sent {v}…"), Style::new().fg(Color::Yellow)),
        ParamStatus::Confirmed => ("confirmed".to_owned(), Style::new().fg(Color::Green)),
        ParamStatus::Refused(r) => (format!("REFUSED: {r}"), Style::new().fg(Color::Red)),
        ParamStatus::NotSent(r) => (format!("not sent: {r}"), Style::new().fg(Color::Magenta)),
    }
}

pub(super) fn draw_params(f: &mut Frame<'_>, app: &App, area: Rect) {
    let p = &app.params;
    let (list_area, side, strip) = if area.width >= SIDE_PANEL_FROM {
        let [l, s] = Layout::horizontal([Constraint::Min(40), Constraint::Length(36)]).areas(area);
        (l, Some(s), None)
    } else {
        let [l, s] = Layout::vertical([Constraint::Min(6), Constraint::Length(5)]).areas(area);
        (l, None, Some(s))
    };
    let rows_data = p.filtered();
    // The status column takes the rest; a long status (a refusal's reason) wraps in it.
    let status_w = usize::from(list_area.width.saturating_sub(2 + NAME_W + VALUE_W + 2));
    let heights: Vec<usize> = rows_data
        .iter()
        .map(|(_, (name, _))| {
            p.status
                .get(name)
                .map_or(1, |s| wrap(&status_text(s).0, status_w).len())
        })
        .collect();
    let visible = list_area.height.saturating_sub(3) as usize;
    // The first row such that the selected one fits whole below it.
    let mut first = p.selected.min(rows_data.len().saturating_sub(1));
    let mut used = heights.get(first).copied().unwrap_or(1);
    while first > 0 && used + heights[first - 1] <= visible {
        first -= 1;
        used += heights[first];
    }
    let rows = table_rows(app, &rows_data, first, status_w);
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
                Constraint::Length(NAME_W),
                Constraint::Length(VALUE_W),
                Constraint::Min(10),
            ],
        )
        .header(
            Row::new(["name", "value", "status"]).style(Style::new().add_modifier(Modifier::BOLD)),
        )
        .block(Block::bordered().title(title)),
        list_area,
    );
    if let Some(side) = side {
        let [prog, info] =
            Layout::vertical([Constraint::Length(3), Constraint::Min(3)]).areas(side);
        draw_progress(f, app, prog);
        f.render_widget(
            Paragraph::new(editor_lines(app, &rows_data, true))
                .alignment(Alignment::Left)
                .wrap(Wrap { trim: false })
                .block(Block::bordered().title(" Edit ").borders(Borders::ALL)),
            info,
        );
    }
    if let Some(strip) = strip {
        // The progress as the strip's title; the keys or the editor's prompt inside.
        let title = match &p.progress {
            Some((what, done, total)) => format!(" {what} {done}/{total} "),
            None => " Edit ".to_owned(),
        };
        f.render_widget(
            Paragraph::new(editor_lines(app, &rows_data, false))
                .wrap(Wrap { trim: false })
                .block(Block::bordered().title(title)),
            strip,
        );
    }
}

/// The table's rows from `first` on, each as tall as its wrapped status.
fn table_rows(
    app: &App,
    rows_data: &[(usize, &(String, f32))],
    first: usize,
    status_w: usize,
) -> Vec<Row<'static>> {
    let p = &app.params;
    rows_data
        .iter()
        .enumerate()
        .skip(first)
        .map(|(i, (_, (name, value)))| {
            let (status, style) = p
                .status
                .get(name)
                .map_or((String::new(), Style::new()), status_text);
            let status = wrap(&status, status_w);
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
            let h = u16::try_from(status.len()).unwrap_or(1);
            Row::new(vec![
                Cell::from(name.clone()),
                Cell::from(value),
                Cell::from(Text::from(
                    status.into_iter().map(Line::raw).collect::<Vec<_>>(),
                ))
                .style(style),
            ])
            .height(h)
            .style(row_style)
        })
        .collect()
}

fn draw_progress(f: &mut Frame<'_>, app: &App, area: Rect) {
    match &app.params.progress {
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
                area,
            );
        }
        None => f.render_widget(Block::bordered().title(" idle "), area),
    }
}

/// What the editor says: the prompt being typed, the loaded file's changes, or the keys and
/// (in the side panel, where the table may be narrow) the selected row's whole status.
fn editor_lines(
    app: &App,
    rows_data: &[(usize, &(String, f32))],
    side: bool,
) -> Vec<Line<'static>> {
    let p = &app.params;
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
        lines.push(Line::raw(
            "Type the value, Enter sends it, Esc cancels. Shown confirmed only when the vehicle \
             echoes it.",
        ));
    } else {
        lines.push(Line::raw(
            "Enter: edit   /: filter   f: gains file   r: download",
        ));
        if side
            && let Some((_, (name, _))) = rows_data.get(p.selected)
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
    lines
}
