//! The Messages view: the message inspector and its per-field charts.

use ratatui::Frame;
use ratatui::layout::{Constraint, Layout, Rect};
use ratatui::style::{Color, Modifier, Style};
use ratatui::text::Line;
use ratatui::widgets::{Block, Paragraph, Row, Table};

use super::charts::{COLOURS, Series, chart};
use super::{RenderState, Snapshot};
use crate::fields;
use crate::tui::app::{App, View};

/// Draws the messages as the app last listed them, the selected one's fields and the charts.
pub(super) fn draw_messages(
    f: &mut Frame<'_>,
    app: &App,
    snap: &Snapshot<'_>,
    render: &mut RenderState,
    area: Rect,
) {
    let now = snap.now;
    let m = &app.messages;
    // The rows still in the tracker's state (all of them, when the app listed this state).
    let listed: Vec<_> = m
        .listed
        .iter()
        .filter_map(|k| Some((*k, snap.state.messages.get(k)?)))
        .collect();
    let [top, charts_area] = if m.charts.is_empty() {
        [area, Rect::default()]
    } else {
        Layout::vertical([Constraint::Percentage(55), Constraint::Percentage(45)]).areas(area)
    };
    // The list as wide as its longest name needs, the fields the rest.
    let name_w = listed
        .iter()
        .filter_map(|(_, s)| s.last.message_name())
        .map(str::len)
        .max()
        .unwrap_or(7)
        .max(7);
    let list_w = u16::try_from(2 + 7 + 1 + name_w + 1 + 5).unwrap_or(44);
    let [list_area, fields_area] =
        Layout::horizontal([Constraint::Length(list_w), Constraint::Min(20)]).areas(top);
    let visible = list_area.height.saturating_sub(3) as usize;
    let first = m.selected.saturating_sub(visible.saturating_sub(1));
    let rows: Vec<Row> = listed
        .iter()
        .enumerate()
        .skip(first)
        .take(visible)
        .map(|(i, (k, s))| {
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
                Constraint::Min(7),
                Constraint::Length(5),
            ],
        )
        .header(
            Row::new(["from", "message", "Hz"]).style(Style::new().add_modifier(Modifier::BOLD)),
        )
        .block(Block::bordered().title(title)),
        list_area,
    );
    let mut lines = Vec::new();
    if let Some((_, s)) = listed.get(m.selected) {
        // Decoded as pymavlink does: a value the dialect does not define still shows the
        // message, with that field's wire number said below it.
        match s.last.decode_lenient() {
            Ok(vtol_link::frame::Lenient { msg, replaced }) => {
                let fs = fields::fields(&msg);
                let numeric_fields: Vec<_> = fs.iter().filter(|f| f.value.is_some()).collect();
                let visible = fields_area.height.saturating_sub(2) as usize;
                let selected_path = numeric_fields.get(m.field).map(|f| f.path.clone());
                // Paths in a column as wide as the longest; a value that does not fit beside
                // its path goes whole on the next line.
                let inner_w = usize::from(fields_area.width.saturating_sub(2));
                let path_w = fs.iter().map(|f| f.path.len()).max().unwrap_or(0).min(24);
                let mut sel_line = 0;
                for f in &fs {
                    let sel = m.in_fields && Some(&f.path) == selected_path.as_ref();
                    let style = if sel {
                        Style::new().add_modifier(Modifier::REVERSED)
                    } else if f.value.is_none() {
                        Style::new().fg(Color::DarkGray)
                    } else {
                        Style::new()
                    };
                    if Some(&f.path) == selected_path.as_ref() {
                        sel_line = lines.len();
                    }
                    let one = format!("{:<path_w$} {}", f.path, f.text);
                    if one.chars().count() <= inner_w {
                        lines.push(Line::styled(one, style));
                    } else {
                        lines.push(Line::styled(f.path.clone(), style));
                        lines.push(Line::styled(format!("  {}", f.text), style));
                    }
                }
                for r in &replaced {
                    let name = fields::field_key(s.last.message_id(), r.field)
                        .unwrap_or_else(|| format!("byte {}", r.field.offset));
                    lines.push(Line::styled(
                        format!(
                            "{name} = {} (not in the dialect's {})",
                            r.value, r.field.enum_type
                        ),
                        Style::new().fg(Color::Yellow),
                    ));
                }
                let skip = sel_line.saturating_sub(visible.saturating_sub(1));
                lines.drain(..skip.min(lines.len()));
            }
            Err(e) => lines.push(Line::raw(format!("cannot decode: {e}"))),
        }
    }
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
                let pts = render
                    .points(k, snap.history)
                    .iter()
                    .filter(|(t, _)| *t >= from)
                    .map(|(t, v)| (t - now_t, *v))
                    .collect();
                (name, COLOURS[i % COLOURS.len()], pts)
            })
            .collect();
        let title = format!(" Chart {} ({} series) ", ci + 1, series.len());
        f.render_widget(
            chart(title, &series, app.window_s, "", areas[ci].width),
            areas[ci],
        );
    }
}
