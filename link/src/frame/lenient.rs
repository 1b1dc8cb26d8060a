//! Decoding like pymavlink: a message whose enum field holds a value the dialect does not
//! define (a newer MAV_TYPE, a command number from another dialect) still decodes.
//!
//! The `mavlink` crate refuses such a payload with `InvalidEnum`. Each enum field's place in
//! the payload is learnt once per message id from the dialect itself (a probe value written at
//! each offset makes the parser name the enum and the value it read, which gives the field's
//! offset and width); on `InvalidEnum` the offending field is set to the value the dialect's
//! default message holds there and the parse is retried. The frame's bytes are never changed:
//! the raw numbers stay readable from [`super::Frame::payload`], and [`Lenient::replaced`]
//! says which fields hold a stand-in.

use std::sync::{Arc, Mutex, OnceLock};

use mavlink::error::ParserError;
use mavlink::{MavlinkVersion, Message};

use crate::dialect::MavMessage;

/// Room for any payload (MAVLink 2's limit).
const MAX_PAYLOAD: usize = 255;

/// One enum field of a message's payload, as the dialect lays it out.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct EnumField {
    /// Byte offset in the (zero-filled) payload.
    pub offset: u8,
    /// Width in bytes on the wire: 1, 2 or 4.
    pub width: u8,
    /// The enum's Rust name in the dialect (`MavType`, `MavCmd`).
    pub enum_type: &'static str,
}

/// A field whose value the dialect does not define, decoded as the dialect's default instead.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Replaced {
    /// Where the field is.
    pub field: EnumField,
    /// The value on the wire.
    pub value: u32,
}

/// A message decoded leniently.
#[derive(Debug, Clone, PartialEq)]
pub struct Lenient {
    /// The message; a field listed in `replaced` holds its enum's stand-in, not the wire value.
    pub msg: MavMessage,
    /// The fields the dialect could not represent, in payload order (empty for most frames).
    pub replaced: Vec<Replaced>,
}

impl Lenient {
    /// The wire value of a replaced field of this enum type, if one was replaced (the first,
    /// for messages with several fields of the type).
    #[must_use]
    pub fn raw(&self, enum_type: &str) -> Option<u32> {
        self.replaced
            .iter()
            .find(|r| r.field.enum_type == enum_type)
            .map(|r| r.value)
    }
}

/// A message id's layout: its default payload and its enum fields.
struct Layout {
    default: [u8; MAX_PAYLOAD],
    fields: Vec<EnumField>,
}

/// Probe values written over a field's bytes: distinct bytes, so the value the parser reports
/// tells how many of them it read. Several, for enums that define one of them.
const PROBES: [[u8; 4]; 3] = [
    [0xA5, 0x5A, 0x3C, 0x96],
    [0xF3, 0xE7, 0xD1, 0xC9],
    [0x6B, 0xB6, 0x4D, 0xD4],
];

fn le(bytes: &[u8]) -> u32 {
    bytes
        .iter()
        .rev()
        .fold(0u32, |acc, b| (acc << 8) | u32::from(*b))
}

/// Whether the value a parser reports (`tmp as u64`: sign-extended for a signed field) is the
/// `width` bytes `raw`.
fn reads_as(value: u64, raw: u32, width: usize) -> bool {
    let bits = 8 * width as u32;
    let mask = if bits >= 64 {
        u64::MAX
    } else {
        (1u64 << bits) - 1
    };
    let high = value & !mask;
    value & mask == u64::from(raw) && (high == 0 || high == !mask)
}

/// Learns the enum fields of a message id from the dialect (a few hundred parses, once).
fn learn(id: u32) -> Option<Layout> {
    let msg = MavMessage::default_message_from_id(id)?;
    let mut default = [0u8; MAX_PAYLOAD];
    msg.ser(MavlinkVersion::V2, &mut default);
    let mut fields = Vec::new();
    let mut at = 0usize;
    while at < MAX_PAYLOAD {
        let mut found = None;
        for probe in PROBES {
            let mut p = default;
            let n = (MAX_PAYLOAD - at).min(4);
            p[at..at + n].copy_from_slice(&probe[..n]);
            if let Err(ParserError::InvalidEnum { enum_type, value }) =
                MavMessage::parse(MavlinkVersion::V2, id, &p)
            {
                let width = [1usize, 2, 4]
                    .into_iter()
                    .find(|w| *w <= n && reads_as(value, le(&probe[..*w]), *w));
                if let Some(w) = width {
                    found = Some(EnumField {
                        offset: at as u8,
                        width: w as u8,
                        enum_type,
                    });
                    break;
                }
            }
        }
        match found {
            Some(f) => {
                fields.push(f);
                at += usize::from(f.width);
            }
            None => at += 1,
        }
    }
    Some(Layout { default, fields })
}

/// The layout of a message id, learnt on first use.
fn layout(id: u32) -> Option<Arc<Layout>> {
    static LAYOUTS: OnceLock<Mutex<foldhash::HashMap<u32, Option<Arc<Layout>>>>> = OnceLock::new();
    let cache = LAYOUTS.get_or_init(Default::default);
    if let Some(l) = cache.lock().ok()?.get(&id) {
        return l.clone();
    }
    let learnt = learn(id).map(Arc::new);
    if let Ok(mut c) = cache.lock() {
        c.insert(id, learnt.clone());
    }
    learnt
}

/// The enum fields of a message id (empty for an id the dialect does not know).
#[must_use]
pub fn enum_fields(message_id: u32) -> Vec<EnumField> {
    layout(message_id).map_or_else(Vec::new, |l| l.fields.clone())
}

/// Parses `payload`, replacing every enum value the dialect rejects by its default message's
/// value at that field. The error is the parser's when no enum field explains it.
pub(super) fn parse(
    version: MavlinkVersion,
    id: u32,
    payload: &[u8],
) -> Result<Lenient, ParserError> {
    let first = match MavMessage::parse(version, id, payload) {
        Ok(msg) => {
            return Ok(Lenient {
                msg,
                replaced: Vec::new(),
            });
        }
        Err(e @ ParserError::InvalidEnum { .. }) => e,
        Err(e) => return Err(e),
    };
    let Some(layout) = layout(id) else {
        return Err(first);
    };
    let mut p = [0u8; MAX_PAYLOAD];
    let n = payload.len().min(MAX_PAYLOAD);
    p[..n].copy_from_slice(&payload[..n]);
    let mut replaced = Vec::new();
    let mut err = first;
    // Each round fixes one field; a field is never fixed twice.
    for _ in 0..=layout.fields.len() {
        let ParserError::InvalidEnum { enum_type, value } = err else {
            return Err(err);
        };
        let span =
            |f: &EnumField| usize::from(f.offset)..usize::from(f.offset) + usize::from(f.width);
        let Some(field) = layout.fields.iter().find(|f| {
            f.enum_type == enum_type
                && reads_as(value, le(&p[span(f)]), usize::from(f.width))
                && !replaced.iter().any(|r: &Replaced| r.field == **f)
        }) else {
            return Err(ParserError::InvalidEnum { enum_type, value });
        };
        replaced.push(Replaced {
            field: *field,
            value: le(&p[span(field)]),
        });
        p[span(field)].copy_from_slice(&layout.default[span(field)]);
        match MavMessage::parse(version, id, &p) {
            Ok(msg) => {
                replaced.sort_by_key(|r| r.field.offset);
                return Ok(Lenient { msg, replaced });
            }
            Err(e) => err = e,
        }
    }
    Err(err)
}
