//! Drawing: one function per view over a [`Snapshot`] of everything shown and the [`App`] as
//! the event loop left it. Pure apart from the [`RenderState`] (chart series, the map's track,
//! the fleet table's scroll), so whole frames render into ratatui's `TestBackend` for snapshot
//! tests.

use std::collections::BTreeMap;
use std::time::Instant;

use ratatui::Frame;
use ratatui::layout::{Constraint, Layout, Rect};
use ratatui::style::{Color, Modifier, Style};
use ratatui::widgets::{Paragraph, Wrap};

use super::app::{App, Level, SeriesKey, View};
use crate::fields;
use crate::links::Side;
use crate::tracker::history::{History, TimedFrame};
use crate::tracker::state::{VehicleState, VehicleView};

mod charts;
mod fleet;
mod flight;
mod header;
mod links;
pub mod map;
mod messages;
mod overlay;
mod params;
mod setpoint;

use charts::draw_charts;
use fleet::draw_fleet;
use flight::draw_flight;
pub use flight::heading_tape;
use header::{draw_footer, draw_header, footer_lines, vehicle_list_lines, vitals_lines};
use links::draw_links;
use messages::draw_messages;
use overlay::{draw_confirm, draw_help, draw_picker};
use params::draw_params;

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
    pub conflict: Option<crate::links::SysidConflict>,
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

/// What drawing keeps from one frame to the next and nothing else reads: field series read
/// incrementally from the history's raw frames (each frame decoded once), the shown vehicle's
/// track for the Map view, and how far the Fleet view's table is scrolled.
#[derive(Debug, Default)]
pub struct RenderState {
    series: BTreeMap<SeriesKey, (u64, Vec<(f64, f64)>)>,
    /// The shown vehicle's track for the Map view.
    track: map::TrackCache,
    /// The Fleet view's first row on screen.
    fleet_first: usize,
}

impl RenderState {
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

/// The shown vehicle's outputs 1–8 labelled by their `SERVOn_FUNCTION` ([`crate::outputs`]).
fn servo_outputs(app: &App) -> Vec<crate::outputs::Output> {
    let f: Vec<Option<f32>> = (1..=8)
        .map(|i| app.params.value(&format!("SERVO{i}_FUNCTION")))
        .collect();
    crate::outputs::outputs(&f)
}

/// Whether the shown vehicle is a tailsitter (its parameters or its MAV_TYPE).
fn tailsitter(app: &App, v: &VehicleView) -> bool {
    crate::tui::attitude::is_tailsitter(v, q_tailsit_enable(app))
}

/// `Q_TAILSIT_ENABLE` as the vehicle's table says it: its value, else 1 when the table has
/// other `Q_TAILSIT_*` parameters (ArduPilot shows them only while it is enabled; the twin
/// publishes them without the switch).
pub(super) fn q_tailsit_enable(app: &App) -> Option<f32> {
    app.params.value("Q_TAILSIT_ENABLE").or_else(|| {
        app.params
            .table
            .iter()
            .any(|(n, _)| n.starts_with("Q_TAILSIT_"))
            .then_some(1.0)
    })
}

fn servo_names(app: &App) -> Vec<String> {
    servo_outputs(app).into_iter().map(|o| o.name).collect()
}

/// Draws the whole screen of `snap` as `app` shows it. Reads the app (the event loop brought it
/// up to date with [`crate::tui::observe`]); writes only `render`.
pub fn draw(f: &mut Frame<'_>, app: &App, render: &mut RenderState, snap: &Snapshot<'_>) {
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
    map::keep_track(app, snap, &mut render.track);
    // The Fleet view is the list: the header does not repeat it there.
    let fleet = if snap.state.vehicles.len() > 1 && app.view != View::Fleet {
        vehicle_list_lines(app, snap, area.width)
    } else {
        Vec::new()
    };
    let list_rows = u16::try_from(fleet.len()).unwrap_or(u16::MAX);
    let vitals_rows = u16::try_from(vitals_lines(app, snap, area.width).len()).unwrap_or(1);
    let footer_rows = u16::try_from(footer_lines(app, area.width).len()).unwrap_or(1);
    let [header, body, footer] = Layout::vertical([
        Constraint::Length(2 + vitals_rows + list_rows),
        Constraint::Min(10),
        Constraint::Length(footer_rows),
    ])
    .areas(area);
    draw_header(f, app, snap, header);
    if !fleet.is_empty() {
        f.render_widget(
            Paragraph::new(fleet),
            Rect {
                y: header.y + 2 + vitals_rows,
                height: list_rows,
                ..header
            },
        );
    }
    match app.view {
        View::Flight => draw_flight(f, app, snap, body),
        View::Charts => draw_charts(f, app, snap, body),
        View::Links => draw_links(f, snap, body),
        View::Messages => draw_messages(f, app, snap, render, body),
        View::Params => draw_params(f, app, body),
        View::Fleet => draw_fleet(f, app, snap, &mut render.fleet_first, body),
        View::Map => map::draw_map_view(f, app, snap, &render.track, body),
    }
    if let Some(p) = &app.mission_prompt {
        overlay::draw_mission_prompt(f, p, body);
    }
    draw_footer(f, app, footer);
    if let Some(p) = &app.picker {
        draw_picker(f, app, p, snap.state, area);
    }
    if let Some(c) = &app.confirm {
        draw_confirm(f, app, c, area);
    }
    if app.help {
        draw_help(f, area);
    }
}

/// Words of `text` in lines of at most `width` characters (a longer word is cut into pieces).
pub(super) fn wrap(text: &str, width: usize) -> Vec<String> {
    let width = width.max(1);
    let mut lines = Vec::new();
    let mut line = String::new();
    for word in text.split_whitespace() {
        let mut word: Vec<char> = word.chars().collect();
        while word.len() > width {
            if !line.is_empty() {
                lines.push(std::mem::take(&mut line));
            }
            lines.push(word.drain(..width).collect());
        }
        let word: String = word.into_iter().collect();
        let n = line.chars().count();
        if n > 0 && n + 1 + word.chars().count() > width {
            lines.push(std::mem::take(&mut line));
        }
        if !line.is_empty() {
            line.push(' ');
        }
        line.push_str(&word);
    }
    if !line.is_empty() || lines.is_empty() {
        lines.push(line);
    }
    lines
}

fn age_s(snap: &Snapshot<'_>, v: &VehicleView, msg: u32) -> Option<f64> {
    snap.state
        .messages
        .get(&(v.system_id, v.component_id, msg))
        .map(|m| snap.now.saturating_duration_since(m.last_at).as_secs_f64())
}

#[cfg(test)]
mod tests {
    use super::wrap;

    #[test]
    fn wrap_keeps_every_word_within_the_width() {
        let lines = wrap(
            "REFUSED: LAT_SAT_B: saturation levels need a > b + c + d",
            20,
        );
        assert!(lines.iter().all(|l| l.chars().count() <= 20), "{lines:?}");
        assert_eq!(
            lines.join(" "),
            "REFUSED: LAT_SAT_B: saturation levels need a > b + c + d"
        );
        assert_eq!(wrap("abcdefgh", 3), ["abc", "def", "gh"]);
        assert_eq!(wrap("", 5), [""]);
    }
}
