//! The Map view: the mission's items and legs, home, the track flown, the vehicle with its
//! heading and its live target, on the flat-earth projection of [`crate::tui::map`].
//!
//! [`draw_map`] is a pure function of a [`MapScene`] and a [`MapCamera`];
//! [`crate::tui::map::scene_parts`] and [`TrackCache`] build the scene from the tracker's state
//! and history.

use ratatui::Frame;
use ratatui::layout::{Constraint, Layout, Rect};
use ratatui::style::{Color, Modifier, Style};
use ratatui::symbols::Marker;
use ratatui::text::{Line as TextLine, Span};
use ratatui::widgets::canvas::{Canvas, Circle, Context, Line};
use ratatui::widgets::{Block, Paragraph};
use vtol_link::dialect::MavMessage;
use vtol_link::protocol::id::GLOBAL_POSITION_INT;
use vtol_link::{ComponentId, SystemId};

use crate::tracker::history::History;
use crate::tui::map::{ItemKind, LatLon, MapCamera, MapScene, east_north_m, scene_parts};

/// Most points the track keeps: past it, every other point goes.
pub const MAX_TRACK: usize = 3000;
/// Closest two successive track points are kept, 1e-7 degree (about 0.3 m).
const TRACK_STEP_E7: i32 = 30;

/// A round length (1, 2 or 5 × 10ⁿ m) no longer than `max_m`.
#[must_use]
pub fn scale_length_m(max_m: f64) -> f64 {
    let mut best = 0.5;
    let mut decade = 1.0;
    while decade <= max_m {
        for f in [1.0, 2.0, 5.0] {
            if f * decade <= max_m {
                best = f * decade;
            }
        }
        decade *= 10.0;
    }
    best
}

fn metres_text(m: f64) -> String {
    if m >= 1000.0 {
        format!("{} km", m / 1000.0)
    } else {
        format!("{m} m")
    }
}

/// The arrow for a heading, degrees clockwise from north.
#[must_use]
pub fn heading_arrow(deg: f32) -> &'static str {
    const ARROWS: [&str; 8] = ["↑", "↗", "→", "↘", "↓", "↙", "←", "↖"];
    let i = ((f64::from(deg).rem_euclid(360.0) + 22.5) / 45.0) as usize % 8;
    ARROWS[i]
}

fn is_leg(kind: ItemKind) -> bool {
    !matches!(kind, ItemKind::Other)
}

/// Draws the map of `scene` as `camera` sees it into `area`.
pub fn draw_map(f: &mut Frame<'_>, scene: &MapScene<'_>, camera: &MapCamera, area: Rect) {
    // From 160 columns the mission and the distances sit beside the map.
    let area = if area.width >= 160 {
        let [map, side] =
            Layout::horizontal([Constraint::Min(100), Constraint::Length(40)]).areas(area);
        draw_side(f, scene, side);
        map
    } else {
        area
    };
    let mpc = camera.metres_per_cell();
    let follow = if camera.follow {
        "following"
    } else {
        "f: follow"
    };
    let title = format!(" Map  {mpc} m/cell  {follow} ");
    let mut block = Block::bordered().title(title);
    if area.width >= 120 {
        block = block
            .title_bottom(" H home  ↑ vehicle  ✛ target  · track  ○ loiter  +/- zoom  arrows pan ");
    }
    let inner = block.inner(area);
    let Some(center) = camera.center_for(scene) else {
        f.render_widget(block, area);
        let msg = "no position yet: the map appears with the vehicle's first GLOBAL_POSITION_INT";
        f.buffer_mut()
            .set_stringn(inner.x, inner.y, msg, inner.width as usize, Style::new());
        return;
    };
    let half_w = f64::from(inner.width) * mpc / 2.0;
    let half_h = f64::from(inner.height) * mpc;
    let canvas = Canvas::default()
        .block(block)
        .marker(Marker::Braille)
        .x_bounds([-half_w, half_w])
        .y_bounds([-half_h, half_h])
        .paint(|ctx| paint(ctx, scene, center, mpc));
    f.render_widget(canvas, area);
    // Scale bar at the bottom left, north marker at the top right.
    if inner.width >= 12 && inner.height >= 3 {
        let len = scale_length_m(f64::from(inner.width / 4) * mpc);
        let cells = ((len / mpc).round() as usize).max(1);
        let bar = format!(
            "├{}┤ {}",
            "─".repeat(cells.saturating_sub(1)),
            metres_text(len)
        );
        let buf = f.buffer_mut();
        let y = inner.y + inner.height - 1;
        buf.set_stringn(inner.x, y, &bar, inner.width as usize, Style::new());
        buf.set_string(
            inner.x + inner.width - 3,
            inner.y,
            "N↑",
            Style::new().add_modifier(Modifier::BOLD),
        );
    }
}

fn kind_name(kind: ItemKind) -> &'static str {
    match kind {
        ItemKind::Takeoff => "take-off",
        ItemKind::Waypoint => "waypoint",
        ItemKind::Loiter { .. } => "loiter",
        ItemKind::Land => "land",
        ItemKind::Other => "command",
    }
}

/// The mission as a list, with each placed item's distance from the vehicle, and the vehicle's
/// distances to home and to its target.
fn draw_side(f: &mut Frame<'_>, scene: &MapScene<'_>, area: Rect) {
    let from = scene.vehicle.map(|v| v.at);
    let dist = |p: LatLon| {
        from.filter(|_| p != (0, 0)).map_or_else(String::new, |v| {
            let (e, n) = east_north_m(v, p);
            format!("{:.0} m", e.hypot(n))
        })
    };
    let mut lines = vec![
        TextLine::raw(format!("home    {}", scene.home.map_or("-".into(), dist))),
        TextLine::raw(format!("target  {}", scene.target.map_or("-".into(), dist))),
        TextLine::raw(""),
    ];
    if scene.items.is_empty() {
        lines.push(TextLine::raw("no mission loaded"));
    }
    for item in scene.items {
        let current = scene.current_seq == Some(item.seq);
        let radius = match item.kind {
            ItemKind::Loiter { radius_m } => format!(" r {radius_m:.0} m"),
            _ => String::new(),
        };
        let text = format!(
            "{} {:>3} {:<9}{:<9}{:>8}",
            if current { "▶" } else { " " },
            item.seq,
            kind_name(item.kind),
            radius,
            dist(item.at)
        );
        let style = if current {
            Style::new().fg(Color::Yellow).add_modifier(Modifier::BOLD)
        } else {
            Style::new()
        };
        lines.push(TextLine::styled(text, style));
    }
    f.render_widget(
        Paragraph::new(lines).block(Block::bordered().title(" Mission ")),
        area,
    );
}

fn paint(ctx: &mut Context<'_>, scene: &MapScene<'_>, center: LatLon, mpc: f64) {
    let xy = |p: LatLon| east_north_m(center, p);
    // The track, as segments (no list of points to build). A braille dot is half a cell wide
    // and a quarter of a cell tall, mpc/2 m either way: points closer than half a dot to the
    // last one drawn land on its dot, so they are passed over (the last point always drawn),
    // which at the default zoom skips most of a track kept 0.3 m apart.
    let step = mpc / 4.0;
    let mut last: Option<(f64, f64)> = None;
    for (i, p) in scene.track.iter().enumerate() {
        let (x, y) = xy(*p);
        if let Some((x0, y0)) = last {
            let near = (x - x0).abs() < step && (y - y0).abs() < step;
            if near && i + 1 < scene.track.len() {
                continue;
            }
            ctx.draw(&Line::new(x0, y0, x, y, Color::DarkGray));
        }
        last = Some((x, y));
    }
    ctx.layer();
    // Legs between successive placed nav items; the leg to the current item in yellow.
    let mut prev: Option<(f64, f64)> = None;
    for item in scene
        .items
        .iter()
        .filter(|i| is_leg(i.kind) && i.at != (0, 0))
    {
        let (x, y) = xy(item.at);
        let current = scene.current_seq == Some(item.seq);
        if let Some((x0, y0)) = prev {
            let colour = if current { Color::Yellow } else { Color::Blue };
            ctx.draw(&Line::new(x0, y0, x, y, colour));
        }
        if let ItemKind::Loiter { radius_m } = item.kind {
            ctx.draw(&Circle::new(x, y, f64::from(radius_m), Color::Cyan));
        }
        prev = Some((x, y));
    }
    ctx.layer();
    // Items that share a place (a take-off and a landing at home) share one label, `T1/L5`,
    // each part in its own style.
    let mut places: Vec<(LatLon, Vec<Span<'static>>)> = Vec::new();
    for item in scene.items.iter().filter(|i| i.at != (0, 0)) {
        let label = match item.kind {
            ItemKind::Takeoff => format!("T{}", item.seq),
            ItemKind::Land => format!("L{}", item.seq),
            _ => item.seq.to_string(),
        };
        let style = if scene.current_seq == Some(item.seq) {
            Style::new()
                .fg(Color::Black)
                .bg(Color::Yellow)
                .add_modifier(Modifier::BOLD)
        } else {
            Style::new().fg(Color::Cyan)
        };
        let span = Span::styled(label, style);
        match places.iter_mut().find(|(at, _)| *at == item.at) {
            Some((_, spans)) => {
                spans.push(Span::styled("/", Style::new().fg(Color::Cyan)));
                spans.push(span);
            }
            None => places.push((item.at, vec![span])),
        }
    }
    for (at, spans) in places {
        let (x, y) = xy(at);
        // Beside the point, so that home, target or vehicle on it leave it readable.
        ctx.print(x + mpc, y, TextLine::from(spans));
    }
    if let Some(h) = scene.home {
        let (x, y) = xy(h);
        ctx.print(
            x,
            y,
            Span::styled(
                "H",
                Style::new().fg(Color::Green).add_modifier(Modifier::BOLD),
            ),
        );
    }
    if let Some(t) = scene.target {
        let (x, y) = xy(t);
        ctx.print(x, y, Span::styled("✛", Style::new().fg(Color::Magenta)));
    }
    if let Some(v) = scene.vehicle {
        let (x, y) = xy(v.at);
        let arrow = v.heading_deg.map_or("●", heading_arrow);
        ctx.print(
            x,
            y,
            TextLine::from(Span::styled(
                arrow,
                Style::new().fg(Color::White).add_modifier(Modifier::BOLD),
            )),
        );
    }
}

/// The track flown by one vehicle, read incrementally from the history's GLOBAL_POSITION_INT
/// frames (each decoded once), thinned to points at least 0.3 m apart and to at most
/// [`MAX_TRACK`] points. It outlives the history's two minutes.
#[derive(Debug, Clone, Default)]
pub struct TrackCache {
    vehicle: Option<(SystemId, ComponentId)>,
    next_index: u64,
    points: Vec<LatLon>,
}

impl TrackCache {
    /// The track of `(system, component)` so far, taking in the frames not read before.
    pub fn update(
        &mut self,
        history: &History,
        system: SystemId,
        component: ComponentId,
    ) -> &[LatLon] {
        if self.vehicle != Some((system, component)) {
            *self = Self {
                vehicle: Some((system, component)),
                ..Self::default()
            };
        }
        if let Some(ring) = history
            .frames
            .get(&(system, component, GLOBAL_POSITION_INT))
        {
            for tf in ring.since(self.next_index) {
                self.next_index = tf.index + 1;
                if let Ok(MavMessage::GLOBAL_POSITION_INT(g)) = tf.frame.decode() {
                    self.push((g.lat, g.lon));
                }
            }
        }
        &self.points
    }

    /// Adds a point unless it is (0, 0) or next to the last one; halves the track when full.
    pub fn push(&mut self, p: LatLon) {
        if p == (0, 0) {
            return;
        }
        if let Some(l) = self.points.last()
            && (p.0 - l.0).abs() < TRACK_STEP_E7
            && (p.1 - l.1).abs() < TRACK_STEP_E7
        {
            return;
        }
        if self.points.len() >= MAX_TRACK {
            let mut i = 0;
            self.points.retain(|_| {
                i += 1;
                i % 2 == 1
            });
        }
        self.points.push(p);
    }

    /// The points kept.
    #[must_use]
    pub fn points(&self) -> &[LatLon] {
        &self.points
    }
}

/// Takes the shown vehicle's new positions into its track (every frame, whatever the view, so
/// the track reaches further back than the history).
pub(super) fn keep_track(
    app: &crate::tui::app::App,
    snap: &super::Snapshot<'_>,
    track: &mut TrackCache,
) {
    if let Some(v) = app.vehicle(snap.state) {
        track.update(snap.history, v.system_id, v.component_id);
    }
}

/// Draws the Map view of the shown vehicle with the app's camera and mission.
pub(super) fn draw_map_view(
    f: &mut Frame<'_>,
    app: &crate::tui::app::App,
    snap: &super::Snapshot<'_>,
    track: &TrackCache,
    area: Rect,
) {
    let (mut vehicle, mut home, mut target, mut current_seq) = (None, None, None, None);
    let mut points: &[LatLon] = &[];
    if let Some(v) = app.vehicle(snap.state) {
        (vehicle, home, target, current_seq) = scene_parts(snap.state, v);
        points = track.points();
    }
    let scene = MapScene {
        home,
        vehicle,
        target,
        items: &app.map.items,
        current_seq,
        track: points,
    };
    draw_map(f, &scene, &app.map.camera, area);
}

#[cfg(test)]
#[path = "map_tests.rs"]
mod tests;
