//! `log stats`: what a tlog holds, in one streaming pass: duration, frames per message type with
//! rates, the (system, component) pairs seen with their sequence loss, the bytes skipped as
//! garbage and a truncated last record.
//!
//! It never decodes payloads: a frame's header and its CRC check (done by the reader) are all it
//! needs, which keeps it fast on long logs.

use std::collections::BTreeMap;
use std::fmt::Write as _;

use serde::Serialize;

use crate::tlog::{Convention, Directions, TlogReader};
use crate::tracker::seq::SenderSeq;

/// Frames of one message type.
#[derive(Debug, Clone, Serialize, PartialEq)]
pub struct MessageCount {
    /// The dialect's name, or `UNKNOWN_<id>` for ids it does not know.
    pub name: String,
    /// Message id.
    pub id: u32,
    /// Frames.
    pub count: u64,
    /// Frames per second over the log's duration (0 for a log shorter than a microsecond).
    pub rate_hz: f64,
}

/// One (system, component) pair as seen in the log.
#[derive(Debug, Clone, Serialize, PartialEq)]
pub struct SourceStats {
    /// System id.
    pub system_id: u8,
    /// Component id.
    pub component_id: u8,
    /// Frames from it.
    pub frames: u64,
    /// Frames missing by its sequence numbers (gaps mod 256 between consecutive frames).
    pub seq_lost: u64,
}

impl SourceStats {
    /// Lost / (received + lost), percent.
    #[must_use]
    pub fn loss_percent(&self) -> f64 {
        let total = self.frames + self.seq_lost;
        if total == 0 {
            0.0
        } else {
            100.0 * self.seq_lost as f64 / total as f64
        }
    }
}

/// Everything `log stats` reports.
#[derive(Debug, Clone, Serialize, PartialEq)]
pub struct LogStats {
    /// File size, bytes.
    pub file_bytes: u64,
    /// Frames read.
    pub frames: u64,
    /// Frames sent towards the vehicle: by the timestamp's link bits in a log that follows
    /// that convention (MAVProxy's, this daemon's), otherwise by their sender (a ground
    /// station's frames).
    pub frames_to_vehicle: u64,
    /// How the direction was read: `link_bits` or `sender`.
    pub direction_from: &'static str,
    /// First record's time, µs since the Unix epoch.
    pub start_us: Option<u64>,
    /// Last record's time minus the first's, s.
    pub duration_s: f64,
    /// Per message type, by name.
    pub messages: Vec<MessageCount>,
    /// Per (system, component).
    pub sources: Vec<SourceStats>,
    /// Bytes skipped as garbage or damaged records.
    pub skipped_bytes: u64,
    /// Bytes of an incomplete last record (0 if the file ends cleanly).
    pub truncated_tail_bytes: u64,
}

/// Scans a log. `progress` is called now and then with the bytes consumed so far.
#[must_use]
pub fn scan(
    reader: &mut TlogReader,
    file_bytes: u64,
    directions: Directions,
    progress: &mut dyn FnMut(u64),
) -> LogStats {
    let mut directions = directions;
    let mut by_id: BTreeMap<u32, u64> = BTreeMap::new();
    // (count, lost, sequences) per (sys, comp), indexed flat for speed. A new session of a
    // sender (a restart, a second process under its identity) is no loss: see
    // `tracker::seq`.
    let mut sources: Vec<(u64, u64, SenderSeq)> = vec![(0, 0, SenderSeq::default()); 65_536];
    let (mut first, mut last) = (None, 0u64);
    let (mut frames, mut to_vehicle) = (0u64, 0u64);
    let mut last_id = u32::MAX;
    let mut last_count: u64 = 0;
    while let Some((stamp, frame)) = reader.next() {
        frames += 1;
        if directions.to_vehicle(stamp, &frame) {
            to_vehicle += 1;
        }
        first.get_or_insert(stamp);
        last = stamp;
        // Runs of one message id are common; count them before touching the map.
        let id = frame.message_id();
        if id == last_id {
            last_count += 1;
        } else {
            if last_count > 0 {
                *by_id.entry(last_id).or_default() += last_count;
            }
            last_id = id;
            last_count = 1;
        }
        let key = (usize::from(frame.system_id()) << 8) | usize::from(frame.component_id());
        let s = &mut sources[key];
        s.1 += u64::from(s.2.observe(frame.seq(), stamp));
        s.0 += 1;
        if frames.is_multiple_of(65_536) {
            progress(reader.bytes_consumed());
        }
    }
    if last_count > 0 {
        *by_id.entry(last_id).or_default() += last_count;
    }
    progress(reader.bytes_consumed());
    let duration_s = first.map_or(0.0, |f| last.saturating_sub(f) as f64 * 1e-6);
    let mut messages: Vec<MessageCount> = by_id
        .into_iter()
        .map(|(id, count)| MessageCount {
            name: message_name(id),
            id,
            count,
            rate_hz: if duration_s > 0.0 {
                count as f64 / duration_s
            } else {
                0.0
            },
        })
        .collect();
    messages.sort_by(|a, b| a.name.cmp(&b.name));
    let sources = sources
        .iter()
        .enumerate()
        .filter(|(_, s)| s.0 > 0)
        .map(|(key, s)| SourceStats {
            system_id: u8::try_from(key >> 8).unwrap_or(u8::MAX),
            component_id: u8::try_from(key & 0xFF).unwrap_or(u8::MAX),
            frames: s.0,
            seq_lost: s.1,
        })
        .collect();
    LogStats {
        file_bytes,
        frames,
        frames_to_vehicle: to_vehicle,
        direction_from: match directions.convention() {
            Convention::LinkBits => "link_bits",
            Convention::Sender => "sender",
        },
        start_us: first,
        duration_s,
        messages,
        sources,
        skipped_bytes: reader.skipped_bytes as u64,
        truncated_tail_bytes: reader.truncated_tail_bytes as u64,
    }
}

/// The dialect's name of an id, or `UNKNOWN_<id>`.
#[must_use]
pub fn message_name(id: u32) -> String {
    vtol_link::frame::message_name(id).map_or_else(|| format!("UNKNOWN_{id}"), str::to_owned)
}

/// The report as text for a terminal.
#[must_use]
pub fn render(s: &LogStats) -> String {
    let mut out = String::new();
    let start = s.start_us.map_or_else(
        || "-".to_owned(),
        |us| {
            let t = std::time::UNIX_EPOCH + std::time::Duration::from_micros(us);
            // `YYYY-MM-DD_HH-MM-SS.tlog` -> `YYYY-MM-DD HH:MM:SS`
            let name = crate::tlog::log_file_name(t);
            let (date, time) = name
                .trim_end_matches(".tlog")
                .split_once('_')
                .unwrap_or_default();
            format!("{date} {}", time.replace('-', ":"))
        },
    );
    let _ = writeln!(
        out,
        "{} frames in {} bytes, {:.3} s from {start} UTC ({} towards the vehicle, by {})",
        s.frames,
        s.file_bytes,
        s.duration_s,
        s.frames_to_vehicle,
        if s.direction_from == "link_bits" {
            "the timestamps' link bits"
        } else {
            "sender"
        }
    );
    let _ = writeln!(
        out,
        "\n{:<32} {:>6} {:>10} {:>10}",
        "message", "id", "frames", "rate Hz"
    );
    for m in &s.messages {
        let _ = writeln!(
            out,
            "{:<32} {:>6} {:>10} {:>10.2}",
            m.name, m.id, m.count, m.rate_hz
        );
    }
    let _ = writeln!(
        out,
        "\n{:<12} {:>10} {:>10} {:>8}",
        "sys:comp", "frames", "seq lost", "loss %"
    );
    for src in &s.sources {
        let _ = writeln!(
            out,
            "{:<12} {:>10} {:>10} {:>8.2}",
            format!("{}:{}", src.system_id, src.component_id),
            src.frames,
            src.seq_lost,
            src.loss_percent()
        );
    }
    let _ = writeln!(out);
    if s.skipped_bytes > 0 {
        let _ = writeln!(
            out,
            "damage: {} bytes skipped as garbage or damaged records",
            s.skipped_bytes
        );
    }
    if s.truncated_tail_bytes > 0 {
        let _ = writeln!(
            out,
            "damage: truncated last record ({} bytes)",
            s.truncated_tail_bytes
        );
    }
    if s.skipped_bytes == 0 && s.truncated_tail_bytes == 0 {
        let _ = writeln!(out, "no damage: every byte belongs to a whole record");
    }
    out
}
