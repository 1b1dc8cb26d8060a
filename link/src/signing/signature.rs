//! A signature: the trailer's fields, computing one, signing a frame, checking one.

use bytes::Bytes;
use sha2::{Digest, Sha256};

use crate::frame::{
    CRC_LEN, Frame, HEADER_LEN_V2, INCOMPAT_SIGNED, SIGNATURE_LEN, crc_extra, frame_crc,
};

use super::{MAX_TIMESTAMP, SIGNATURE_BYTES, SigningKey};

/// The 13-byte trailer of a signed frame, read.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct SignatureFields {
    /// The sender's link id.
    pub link_id: u8,
    /// The 48-bit timestamp.
    pub timestamp: u64,
    /// The 6 signature bytes.
    pub signature: [u8; SIGNATURE_BYTES],
}

impl SignatureFields {
    /// The trailer of a signed frame; `None` for unsigned and MAVLink 1 frames.
    #[must_use]
    pub fn of(frame: &Frame) -> Option<SignatureFields> {
        let sig = frame.signature()?;
        let mut ts = [0u8; 8];
        ts[..6].copy_from_slice(&sig[1..7]);
        let mut signature = [0u8; SIGNATURE_BYTES];
        signature.copy_from_slice(&sig[7..]);
        Some(SignatureFields {
            link_id: sig[0],
            timestamp: u64::from_le_bytes(ts),
            signature,
        })
    }
}

/// Why a frame cannot be signed.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum SignError {
    /// MAVLink 1 has no signatures.
    #[error("a MAVLink 1 frame cannot be signed")]
    NotV2,
    /// An unsigned frame of an id outside the dialect whose CRC matches no CRC_EXTRA: its CRC
    /// cannot be recomputed for the signed header.
    #[error("cannot sign message id {0}: its CRC_EXTRA is unknown and its CRC matches none")]
    UnknownCrcExtra(u32),
    /// The 48-bit timestamp has run out (year 2104, or a corrupt persisted timestamp).
    #[error("signing timestamp exhausted (48 bits)")]
    TimestampExhausted,
}

/// The signature of `signed_prefix` (a signed frame from the magic through the timestamp).
#[must_use]
pub fn signature_of(key: &SigningKey, signed_prefix: &[u8]) -> [u8; SIGNATURE_BYTES] {
    let digest = Sha256::new()
        .chain_update(key.as_bytes())
        .chain_update(signed_prefix)
        .finalize();
    let mut sig = [0u8; SIGNATURE_BYTES];
    sig.copy_from_slice(&digest[..SIGNATURE_BYTES]);
    sig
}

/// The CRC_EXTRA that gives `frame` its CRC: the dialect's, or for an id outside it the one
/// value (the CRC's last step is one-to-one in that byte) that reproduces the stored CRC.
pub(super) fn crc_extra_of(frame: &Frame) -> Option<u8> {
    if let Some(extra) = crc_extra(frame.message_id()) {
        return Some(extra);
    }
    let covered = &frame.as_bytes()[1..HEADER_LEN_V2 + frame.payload_len()];
    (0..=u8::MAX).find(|&x| frame_crc(covered, x) == frame.crc())
}

/// Signs a MAVLink 2 frame with an explicit link id and timestamp (stateless; most callers
/// want [`Signing::sign`]). An already signed frame gets a new trailer; an unsigned one gets
/// the signed flag and a CRC recomputed over the changed header.
pub fn sign_frame(
    key: &SigningKey,
    frame: &Frame,
    link_id: u8,
    timestamp: u64,
) -> Result<Frame, SignError> {
    if !frame.is_v2() {
        return Err(SignError::NotV2);
    }
    if timestamp > MAX_TIMESTAMP {
        return Err(SignError::TimestampExhausted);
    }
    let body_len = HEADER_LEN_V2 + frame.payload_len() + CRC_LEN;
    let mut buf = Vec::with_capacity(body_len + SIGNATURE_LEN);
    buf.extend_from_slice(&frame.as_bytes()[..body_len]);
    if !frame.is_signed() {
        let extra = crc_extra_of(frame).ok_or(SignError::UnknownCrcExtra(frame.message_id()))?;
        buf[2] |= INCOMPAT_SIGNED;
        let crc = frame_crc(&buf[1..body_len - CRC_LEN], extra);
        buf[body_len - CRC_LEN..].copy_from_slice(&crc.to_le_bytes());
    }
    buf.push(link_id);
    buf.extend_from_slice(&timestamp.to_le_bytes()[..6]);
    let sig = signature_of(key, &buf);
    buf.extend_from_slice(&sig);
    Ok(Frame::from_checked(Bytes::from(buf), frame.is_verified()))
}

/// True if `frame` is signed and its signature is right for `key` (no timestamp rules).
#[must_use]
pub fn signature_matches(key: &SigningKey, frame: &Frame) -> bool {
    let Some(fields) = SignatureFields::of(frame) else {
        return false;
    };
    let bytes = frame.as_bytes();
    let expected = signature_of(key, &bytes[..bytes.len() - SIGNATURE_BYTES]);
    // Compare every byte (no early exit on the first difference).
    expected
        .iter()
        .zip(fields.signature.iter())
        .fold(0u8, |acc, (a, b)| acc | (a ^ b))
        == 0
}
