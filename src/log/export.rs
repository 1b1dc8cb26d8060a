//! `log export`: a tlog's messages as CSV (one file per message type, or one wide table
//! resampled at a fixed rate) or as MCAP with a JSON schema per message type (Foxglove and
//! PlotJuggler open it).
//!
//! Time is in seconds from the log's first record. Field names are those of the MAVLink
//! definitions (see [`super::fields`]). Frames the dialect cannot decode are counted, not
//! written.

use std::collections::{BTreeMap, HashMap};
use std::io::BufWriter;
use std::path::{Path, PathBuf};
use vtol_link::text_file::Output;

use serde::Serialize;
use serde_json::Value;

use super::{LogError, finish_read, open_tlog};
use crate::fields::{self, Fields};

/// What an export wrote and what it passed over.
#[derive(Debug, Clone, Default, Serialize, PartialEq)]
pub struct ExportReport {
    /// Rows (or MCAP messages) per message type.
    pub rows: BTreeMap<String, u64>,
    /// Files written.
    pub files: Vec<PathBuf>,
    /// Frames of a selected (or any, without a selection) type the dialect could not decode.
    pub undecodable: u64,
    /// Bytes skipped as garbage or damaged records.
    pub skipped_bytes: u64,
    /// Bytes of an incomplete last record.
    pub truncated_tail_bytes: u64,
}

/// Which message types to export: all, or those named (names as in the MAVLink definitions).
#[derive(Debug, Clone, Default)]
pub struct Selection(Option<Vec<String>>);

impl Selection {
    /// Every type.
    #[must_use]
    pub fn all() -> Self {
        Self(None)
    }

    /// Only these names. Unknown names are an error, so a typo never yields an empty export.
    ///
    /// # Errors
    /// [`LogError::Unsupported`] naming the unknown message.
    pub fn only(names: &[String]) -> Result<Self, LogError> {
        let known: Vec<&str> = vtol_link::frame::known_message_ids()
            .into_iter()
            .filter_map(vtol_link::frame::message_name)
            .collect();
        for n in names {
            if !known.contains(&n.as_str()) {
                return Err(LogError::Unsupported(format!(
                    "no message called {n} in the ardupilotmega dialect"
                )));
            }
        }
        Ok(Self(Some(names.to_vec())))
    }

    fn wants_id(&self, id: u32) -> bool {
        match &self.0 {
            None => true,
            Some(names) => {
                vtol_link::frame::message_name(id).is_some_and(|n| names.iter().any(|w| w == n))
            }
        }
    }
}

fn write_err(path: &Path, e: impl std::fmt::Display) -> LogError {
    LogError::Write {
        path: path.to_owned(),
        message: e.to_string(),
    }
}

/// Flushes a CSV file and completes it (a regular file is renamed into place).
fn finish_csv(w: csv::Writer<BufWriter<Output>>) -> std::io::Result<()> {
    w.into_inner()
        .map_err(|e| std::io::Error::other(e.to_string()))?
        .into_inner()
        .map_err(std::io::IntoInnerError::into_error)?
        .finish()
}

fn seconds(stamp: u64, start: u64) -> f64 {
    stamp.saturating_sub(start) as f64 * 1e-6
}

/// One CSV per message type in `out_dir` (created), named `NAME.csv`, with columns
/// `t,system_id,component_id` and the message's fields.
///
/// # Errors
/// The log cannot be read or a file cannot be written.
pub fn csv_per_type(
    input: &Path,
    out_dir: &Path,
    selection: &Selection,
    progress: &mut dyn FnMut(u64),
) -> Result<ExportReport, LogError> {
    std::fs::create_dir_all(out_dir).map_err(|e| write_err(out_dir, e))?;
    let (mut reader, _) = open_tlog(input)?;
    let mut report = ExportReport::default();
    let mut writers: HashMap<&'static str, (PathBuf, csv::Writer<BufWriter<Output>>)> =
        HashMap::new();
    for_each_selected(&mut reader, selection, progress, &mut report, |m| {
        let Selected {
            stamp,
            start,
            frame,
            name,
            fields,
        } = m;
        let (path, w) = match writers.entry(name) {
            std::collections::hash_map::Entry::Occupied(o) => o.into_mut(),
            std::collections::hash_map::Entry::Vacant(v) => {
                let path = out_dir.join(format!("{name}.csv"));
                let file = Output::create(&path).map_err(|e| write_err(&path, e))?;
                let mut w = csv::Writer::from_writer(BufWriter::new(file));
                let header = ["t", "system_id", "component_id"]
                    .into_iter()
                    .map(str::to_owned)
                    .chain(fields.iter().map(|(k, _)| k.clone()));
                w.write_record(header).map_err(|e| write_err(&path, e))?;
                v.insert((path, w))
            }
        };
        let row = [
            format!("{:.6}", seconds(stamp, start)),
            frame.system_id().to_string(),
            frame.component_id().to_string(),
        ]
        .into_iter()
        .chain(fields.iter().map(|(_, v)| fields::csv_text(v)));
        w.write_record(row).map_err(|e| write_err(path, e))
    })?;
    finish_read(&mut reader, input)?;
    let mut files = Vec::new();
    for (_, (path, w)) in writers {
        finish_csv(w).map_err(|e| write_err(&path, e))?;
        files.push(path);
    }
    files.sort();
    report.files = files;
    report.skipped_bytes = reader.skipped_bytes as u64;
    report.truncated_tail_bytes = reader.truncated_tail_bytes as u64;
    Ok(report)
}

/// (message id, system id, component id).
type SourceKey = (u32, u8, u8);

/// Column layout of the wide table: per (type, source) the columns of its fields.
struct WideLayout {
    header: Vec<String>,
    /// Index of the first column of each source's fields.
    first_col: HashMap<SourceKey, usize>,
}

fn wide_layout(input: &Path, selection: &Selection) -> Result<WideLayout, LogError> {
    let (mut reader, _) = open_tlog(input)?;
    // name -> sources (id, sys, comp) with their field names.
    let mut seen: BTreeMap<&'static str, Vec<(SourceKey, Vec<String>)>> = BTreeMap::new();
    for (_, frame) in reader.by_ref() {
        if !selection.wants_id(frame.message_id()) {
            continue;
        }
        let key = (frame.message_id(), frame.system_id(), frame.component_id());
        let Some(name) = frame.message_name() else {
            continue;
        };
        let sources = seen.entry(name).or_default();
        if sources.iter().any(|(k, _)| *k == key) {
            continue;
        }
        if let Some((_, f)) = fields::decode(&frame) {
            sources.push((key, f.into_iter().map(|(k, _)| k).collect()));
        }
    }
    finish_read(&mut reader, input)?;
    let mut header = vec!["t".to_owned()];
    let mut first_col = HashMap::new();
    for (name, sources) in seen {
        let several = sources.len() > 1;
        for (key, names) in sources {
            first_col.insert(key, header.len());
            let prefix = if several {
                format!("{name}[{}:{}]", key.1, key.2)
            } else {
                name.to_owned()
            };
            header.extend(names.iter().map(|f| format!("{prefix}.{f}")));
        }
    }
    Ok(WideLayout { header, first_col })
}

/// One CSV table sampled every 1/`rate_hz` s from t = 0 to the log's last record: each column holds the latest value of
/// its field at or before the row's time (zero-order hold; empty before the first message).
/// One selected, decoded message of the log.
struct Selected<'a> {
    stamp: u64,
    /// The first record's stamp (of the whole log, selected or not).
    start: u64,
    frame: &'a vtol_link::Frame,
    name: &'static str,
    fields: Fields,
}

/// The exports' one pass over the log: reports progress, keeps the log's start time, skips what
/// the selection leaves out, counts what does not decode, and counts a row per message `each`
/// writes.
fn for_each_selected(
    reader: &mut crate::tlog::TlogReader,
    selection: &Selection,
    progress: &mut dyn FnMut(u64),
    report: &mut ExportReport,
    mut each: impl FnMut(Selected<'_>) -> Result<(), LogError>,
) -> Result<(), LogError> {
    let mut start = None;
    let mut n = 0u64;
    while let Some((stamp, frame)) = reader.next() {
        let start = *start.get_or_insert(stamp);
        n += 1;
        if n.is_multiple_of(16_384) {
            progress(reader.bytes_consumed());
        }
        if !selection.wants_id(frame.message_id()) {
            continue;
        }
        let Some((name, fields)) = fields::decode(&frame) else {
            report.undecodable += 1;
            continue;
        };
        each(Selected {
            stamp,
            start,
            frame: &frame,
            name,
            fields,
        })?;
        *report.rows.entry(name.to_owned()).or_default() += 1;
    }
    progress(reader.bytes_consumed());
    Ok(())
}

/// Columns are `NAME.field`, or `NAME[sys:comp].field` when several sources send that type.
///
/// # Errors
/// The log cannot be read, the rate is not positive, or the file cannot be written.
pub fn csv_wide(
    input: &Path,
    out: &Path,
    selection: &Selection,
    rate_hz: f64,
    progress: &mut dyn FnMut(u64),
) -> Result<ExportReport, LogError> {
    if !(rate_hz.is_finite() && rate_hz > 0.0) {
        return Err(LogError::Unsupported(format!(
            "--rate must be a positive number of Hz, got {rate_hz}"
        )));
    }
    let layout = wide_layout(input, selection)?;
    let file = Output::create(out).map_err(|e| write_err(out, e))?;
    let mut w = csv::Writer::from_writer(BufWriter::new(file));
    w.write_record(&layout.header)
        .map_err(|e| write_err(out, e))?;
    let mut row: Vec<String> = vec![String::new(); layout.header.len()];
    let (mut reader, _) = open_tlog(input)?;
    let mut report = ExportReport::default();
    let mut start = None;
    let mut tick: u64 = 0;
    let mut rows = 0u64;
    let mut emit_until = |t: f64,
                          inclusive: bool,
                          row: &mut Vec<String>,
                          tick: &mut u64,
                          w: &mut csv::Writer<BufWriter<Output>>|
     -> Result<(), LogError> {
        loop {
            let tk = *tick as f64 / rate_hz;
            if tk > t || (!inclusive && tk >= t) {
                return Ok(());
            }
            row[0] = format!("{tk:.6}");
            w.write_record(row.iter()).map_err(|e| write_err(out, e))?;
            rows += 1;
            *tick += 1;
        }
    };
    let mut last_t = 0.0;
    let mut n = 0u64;
    while let Some((stamp, frame)) = reader.next() {
        let start = *start.get_or_insert(stamp);
        n += 1;
        if n.is_multiple_of(16_384) {
            progress(reader.bytes_consumed());
        }
        // The table spans the whole log, not only the selected messages.
        let t = seconds(stamp, start);
        last_t = t;
        let key = (frame.message_id(), frame.system_id(), frame.component_id());
        let Some(&col) = layout.first_col.get(&key) else {
            continue;
        };
        emit_until(t, false, &mut row, &mut tick, &mut w)?;
        let Some((name, f)) = fields::decode(&frame) else {
            report.undecodable += 1;
            continue;
        };
        for (i, (_, v)) in f.iter().enumerate() {
            if let Some(cell) = row.get_mut(col + i) {
                *cell = fields::csv_text(v);
            }
        }
        *report.rows.entry(name.to_owned()).or_default() += 1;
    }
    emit_until(last_t, true, &mut row, &mut tick, &mut w)?;
    progress(reader.bytes_consumed());
    finish_read(&mut reader, input)?;
    finish_csv(w).map_err(|e| write_err(out, e))?;
    report.rows.insert("rows".into(), rows);
    report.files = vec![out.to_owned()];
    report.skipped_bytes = reader.skipped_bytes as u64;
    report.truncated_tail_bytes = reader.truncated_tail_bytes as u64;
    Ok(report)
}

/// JSON schema of a flattened message (numbers, strings, or anything for nested values).
fn json_schema(name: &str, f: &Fields) -> Vec<u8> {
    let mut props = serde_json::Map::new();
    for key in ["system_id", "component_id", "seq"] {
        props.insert(key.into(), serde_json::json!({"type": "integer"}));
    }
    for (k, v) in f {
        let ty = match v {
            Value::Number(_) => serde_json::json!({"type": "number"}),
            Value::String(_) => serde_json::json!({"type": "string"}),
            Value::Bool(_) => serde_json::json!({"type": "boolean"}),
            _ => serde_json::json!({}),
        };
        props.insert(k.clone(), ty);
    }
    serde_json::to_vec(&serde_json::json!({
        "title": name,
        "type": "object",
        "properties": props,
    }))
    .unwrap_or_default()
}

/// Every selected message into an MCAP file: one channel per (system, component, type) named
/// `/sys<S>/comp<C>/<NAME>`, JSON-encoded, with a JSON schema per type; log and publish time
/// are the tlog's timestamps.
///
/// # Errors
/// The log cannot be read or the file cannot be written.
pub fn mcap(
    input: &Path,
    out: &Path,
    selection: &Selection,
    progress: &mut dyn FnMut(u64),
) -> Result<ExportReport, LogError> {
    let file = Output::create_seekable(out).map_err(|e| write_err(out, e))?;
    let options = mcap::WriteOptions::new()
        .compression(None)
        .profile("vtol-gcs");
    let mut w = options
        .create(BufWriter::new(file))
        .map_err(|e| write_err(out, e))?;
    let (mut reader, _) = open_tlog(input)?;
    let mut report = ExportReport::default();
    let mut schemas: HashMap<&'static str, u16> = HashMap::new();
    let mut channels: HashMap<SourceKey, (u16, u32)> = HashMap::new();
    for_each_selected(&mut reader, selection, progress, &mut report, |m| {
        let Selected {
            stamp,
            frame,
            name,
            fields: f,
            ..
        } = m;
        let schema = match schemas.get(name) {
            Some(&id) => id,
            None => {
                let id = w
                    .add_schema(name, "jsonschema", &json_schema(name, &f))
                    .map_err(|e| write_err(out, e))?;
                schemas.insert(name, id);
                id
            }
        };
        let key = (frame.message_id(), frame.system_id(), frame.component_id());
        let (channel, seq) = match channels.get_mut(&key) {
            Some(c) => c,
            None => {
                let topic = format!("/sys{}/comp{}/{name}", key.1, key.2);
                let id = w
                    .add_channel(schema, &topic, "json", &BTreeMap::new())
                    .map_err(|e| write_err(out, e))?;
                channels.entry(key).or_insert((id, 0))
            }
        };
        let mut obj = serde_json::Map::new();
        obj.insert("system_id".into(), frame.system_id().into());
        obj.insert("component_id".into(), frame.component_id().into());
        obj.insert("seq".into(), frame.seq().into());
        obj.extend(f);
        let data = serde_json::to_vec(&Value::Object(obj)).map_err(|e| write_err(out, e))?;
        let ns = stamp.saturating_mul(1000);
        w.write_to_known_channel(
            &mcap::records::MessageHeader {
                channel_id: *channel,
                sequence: *seq,
                log_time: ns,
                publish_time: ns,
            },
            &data,
        )
        .map_err(|e| write_err(out, e))?;
        *seq += 1;
        Ok(())
    })?;
    finish_read(&mut reader, input)?;
    w.finish().map_err(|e| write_err(out, e))?;
    w.into_inner()
        .into_inner()
        .map_err(std::io::IntoInnerError::into_error)
        .and_then(Output::finish)
        .map_err(|e| write_err(out, e))?;
    report.files = vec![out.to_owned()];
    report.skipped_bytes = reader.skipped_bytes as u64;
    report.truncated_tail_bytes = reader.truncated_tail_bytes as u64;
    Ok(report)
}
