//! The Fleet view: every vehicle in one table, the lost ones first, then those in trouble, the
//! armed ones and the rest; `/` searches, the arrows and PgUp/PgDn scroll, Enter shows and
//! commands the vehicle under the cursor. Only the rows on screen decode anything.

use ratatui::Frame;
use ratatui::layout::{Constraint, Rect};
use ratatui::style::{Color, Modifier, Style};
use ratatui::widgets::{Block, Cell, Row, Table};
use vtol_link::dialect::MavMessage;
use vtol_link::protocol::id::SYS_STATUS;

use super::Snapshot;
use crate::tracker::VehicleView;
use crate::tui::app::fleet::state_word;
use crate::tui::app::{App, View};

fn battery(snap: &Snapshot<'_>, v: &VehicleView) -> String {
    let Some(MavMessage::SYS_STATUS(s)) = snap
        .state
        .messages
        .get(&(v.system_id, v.component_id, SYS_STATUS))
        .and_then(|m| m.last.decode_lenient().ok().map(|l| l.msg))
    else {
        return "-".to_owned();
    };
    if s.voltage_battery == u16::MAX {
        return "-".to_owned();
    }
    let mut t = format!("{:.1}V", f32::from(s.voltage_battery) / 1000.0);
    if s.battery_remaining >= 0 {
        t.push_str(&format!(" {}%", s.battery_remaining));
    }
    t
}

/// One vehicle's row: a lost one in red with no live figure, `▶` on the one shown.
fn fleet_row(snap: &Snapshot<'_>, v: &VehicleView, shown: bool) -> Row<'static> {
    let now = snap.now;
    let grey = Style::new().fg(Color::DarkGray);
    let is_lost = v.is_lost(now);
    let mark = if shown { "▶" } else { " " };
    let (state_style, live) = if is_lost {
        (
            Style::new().fg(Color::Red).add_modifier(Modifier::BOLD),
            grey,
        )
    } else if v.armed {
        (Style::new().fg(Color::Yellow), Style::new())
    } else {
        (Style::new().fg(Color::Green), Style::new())
    };
    let heard = now
        .saturating_duration_since(v.last_heartbeat)
        .as_secs_f64();
    let (rate, loss, bat) = if is_lost {
        ("-".to_owned(), "-".to_owned(), "-".to_owned())
    } else {
        (
            format!("{:.0}", v.window.rate_hz(now)),
            format!("{:.1}", v.window.loss_pct(now)),
            battery(snap, v),
        )
    };
    Row::new(vec![
        Cell::from(format!("{mark}{}", v.system_id.0)),
        Cell::from(state_word(v, now)).style(state_style),
        Cell::from(v.mode_name()).style(live),
        Cell::from(crate::words::mav_state(v.system_status)).style(live),
        Cell::from(rate),
        Cell::from(loss),
        Cell::from(format!("{heard:.0} s")).style(if is_lost { state_style } else { Style::new() }),
        Cell::from(bat),
    ])
}

/// Draws the vehicles as the app last listed them, the cursor's row kept on screen by
/// scrolling `first` (the first row shown) only as far as it needs.
pub(super) fn draw_fleet(
    f: &mut Frame<'_>,
    app: &App,
    snap: &Snapshot<'_>,
    first: &mut usize,
    area: Rect,
) {
    let now = snap.now;
    let listed = &app.fleet.listed;
    let total = snap.state.vehicles.len();
    let lost = snap
        .state
        .vehicles
        .values()
        .filter(|v| v.is_lost(now))
        .count();
    let armed = snap
        .state
        .vehicles
        .values()
        .filter(|v| v.armed && !v.is_lost(now))
        .count();
    let shown = app
        .vehicle(snap.state)
        .map(|v| (v.system_id, v.component_id));
    let at = app
        .fleet
        .cursor
        .and_then(|c| listed.iter().position(|k| *k == c))
        .unwrap_or(0);
    let visible = usize::from(area.height.saturating_sub(3)).max(1);
    // Scroll only as far as the cursor needs.
    if at < *first {
        *first = at;
    } else if at >= *first + visible {
        *first = at + 1 - visible;
    }
    *first = (*first).min(listed.len().saturating_sub(visible));
    let first = *first;
    let rows: Vec<Row> = listed
        .iter()
        .enumerate()
        .skip(first)
        .take(visible)
        .filter_map(|(i, k)| {
            let v = snap.state.vehicles.get(k)?;
            let row = fleet_row(snap, v, Some(*k) == shown);
            Some(if i == at {
                row.style(Style::new().add_modifier(Modifier::REVERSED))
            } else {
                row
            })
        })
        .collect();
    let title = if app.typing && app.view == View::Fleet {
        format!(
            " Fleet /{}▏ ({} of {total}) ",
            app.fleet.filter,
            listed.len()
        )
    } else if app.fleet.filter.is_empty() {
        format!(
            " Fleet: {total} vehicle{}, {lost} lost, {armed} armed   /: search  Enter: show ",
            if total == 1 { "" } else { "s" }
        )
    } else {
        format!(
            " Fleet /{} ({} of {total}, {lost} lost)   Esc: all ",
            app.fleet.filter,
            listed.len()
        )
    };
    let below = listed.len().saturating_sub(first + visible);
    let block = Block::bordered().title(title);
    let block = if first > 0 || below > 0 {
        block.title_bottom(format!(
            " rows {}–{} of {} ",
            first + 1,
            (first + visible).min(listed.len()),
            listed.len()
        ))
    } else {
        block
    };
    f.render_widget(
        Table::new(
            rows,
            [
                Constraint::Length(5),
                Constraint::Length(8),
                Constraint::Length(10),
                Constraint::Length(11),
                Constraint::Length(5),
                Constraint::Length(6),
                Constraint::Length(7),
                Constraint::Min(10),
            ],
        )
        .header(
            Row::new([
                "sys", "state", "mode", "status", "Hz", "loss%", "heard", "battery",
            ])
            .style(Style::new().add_modifier(Modifier::BOLD)),
        )
        .block(block),
        area,
    );
}
