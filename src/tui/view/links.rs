//! The Links view: every link's health, the router counters, the log and endpoints.

use std::fmt::Write as _;

use ratatui::Frame;
use ratatui::layout::{Constraint, Layout, Rect};
use ratatui::style::{Color, Modifier, Style};
use ratatui::text::{Line, Text};
use ratatui::widgets::{Block, Cell, Paragraph, Row, Table, Wrap};

use super::{Snapshot, wrap};
use crate::links::Side;
use crate::tracker::state::LINK_TIMEOUT;

pub(super) fn draw_links(f: &mut Frame<'_>, snap: &Snapshot<'_>, area: Rect) {
    let now = snap.now;
    let [table_area, rest] =
        Layout::vertical([Constraint::Min(6), Constraint::Length(9)]).areas(area);
    // Below 110 columns the titles shorten so every one stays whole.
    let narrow = area.width < 110;
    let titles = if narrow {
        [
            "id", "side", "peer", "Hz", "loss%", "heard", "rx", "tx", "drop", "crc",
        ]
    } else {
        [
            "id", "side", "peer", "rate Hz", "loss %", "heard", "rx", "tx", "dropped", "bad crc",
        ]
    };
    let header = Row::new(titles).style(Style::new().add_modifier(Modifier::BOLD));
    // What the narrow layout leaves the peer: the fixed columns and their spacing taken.
    let peer_w = usize::from(
        area.width
            .saturating_sub(2 + 3 + 4 + 5 + 5 + 11 + 7 + 7 + 4 + 3 + 9),
    );
    let rows: Vec<Row> = snap
        .links
        .iter()
        .map(|l| {
            let h = snap.state.links.get(&l.id);
            let (rate, loss, heard, lost) = match h {
                Some(h) => (
                    // Five columns: a thousand frames a second and more without the tenth.
                    match h.window.rate_hz(now) {
                        r if r >= 999.95 => format!("{r:.0}"),
                        r => format!("{r:.1}"),
                    },
                    format!("{:.1}", h.window.loss_pct(now)),
                    format!(
                        "{:.1} s",
                        now.saturating_duration_since(h.last_heard).as_secs_f64()
                    ),
                    h.is_lost(now),
                ),
                None => ("0.0".into(), "-".into(), "never".into(), false),
            };
            // Narrow, the side takes three letters so that the address keeps its row.
            let side = match (l.side, l.own, narrow) {
                (_, true, _) => "own",
                (Side::Vehicle, _, false) => "vehicle",
                (Side::Vehicle, _, true) => "veh",
                (Side::Client, _, false) => "client",
                (Side::Client, _, true) => "cli",
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
            // Narrow, the peer wraps in its column rather than lose its end (the port).
            let peer = if narrow {
                peer_lines(&peer, peer_w)
            } else {
                vec![peer]
            };
            let height = u16::try_from(peer.len()).unwrap_or(1);
            Row::new(vec![
                Cell::from(if narrow {
                    l.id.0.to_string()
                } else {
                    l.id.to_string()
                }),
                Cell::from(side),
                Cell::from(Text::from(
                    peer.into_iter().map(Line::raw).collect::<Vec<_>>(),
                )),
                Cell::from(rate),
                Cell::from(loss),
                Cell::from(if lost { format!("LOST {heard}") } else { heard }),
                Cell::from(l.stats.rx_frames.to_string()),
                Cell::from(l.stats.tx_frames.to_string()),
                Cell::from((l.stats.tx_dropped_queue_full + rate_dropped).to_string()),
                Cell::from(l.stats.bad_crc.to_string()),
            ])
            .height(height)
            .style(style)
        })
        .collect();
    let widths = if narrow {
        [
            Constraint::Length(3),
            Constraint::Length(4),
            Constraint::Min(9),
            Constraint::Length(5),
            Constraint::Length(5),
            Constraint::Length(11),
            Constraint::Length(7),
            Constraint::Length(7),
            Constraint::Length(4),
            Constraint::Length(3),
        ]
    } else {
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
        ]
    };
    f.render_widget(
        Table::new(rows, widths)
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

/// A peer in lines of `width`: words whole where they fit, an address too long for a line
/// broken after a `:` (host, then port) rather than inside a number.
fn peer_lines(peer: &str, width: usize) -> Vec<String> {
    let mut words = Vec::new();
    for word in peer.split_whitespace() {
        let mut rest = word;
        while rest.chars().count() > width {
            let head: String = rest.chars().take(width).collect();
            let Some(cut) = head.rfind(':').filter(|c| *c > 0) else {
                break;
            };
            words.push(&rest[..=cut]);
            rest = &rest[cut + 1..];
        }
        words.push(rest);
    }
    wrap(&words.join(" "), width)
}

#[cfg(test)]
mod tests {
    use super::peer_lines;

    #[test]
    fn an_address_breaks_at_its_colon_not_inside_a_number() {
        assert_eq!(peer_lines("tcp 127.0.0.1:5810", 20), ["tcp 127.0.0.1:5810"]);
        assert_eq!(
            peer_lines("udp 192.168.100.200:14550", 20),
            ["udp 192.168.100.200:", "14550"]
        );
        // A host longer than the column is cut where it must, the port kept with its colon.
        assert_eq!(
            peer_lines("udp 192.168.100.200:14550", 12),
            ["udp", "192.168.100.", "200:14550"]
        );
    }
}
