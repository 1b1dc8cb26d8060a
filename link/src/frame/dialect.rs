//! What the dialect tells about each message id (name, CRC_EXTRA, target offsets), learnt once,
//! and the checksum and length of a frame.

use std::sync::OnceLock;

use mavlink::{MavlinkVersion, Message};

use super::{
    CRC_LEN, HEADER_LEN_V1, HEADER_LEN_V2, INCOMPAT_SIGNED, MAGIC_V1, MAGIC_V2, SIGNATURE_LEN,
};
use crate::dialect::MavMessage;

/// What the dialect tells us about one message id, computed once.
#[derive(Debug, Clone, Copy)]
pub(super) struct MsgInfo {
    name: &'static str,
    crc_extra: u8,
    /// Byte offset of `target_system` in the (zero-filled) payload.
    pub(super) target_system_offset: Option<u8>,
    /// Byte offset of `target_component` in the (zero-filled) payload.
    pub(super) target_component_offset: Option<u8>,
}

/// Finds the payload byte a setter changes, by serialising the message before and after.
pub(super) fn field_offset(msg: &MavMessage, set: impl Fn(&mut MavMessage) -> bool) -> Option<u8> {
    let mut before = [0u8; 255];
    let mut after = [0u8; 255];
    msg.ser(MavlinkVersion::V2, &mut before);
    let mut changed = msg.clone();
    if !set(&mut changed) {
        return None;
    }
    changed.ser(MavlinkVersion::V2, &mut after);
    let pos = before.iter().zip(after.iter()).position(|(a, b)| a != b)?;
    u8::try_from(pos).ok()
}

/// The dialect's message table. The generated code has no list of ids, so probe every id that
/// fits in 16 bits (all ardupilotmega ids do) once; that takes a few milliseconds.
pub(super) fn dialect_table() -> &'static foldhash::HashMap<u32, MsgInfo> {
    static TABLE: OnceLock<foldhash::HashMap<u32, MsgInfo>> = OnceLock::new();
    TABLE.get_or_init(|| {
        let mut table = foldhash::HashMap::default();
        for id in 0..=u32::from(u16::MAX) {
            let Some(msg) = MavMessage::default_message_from_id(id) else {
                continue;
            };
            // 0xA5 differs from every default (targets default to 0), so exactly one byte moves.
            let target_system_offset = field_offset(&msg, |m| {
                m.target_system_id_mut().map(|t| *t = 0xA5).is_some()
            });
            let target_component_offset = field_offset(&msg, |m| {
                m.target_component_id_mut().map(|t| *t = 0xA5).is_some()
            });
            table.insert(
                id,
                MsgInfo {
                    name: msg.message_name(),
                    crc_extra: MavMessage::extra_crc(id),
                    target_system_offset,
                    target_component_offset,
                },
            );
        }
        table
    })
}

/// Every message id the dialect knows, ascending.
pub fn known_message_ids() -> Vec<u32> {
    let mut ids: Vec<u32> = dialect_table().keys().copied().collect();
    ids.sort_unstable();
    ids
}

/// The CRC_EXTRA of a message id, or `None` if the dialect does not know it.
pub fn crc_extra(message_id: u32) -> Option<u8> {
    dialect_table().get(&message_id).map(|i| i.crc_extra)
}

/// The dialect's name of a message id (e.g. `"HEARTBEAT"`), if known.
pub fn message_name(message_id: u32) -> Option<&'static str> {
    dialect_table().get(&message_id).map(|i| i.name)
}

/// MAVLink's CRC (X.25 / MCRF4XX) over `data` followed by `crc_extra`.
pub fn frame_crc(data: &[u8], crc_extra: u8) -> u16 {
    // One 512-byte table: a frame is short, and a slice-by-16 table (8 KiB) would take more
    // cache lines per frame than the bytes it saves work on.
    static MCRF4XX: crc::Crc<u16, crc::Table<1>> =
        crc::Crc::<u16, crc::Table<1>>::new(&crc::CRC_16_MCRF4XX);
    let mut digest = MCRF4XX.digest();
    digest.update(data);
    digest.update(&[crc_extra]);
    digest.finalize()
}

/// Total frame length from the first bytes of a candidate frame, if enough bytes are there
/// (v1: 2 bytes; v2: 3 bytes, the incompat byte decides about the signature).
pub fn frame_len_from_prefix(prefix: &[u8]) -> Option<usize> {
    match *prefix.first()? {
        MAGIC_V1 => Some(HEADER_LEN_V1 + usize::from(*prefix.get(1)?) + CRC_LEN),
        MAGIC_V2 => {
            let payload = usize::from(*prefix.get(1)?);
            let signed = prefix.get(2)? & INCOMPAT_SIGNED != 0;
            Some(HEADER_LEN_V2 + payload + CRC_LEN + if signed { SIGNATURE_LEN } else { 0 })
        }
        _ => None,
    }
}
