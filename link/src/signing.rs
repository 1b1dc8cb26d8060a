//! MAVLink 2 message signing, written once for the daemon and the twin.
//!
//! Contract (MAVLink devguide "Message Signing", byte order as pymavlink and the C library):
//! - A signed frame has incompat flag 0x01 set and 13 more bytes after the CRC:
//!   `link_id (1) | timestamp (6, little-endian) | signature (6)`. The timestamp counts 10 µs
//!   units since 2015-01-01 00:00:00 UTC (Unix time 1 420 070 400 s) and has 48 bits.
//! - `signature = SHA-256(key ‖ frame bytes from the magic 0xFD through the timestamp)[..6]`,
//!   the frame bytes including the header with the signed flag set, the payload, the CRC
//!   (computed over that header) and the link id.
//! - [`SigningKey`]: 32 secret bytes, from a passphrase (SHA-256 of its UTF-8 bytes, as MAVProxy's
//!   `signing setup` does) or from a key file of 64 hex characters. `Debug` and `Display` never
//!   show key bytes, and no error of this module quotes them.
//! - [`TimestampSource`]: the timestamp we send with never goes back, grows by at least 1 per
//!   signed frame and follows the wall clock (`max(last + 1, now)`), so a link that was idle or
//!   cut for minutes resumes with timestamps a receiver takes, even one that forgot our stream.
//!   Accepting a signed frame raises it to the frame's timestamp, as the spec asks.
//! - [`Signing::verify`] accepts a frame when its signature is right and, for its stream
//!   `(link id, system id, component id)`, its timestamp is strictly greater than the last one
//!   accepted; the first frame of a stream is refused if it is more than 60 s
//!   ([`NEW_STREAM_WINDOW`]) behind our own timestamp. Unsigned frames (MAVLink 1 included) are
//!   refused unless their message id is on the allow-list (RADIO_STATUS by default). A refused
//!   frame changes no state.
//! - [`SigningState`] (key and last timestamp) persists as a small TOML file
//!   (`key = "<64 hex>"`, `timestamp = N`), written with owner-only permissions; every broken
//!   file gives one [`SigningFileError`] naming the file and, where it can, the line.
//!
//! Nothing here reads the clock by itself except the `*_now` conveniences: callers pass `now`,
//! so tests can move time freely.

use std::collections::HashMap;
use std::fmt;
use std::path::{Path, PathBuf};
use std::time::{Duration, SystemTime, UNIX_EPOCH};

use bytes::Bytes;
use sha2::{Digest, Sha256};

use crate::frame::{
    CRC_LEN, Frame, HEADER_LEN_V2, INCOMPAT_SIGNED, SIGNATURE_LEN, crc_extra, frame_crc,
};

/// How a signing state file is written, as its errors say it (never with a value of the file).
pub const STATE_FILE_FORMAT: &str = "expected key = \"64 hex characters\" and timestamp = N";

/// Seconds from the Unix epoch to the signing epoch, 2015-01-01 00:00:00 UTC.
pub const SIGNING_EPOCH_UNIX_S: u64 = 1_420_070_400;
/// Timestamp units per second (one unit is 10 µs).
pub const TIMESTAMP_UNITS_PER_S: u64 = 100_000;
/// Largest timestamp a signature can carry (48 bits).
pub const MAX_TIMESTAMP: u64 = (1 << 48) - 1;
/// How far (in timestamp units: 60 s) the first frame of a new stream may be behind our own
/// timestamp (devguide; pymavlink and the C library use the same 6 000 000).
pub const NEW_STREAM_WINDOW: u64 = 60 * TIMESTAMP_UNITS_PER_S;
/// Message id of RADIO_STATUS, which radios inject unsigned: allowed unsigned by default.
pub const MSG_ID_RADIO_STATUS: u32 = 109;
/// Message id of SETUP_SIGNING.
pub const MSG_ID_SETUP_SIGNING: u32 = 256;
/// At most this many streams are remembered; a further new stream is refused (the C library
/// keeps 16). Only frames with a right signature create streams.
pub const MAX_STREAMS: usize = 1024;
/// Bytes of the signature proper (the last field of the trailer).
pub const SIGNATURE_BYTES: usize = 6;
/// Bytes of a signing key.
pub const KEY_LEN: usize = 32;

/// A 32-byte MAVLink 2 signing key. Its bytes never appear in `Debug` or `Display`.
#[derive(Clone, PartialEq, Eq)]
pub struct SigningKey([u8; KEY_LEN]);

impl fmt::Debug for SigningKey {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str("SigningKey(<secret>)")
    }
}

impl fmt::Display for SigningKey {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str("<secret signing key>")
    }
}

/// Why text is not a signing key. The text itself is never quoted.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum KeyError {
    /// Not 64 characters (after trimming white space).
    #[error("a signing key is 64 hex characters, got {chars}")]
    WrongLength {
        /// Characters found.
        chars: usize,
    },
    /// A character that is not a hex digit.
    #[error("a signing key is 64 hex characters: character {position} is not a hex digit")]
    NotHex {
        /// 1-based position of the first bad character.
        position: usize,
    },
}

impl SigningKey {
    /// The key from its 32 bytes.
    #[must_use]
    pub fn from_bytes(bytes: [u8; KEY_LEN]) -> SigningKey {
        SigningKey(bytes)
    }

    /// The key MAVProxy's `signing setup PASSPHRASE` uses: SHA-256 of the passphrase's UTF-8
    /// bytes.
    #[must_use]
    pub fn from_passphrase(passphrase: &str) -> SigningKey {
        SigningKey(Sha256::digest(passphrase.as_bytes()).into())
    }

    /// The key from 64 hex characters (either case; white space around them is ignored).
    pub fn from_hex(text: &str) -> Result<SigningKey, KeyError> {
        let text = text.trim();
        let chars = text.chars().count();
        if chars != 2 * KEY_LEN {
            return Err(KeyError::WrongLength { chars });
        }
        if let Some(pos) = text.chars().position(|c| !c.is_ascii_hexdigit()) {
            return Err(KeyError::NotHex { position: pos + 1 });
        }
        let mut bytes = [0u8; KEY_LEN];
        hex::decode_to_slice(text, &mut bytes).map_err(|_| KeyError::WrongLength { chars })?;
        Ok(SigningKey(bytes))
    }

    /// Reads a key file: 64 hex characters (a trailing newline is fine).
    pub fn from_key_file(path: &Path) -> Result<SigningKey, SigningFileError> {
        let text = read_text(path)?;
        SigningKey::from_hex(&text).map_err(|source| SigningFileError::Key {
            path: path.to_owned(),
            source,
        })
    }

    /// The key as 64 lowercase hex characters, for writing a key or state file. Never log it.
    #[must_use]
    pub fn to_hex(&self) -> String {
        hex::encode(self.0)
    }

    /// The raw key bytes (for SETUP_SIGNING). Never log them.
    #[must_use]
    pub fn as_bytes(&self) -> &[u8; KEY_LEN] {
        &self.0
    }

    /// True for the all-zero key, which SETUP_SIGNING uses to switch signing off.
    #[must_use]
    pub fn is_zero(&self) -> bool {
        self.0.iter().all(|&b| b == 0)
    }
}

/// The signing timestamp of a wall-clock time: 10 µs units since 2015-01-01 00:00 UTC, 0 for
/// earlier times, [`MAX_TIMESTAMP`] past the 48-bit range (year 2104).
#[must_use]
pub fn timestamp_at(now: SystemTime) -> u64 {
    let since_unix = now.duration_since(UNIX_EPOCH).unwrap_or(Duration::ZERO);
    let Some(since_epoch) = since_unix.checked_sub(Duration::from_secs(SIGNING_EPOCH_UNIX_S))
    else {
        return 0;
    };
    let units = since_epoch.as_micros() / 10;
    u64::try_from(units).map_or(MAX_TIMESTAMP, |u| u.min(MAX_TIMESTAMP))
}

/// The timestamps we sign with: never back, +1 at least per frame, and never behind the wall
/// clock (see the module docs).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct TimestampSource {
    last: u64,
}

impl TimestampSource {
    /// A source whose next timestamp is above `initial` (a persisted value, or 0).
    #[must_use]
    pub fn new(initial: u64) -> TimestampSource {
        TimestampSource {
            last: initial.min(MAX_TIMESTAMP),
        }
    }

    /// The last timestamp used or accepted (what to persist).
    #[must_use]
    pub fn last(&self) -> u64 {
        self.last
    }

    /// Our timestamp at `now` without using one: `max(last, wall clock)`.
    #[must_use]
    pub fn current(&self, now: SystemTime) -> u64 {
        self.last.max(timestamp_at(now))
    }

    /// The timestamp for the next signed frame: `max(last + 1, wall clock)`.
    pub fn next(&mut self, now: SystemTime) -> Result<u64, SignError> {
        let after = self
            .last
            .checked_add(1)
            .filter(|&t| t <= MAX_TIMESTAMP)
            .ok_or(SignError::TimestampExhausted)?;
        self.last = after.max(timestamp_at(now));
        Ok(self.last)
    }

    /// Raises the source to a timestamp accepted from a peer (our next one will be above it).
    pub fn observe(&mut self, timestamp: u64) {
        self.last = self.last.max(timestamp.min(MAX_TIMESTAMP));
    }
}

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
fn crc_extra_of(frame: &Frame) -> Option<u8> {
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

/// Why [`Signing::verify`] refused a frame. No state changed.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum Refusal {
    /// Unsigned (or MAVLink 1), and its id is not on the allow-list.
    #[error("unsigned message id {message_id} refused")]
    Unsigned {
        /// The frame's message id.
        message_id: u32,
    },
    /// The signature does not match our key (wrong key, or the frame was changed).
    #[error("bad signature")]
    BadSignature,
    /// The timestamp is not above the last one accepted on this stream (a replay).
    #[error(
        "replayed or old timestamp {timestamp} on stream (link {link_id}, system {system_id}, \
         component {component_id}): last accepted {last}"
    )]
    Replayed {
        /// Link id of the stream.
        link_id: u8,
        /// Sender's system id.
        system_id: u8,
        /// Sender's component id.
        component_id: u8,
        /// The frame's timestamp.
        timestamp: u64,
        /// The last timestamp accepted on the stream.
        last: u64,
    },
    /// The first frame of a new stream is more than [`NEW_STREAM_WINDOW`] behind our timestamp.
    #[error("new stream's timestamp {timestamp} is more than 60 s behind ours ({ours})")]
    TooOld {
        /// The frame's timestamp.
        timestamp: u64,
        /// Our timestamp when it came.
        ours: u64,
    },
    /// [`MAX_STREAMS`] streams are already known.
    #[error("too many signing streams ({MAX_STREAMS})")]
    TooManyStreams,
}

/// What [`Signing::verify`] accepted.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Accepted {
    /// A signed frame with a right signature and a fresh timestamp.
    Signed {
        /// The sender's link id.
        link_id: u8,
        /// Its timestamp.
        timestamp: u64,
    },
    /// An unsigned frame whose message id is on the allow-list.
    UnsignedAllowed,
}

/// The signing side of one party: a key, the link id it signs with, its timestamp source, the
/// streams it has accepted and the unsigned allow-list.
#[derive(Debug, Clone)]
pub struct Signing {
    key: SigningKey,
    link_id: u8,
    clock: TimestampSource,
    streams: HashMap<(u8, u8, u8), u64>,
    allow_unsigned: Vec<u32>,
}

impl Signing {
    /// Signing with `key` on `link_id`, starting above `initial_timestamp` (a persisted value or
    /// 0); unsigned RADIO_STATUS allowed.
    #[must_use]
    pub fn new(key: SigningKey, link_id: u8, initial_timestamp: u64) -> Signing {
        Signing {
            key,
            link_id,
            clock: TimestampSource::new(initial_timestamp),
            streams: HashMap::new(),
            allow_unsigned: vec![MSG_ID_RADIO_STATUS],
        }
    }

    /// Signing from a persisted state.
    #[must_use]
    pub fn from_state(state: &SigningState, link_id: u8) -> Signing {
        Signing::new(state.key.clone(), link_id, state.timestamp)
    }

    /// Replaces the list of message ids accepted unsigned.
    #[must_use]
    pub fn with_allow_unsigned(mut self, message_ids: &[u32]) -> Signing {
        self.allow_unsigned = message_ids.to_vec();
        self
    }

    /// The key.
    #[must_use]
    pub fn key(&self) -> &SigningKey {
        &self.key
    }

    /// The link id we sign with.
    #[must_use]
    pub fn link_id(&self) -> u8 {
        self.link_id
    }

    /// Our timestamp source.
    #[must_use]
    pub fn clock(&self) -> &TimestampSource {
        &self.clock
    }

    /// What to persist at `now`: the key and our current timestamp.
    #[must_use]
    pub fn state(&self, now: SystemTime) -> SigningState {
        SigningState {
            key: self.key.clone(),
            timestamp: self.clock.current(now),
        }
    }

    /// Signs `frame` with the next timestamp.
    pub fn sign(&mut self, frame: &Frame, now: SystemTime) -> Result<Frame, SignError> {
        self.sign_as(frame, self.link_id, now)
    }

    /// Signs `frame` with the next timestamp as link `link_id` instead of our own: one party
    /// that signs for several links (a router signing each client's frames) keeps one
    /// timestamp source, so no two of its frames share a timestamp, and each link its stream.
    pub fn sign_as(
        &mut self,
        frame: &Frame,
        link_id: u8,
        now: SystemTime,
    ) -> Result<Frame, SignError> {
        if !frame.is_v2() {
            return Err(SignError::NotV2);
        }
        let mut clock = self.clock;
        let timestamp = clock.next(now)?;
        let signed = sign_frame(&self.key, frame, link_id, timestamp)?;
        self.clock = clock;
        Ok(signed)
    }

    /// [`Signing::sign`] at the wall clock's now.
    pub fn sign_now(&mut self, frame: &Frame) -> Result<Frame, SignError> {
        self.sign(frame, SystemTime::now())
    }

    /// Checks a received frame against the key, the streams and the allow-list (module docs).
    /// Accepting a signed frame records its stream's timestamp and raises our own.
    pub fn verify(&mut self, frame: &Frame, now: SystemTime) -> Result<Accepted, Refusal> {
        let Some(fields) = SignatureFields::of(frame) else {
            let message_id = frame.message_id();
            return if self.allow_unsigned.contains(&message_id) {
                Ok(Accepted::UnsignedAllowed)
            } else {
                Err(Refusal::Unsigned { message_id })
            };
        };
        if !signature_matches(&self.key, frame) {
            return Err(Refusal::BadSignature);
        }
        let stream = (fields.link_id, frame.system_id(), frame.component_id());
        let timestamp = fields.timestamp;
        match self.streams.get(&stream) {
            Some(&last) if timestamp <= last => {
                return Err(Refusal::Replayed {
                    link_id: stream.0,
                    system_id: stream.1,
                    component_id: stream.2,
                    timestamp,
                    last,
                });
            }
            Some(_) => {}
            None => {
                let ours = self.clock.current(now);
                if timestamp.saturating_add(NEW_STREAM_WINDOW) < ours {
                    return Err(Refusal::TooOld { timestamp, ours });
                }
                if self.streams.len() >= MAX_STREAMS {
                    return Err(Refusal::TooManyStreams);
                }
            }
        }
        self.streams.insert(stream, timestamp);
        self.clock.observe(timestamp);
        Ok(Accepted::Signed {
            link_id: fields.link_id,
            timestamp,
        })
    }

    /// [`Signing::verify`] at the wall clock's now.
    pub fn verify_now(&mut self, frame: &Frame) -> Result<Accepted, Refusal> {
        self.verify(frame, SystemTime::now())
    }
}

/// What a signing party persists: its key and its last timestamp.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct SigningState {
    /// The key.
    pub key: SigningKey,
    /// The last timestamp used or accepted.
    pub timestamp: u64,
}

/// Why a key or state file cannot be read or written. Never quotes key bytes.
#[derive(Debug, thiserror::Error)]
pub enum SigningFileError {
    /// The file cannot be read.
    #[error("cannot read signing file {}: {source}", path.display())]
    Read {
        /// The file.
        path: PathBuf,
        /// The cause.
        source: std::io::Error,
    },
    /// The file cannot be written.
    #[error("cannot write signing file {}: {source}", path.display())]
    Write {
        /// The file.
        path: PathBuf,
        /// The cause.
        source: std::io::Error,
    },
    /// The file holds a bad key.
    #[error("bad signing key in {}: {source}", path.display())]
    Key {
        /// The file.
        path: PathBuf,
        /// What is wrong with the key.
        source: KeyError,
    },
    /// The state file is not `key = "<64 hex>"` and `timestamp = N`.
    #[error("bad signing state file {}{}: {message}", path.display(), line.map(|l| format!(" line {l}")).unwrap_or_default())]
    Format {
        /// The file.
        path: PathBuf,
        /// 1-based line, when known.
        line: Option<usize>,
        /// What is wrong.
        message: String,
    },
}

fn read_text(path: &Path) -> Result<String, SigningFileError> {
    std::fs::read_to_string(path).map_err(|source| SigningFileError::Read {
        path: path.to_owned(),
        source,
    })
}

impl SigningState {
    /// The state file's text (TOML).
    #[must_use]
    pub fn to_text(&self) -> String {
        format!(
            "# MAVLink 2 signing key and last timestamp (10 us units since 2015-01-01 UTC).\n\
             # Secret: keep this file private.\n\
             key = \"{}\"\n\
             timestamp = {}\n",
            self.key.to_hex(),
            self.timestamp
        )
    }

    /// Parses a state file's text; `path` only names the file in errors.
    pub fn parse(text: &str, path: &Path) -> Result<SigningState, SigningFileError> {
        let format = |line: Option<usize>, message: String| SigningFileError::Format {
            path: path.to_owned(),
            line,
            message,
        };
        let line_of = |offset: usize| text[..offset.min(text.len())].matches('\n').count() + 1;
        // Only the parser's message and position: its full report quotes the line, which may
        // hold the key.
        // Not even the message when it quotes a value (`invalid type: integer `…``): that value
        // may be the key, written without its quotes.
        let table: toml::Table = toml::from_str(text).map_err(|e| {
            let message = if e.message().contains('`') {
                format!("not valid TOML ({STATE_FILE_FORMAT})")
            } else {
                e.message().trim_end().replace('\n', "; ")
            };
            format(e.span().map(|s| line_of(s.start)), message)
        })?;
        let line_of_key = |name: &str| {
            text.lines()
                .position(|l| l.trim_start().starts_with(name))
                .map(|i| i + 1)
        };
        if let Some(unknown) = table
            .keys()
            .find(|k| k.as_str() != "key" && k.as_str() != "timestamp")
        {
            // The name is not quoted: a key glued to its name by a missing `=` would be.
            return Err(format(
                line_of_key(unknown),
                "unknown field (expected `key` and `timestamp`)".to_owned(),
            ));
        }
        let key = match table.get("key") {
            None => return Err(format(None, "missing `key`".to_owned())),
            Some(toml::Value::String(s)) => {
                SigningKey::from_hex(s).map_err(|source| SigningFileError::Key {
                    path: path.to_owned(),
                    source,
                })?
            }
            Some(_) => {
                return Err(format(
                    line_of_key("key"),
                    "`key` must be a quoted string of 64 hex characters".to_owned(),
                ));
            }
        };
        let timestamp = match table.get("timestamp") {
            None => return Err(format(None, "missing `timestamp`".to_owned())),
            Some(toml::Value::Integer(t)) => u64::try_from(*t)
                .ok()
                .filter(|&t| t <= MAX_TIMESTAMP)
                .ok_or_else(|| {
                    format(
                        line_of_key("timestamp"),
                        format!("`timestamp` {t} is outside 0..={MAX_TIMESTAMP}"),
                    )
                })?,
            Some(_) => {
                return Err(format(
                    line_of_key("timestamp"),
                    "`timestamp` must be a whole number".to_owned(),
                ));
            }
        };
        Ok(SigningState { key, timestamp })
    }

    /// Reads a state file.
    pub fn load(path: &Path) -> Result<SigningState, SigningFileError> {
        SigningState::parse(&read_text(path)?, path)
    }

    /// Reads a state file if it exists (`Ok(None)` if it does not).
    pub fn load_if_exists(path: &Path) -> Result<Option<SigningState>, SigningFileError> {
        match std::fs::read_to_string(path) {
            Ok(text) => SigningState::parse(&text, path).map(Some),
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => Ok(None),
            Err(source) => Err(SigningFileError::Read {
                path: path.to_owned(),
                source,
            }),
        }
    }

    /// Writes the state file (owner-only permissions on Unix) through a temporary file beside
    /// it, renamed into place, so a crash leaves the old or the new state, never half of one.
    pub fn save(&self, path: &Path) -> Result<(), SigningFileError> {
        use std::io::Write;
        let write_err = |source| SigningFileError::Write {
            path: path.to_owned(),
            source,
        };
        let mut tmp_name = path.as_os_str().to_owned();
        tmp_name.push(".tmp");
        let tmp = PathBuf::from(tmp_name);
        let mut options = std::fs::OpenOptions::new();
        options.write(true).create(true).truncate(true);
        #[cfg(unix)]
        {
            use std::os::unix::fs::OpenOptionsExt;
            options.mode(0o600);
        }
        let mut file = options.open(&tmp).map_err(write_err)?;
        file.write_all(self.to_text().as_bytes())
            .and_then(|()| file.sync_all())
            .map_err(write_err)?;
        drop(file);
        std::fs::rename(&tmp, path).map_err(write_err)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::dialect::{self as apm, MavMessage};
    use proptest::prelude::*;

    fn at(seconds_since_2015: f64) -> SystemTime {
        UNIX_EPOCH + Duration::from_secs_f64(SIGNING_EPOCH_UNIX_S as f64 + seconds_since_2015)
    }

    /// 2026-11-23, as a fixed "now".
    const T0: f64 = 375_000_000.0;

    fn command_long(sysid: u8, compid: u8, seq: u8) -> Frame {
        let msg = MavMessage::COMMAND_LONG(apm::COMMAND_LONG_DATA {
            param1: 1.0,
            command: apm::MavCmd::MAV_CMD_COMPONENT_ARM_DISARM,
            target_system: 1,
            target_component: 1,
            ..Default::default()
        });
        Frame::encode_v2(
            crate::SystemId(sysid),
            crate::ComponentId(compid),
            seq,
            &msg,
        )
    }

    fn key() -> SigningKey {
        SigningKey::from_passphrase("correct horse")
    }

    #[test]
    fn timestamp_epoch_and_units() {
        assert_eq!(timestamp_at(at(0.0)), 0);
        assert_eq!(timestamp_at(UNIX_EPOCH), 0);
        assert_eq!(timestamp_at(at(1.0)), TIMESTAMP_UNITS_PER_S);
        assert_eq!(timestamp_at(at(0.00001)), 1);
        assert_eq!(
            timestamp_at(UNIX_EPOCH + Duration::from_secs(u64::from(u32::MAX) * 4)),
            MAX_TIMESTAMP
        );
    }

    #[test]
    fn key_debug_display_and_errors_hide_bytes() {
        let k = SigningKey::from_bytes([0xab; 32]);
        for text in [format!("{k:?}"), format!("{k}")] {
            assert!(!text.to_lowercase().contains("ab"), "{text}");
        }
        assert_eq!(SigningKey::from_hex(&k.to_hex()).unwrap(), k);
        assert_eq!(
            SigningKey::from_hex(&format!("  {}\n", k.to_hex().to_uppercase())).unwrap(),
            k
        );
        assert_eq!(
            SigningKey::from_hex("abcd"),
            Err(KeyError::WrongLength { chars: 4 })
        );
        let mut bad = k.to_hex();
        bad.replace_range(10..11, "g");
        let err = SigningKey::from_hex(&bad).unwrap_err();
        assert_eq!(err, KeyError::NotHex { position: 11 });
        assert!(!err.to_string().contains("abab"));
        // Multi-byte characters count as characters, not bytes, and do not panic.
        assert!(matches!(
            SigningKey::from_hex(&"é".repeat(64)),
            Err(KeyError::NotHex { position: 1 })
        ));
        assert!(SigningKey::from_bytes([0; 32]).is_zero());
        assert!(!k.is_zero());
    }

    #[test]
    fn passphrase_key_is_sha256_of_the_text() {
        // SHA-256("abc"), FIPS 180-2 appendix B.1.
        assert_eq!(
            SigningKey::from_passphrase("abc").to_hex(),
            "ba7816bf8f01cfea414140de5dae2223b00361a396177a9cb410ff61f20015ad"
        );
    }

    #[test]
    fn signed_frame_layout() {
        let f = command_long(255, 190, 3);
        let signed = sign_frame(&key(), &f, 7, 0x0102_0304_0506).unwrap();
        assert_eq!(signed.len(), f.len() + SIGNATURE_LEN);
        assert!(signed.is_signed());
        assert_eq!(signed.payload(), f.payload());
        // The CRC covers the header with the signed flag, so it changed; the frame re-parses.
        assert_ne!(signed.crc(), f.crc());
        let reparsed = Frame::from_bytes(signed.bytes().clone()).unwrap();
        assert!(reparsed.is_verified());
        let sig = signed.signature().unwrap();
        assert_eq!(&sig[..7], &[7, 6, 5, 4, 3, 2, 1]);
        let fields = SignatureFields::of(&signed).unwrap();
        assert_eq!((fields.link_id, fields.timestamp), (7, 0x0102_0304_0506));
        assert!(signature_matches(&key(), &signed));
        assert!(!signature_matches(
            &SigningKey::from_passphrase("x"),
            &signed
        ));
        // Re-signing a signed frame replaces the trailer only.
        let again = sign_frame(&key(), &signed, 8, 99).unwrap();
        assert_eq!(again.len(), signed.len());
        assert_eq!(again.crc(), signed.crc());
        assert!(signature_matches(&key(), &again));
        assert_eq!(
            sign_frame(&key(), &f, 0, MAX_TIMESTAMP + 1),
            Err(SignError::TimestampExhausted)
        );
    }

    #[test]
    fn v1_cannot_be_signed_and_counts_as_unsigned() {
        let hb = crate::gcs_heartbeat();
        let v1 = Frame::encode_v1(crate::SystemId(255), crate::ComponentId(190), 0, &hb).unwrap();
        let mut s = Signing::new(key(), 0, 0);
        assert_eq!(s.sign(&v1, at(T0)), Err(SignError::NotV2));
        assert_eq!(
            s.verify(&v1, at(T0)),
            Err(Refusal::Unsigned { message_id: 0 })
        );
    }

    #[test]
    fn unknown_ids_are_signed_with_the_recovered_crc_extra() {
        let f = Frame::encode_raw_v2(
            crate::SystemId(1),
            crate::ComponentId(1),
            0,
            60_000,
            &[1, 2, 3],
            77,
        )
        .unwrap();
        assert!(!f.is_verified());
        let signed = sign_frame(&key(), &f, 0, 5).unwrap();
        let expected = frame_crc(&signed.as_bytes()[1..HEADER_LEN_V2 + 3], 77);
        assert_eq!(signed.crc(), expected);
        // A CRC no CRC_EXTRA explains (the last step is one-to-one, so most do not).
        let mut b = f.as_bytes().to_vec();
        let crcs: std::collections::HashSet<u16> = (0..=255u8)
            .map(|x| frame_crc(&b[1..HEADER_LEN_V2 + 3], x))
            .collect();
        assert_eq!(crcs.len(), 256, "CRC_EXTRA recovery must be unambiguous");
        let free = (0..=u16::MAX).find(|c| !crcs.contains(c)).unwrap();
        let n = b.len();
        b[n - 2..].copy_from_slice(&free.to_le_bytes());
        let broken = Frame::from_bytes(Bytes::from(b)).unwrap();
        assert_eq!(
            sign_frame(&key(), &broken, 0, 5),
            Err(SignError::UnknownCrcExtra(60_000))
        );
    }

    #[test]
    fn timestamps_never_go_back_and_follow_the_wall_clock() {
        let mut c = TimestampSource::new(0);
        let a = c.next(at(T0)).unwrap();
        assert_eq!(a, timestamp_at(at(T0)));
        // Same instant, or the wall clock stepping back: still +1.
        assert_eq!(c.next(at(T0)).unwrap(), a + 1);
        assert_eq!(c.next(at(T0 - 3600.0)).unwrap(), a + 2);
        // Ten minutes later: the wall clock again.
        assert_eq!(
            c.next(at(T0 + 600.0)).unwrap(),
            timestamp_at(at(T0 + 600.0))
        );
        // A peer's higher timestamp raises ours.
        let high = timestamp_at(at(T0 + 1000.0));
        c.observe(high);
        assert_eq!(c.next(at(T0 + 601.0)).unwrap(), high + 1);
        // A persisted timestamp ahead of the clock is honoured.
        let mut p = TimestampSource::new(high);
        assert_eq!(p.next(at(T0)).unwrap(), high + 1);
        let mut end = TimestampSource::new(MAX_TIMESTAMP);
        assert_eq!(end.next(at(T0)), Err(SignError::TimestampExhausted));
    }

    #[test]
    fn replay_and_streams() {
        let mut gcs = Signing::new(key(), 1, 0);
        let mut vehicle = Signing::new(key(), 0, 0);
        let now = at(T0);
        let f1 = gcs.sign(&command_long(255, 190, 0), now).unwrap();
        let f2 = gcs.sign(&command_long(255, 190, 1), now).unwrap();
        assert!(matches!(
            vehicle.verify(&f1, now),
            Ok(Accepted::Signed { link_id: 1, .. })
        ));
        assert!(matches!(
            vehicle.verify(&f1, now),
            Err(Refusal::Replayed {
                link_id: 1,
                system_id: 255,
                component_id: 190,
                ..
            })
        ));
        assert!(vehicle.verify(&f2, now).is_ok());
        // f1 after f2: older than the stream's last.
        assert!(matches!(
            vehicle.verify(&f1, now),
            Err(Refusal::Replayed { .. })
        ));
        // The same timestamp on another (link, sys, comp) is another stream.
        let other_comp = sign_frame(
            &key(),
            &command_long(255, 191, 0),
            1,
            SignatureFields::of(&f1).unwrap().timestamp,
        )
        .unwrap();
        assert!(vehicle.verify(&other_comp, now).is_ok());
        let other_link = sign_frame(
            &key(),
            &command_long(255, 190, 0),
            2,
            SignatureFields::of(&f1).unwrap().timestamp,
        )
        .unwrap();
        assert!(vehicle.verify(&other_link, now).is_ok());
        // Accepting raised the vehicle's own timestamp above what it saw.
        let seen = SignatureFields::of(&f2).unwrap().timestamp;
        let reply = vehicle.sign(&command_long(1, 1, 0), now).unwrap();
        assert!(SignatureFields::of(&reply).unwrap().timestamp > seen);
    }

    #[test]
    fn new_stream_older_than_a_minute_is_refused() {
        let mut vehicle = Signing::new(key(), 0, 0);
        let now = at(T0);
        let ours = timestamp_at(now);
        let old = sign_frame(
            &key(),
            &command_long(255, 190, 0),
            0,
            ours - NEW_STREAM_WINDOW - 1,
        )
        .unwrap();
        assert_eq!(
            vehicle.verify(&old, now),
            Err(Refusal::TooOld {
                timestamp: ours - NEW_STREAM_WINDOW - 1,
                ours
            })
        );
        let edge = sign_frame(
            &key(),
            &command_long(255, 190, 0),
            0,
            ours - NEW_STREAM_WINDOW,
        )
        .unwrap();
        assert!(vehicle.verify(&edge, now).is_ok());
    }

    #[test]
    fn unsigned_allow_list() {
        let mut vehicle = Signing::new(key(), 0, 0);
        let now = at(T0);
        let radio = Frame::encode_v2(
            crate::SystemId(51),
            crate::ComponentId(68),
            0,
            &MavMessage::RADIO_STATUS(apm::RADIO_STATUS_DATA::default()),
        );
        assert_eq!(vehicle.verify(&radio, now), Ok(Accepted::UnsignedAllowed));
        assert_eq!(
            vehicle.verify(&command_long(255, 190, 0), now),
            Err(Refusal::Unsigned { message_id: 76 })
        );
        let mut strict = Signing::new(key(), 0, 0).with_allow_unsigned(&[]);
        assert!(strict.verify(&radio, now).is_err());
    }

    #[test]
    fn idle_and_outage_cause_no_refusal() {
        // The sender signs at T0, then stays silent for 10 minutes, then sends across a 90 s
        // outage; the receiver forgets its streams in between (a restart). Every frame passes.
        let mut gcs = Signing::new(key(), 1, 0);
        let mut vehicle = Signing::new(key(), 0, 0);
        let mut t = T0;
        for step in [0.0, 600.0, 90.0, 0.001] {
            t += step;
            let f = gcs.sign(&command_long(255, 190, 0), at(t)).unwrap();
            assert!(vehicle.verify(&f, at(t)).is_ok(), "after {step} s");
            let mut restarted = Signing::new(key(), 0, vehicle.state(at(t)).timestamp);
            let g = gcs.sign(&command_long(255, 190, 1), at(t)).unwrap();
            assert!(
                restarted.verify(&g, at(t)).is_ok(),
                "restarted, after {step} s"
            );
            let reply = vehicle.sign(&command_long(1, 1, 0), at(t)).unwrap();
            assert!(gcs.verify(&reply, at(t)).is_ok());
        }
        // What a +1-per-frame counter (pymavlink's) would send after the 10-minute idle is
        // refused by a receiver that does not know the stream yet: why the source follows
        // the wall clock.
        let counter = timestamp_at(at(T0)) + 2;
        let stale = sign_frame(&key(), &command_long(255, 190, 0), 9, counter).unwrap();
        assert!(matches!(
            Signing::new(key(), 0, 0).verify(&stale, at(T0 + 600.0)),
            Err(Refusal::TooOld { .. })
        ));
    }

    #[test]
    fn refused_frames_change_nothing() {
        let mut vehicle = Signing::new(key(), 0, 0);
        let now = at(T0);
        let far = timestamp_at(at(T0 + 10_000.0));
        let wrong = sign_frame(
            &SigningKey::from_passphrase("wrong"),
            &command_long(255, 190, 0),
            0,
            far,
        )
        .unwrap();
        assert_eq!(vehicle.verify(&wrong, now), Err(Refusal::BadSignature));
        assert_eq!(vehicle.clock().last(), 0);
        // The same stream signed right, with a lower timestamp, is still a new stream.
        let right = sign_frame(&key(), &command_long(255, 190, 0), 0, timestamp_at(now)).unwrap();
        assert!(vehicle.verify(&right, now).is_ok());
    }

    #[test]
    fn state_file_round_trip_and_errors() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("signing.toml");
        assert!(SigningState::load_if_exists(&path).unwrap().is_none());
        let state = SigningState {
            key: key(),
            timestamp: 123_456_789,
        };
        state.save(&path).unwrap();
        assert_eq!(SigningState::load(&path).unwrap(), state);
        assert_eq!(
            SigningState::load_if_exists(&path).unwrap(),
            Some(state.clone())
        );
        #[cfg(unix)]
        {
            use std::os::unix::fs::PermissionsExt;
            let mode = std::fs::metadata(&path).unwrap().permissions().mode();
            assert_eq!(mode & 0o777, 0o600);
        }
        let hex = key().to_hex();
        let cases: [(String, &str); 8] = [
            (String::new(), "missing `key`"),
            (format!("key = \"{hex}\"\n"), "missing `timestamp`"),
            (format!("key = \"{hex}\"\ntimestamp = -1\n"), "line 2"),
            (
                format!("key = \"{hex}\"\ntimestamp = 1.5\n"),
                "whole number",
            ),
            (
                format!("key = \"{hex}\"\ntimestamp = 1\nextra = 2\n"),
                "line 3: unknown field",
            ),
            (
                format!("key = \"{}\"\ntimestamp = 1\n", &hex[..60]),
                "got 60",
            ),
            (format!("key = {hex}\ntimestamp = 1\n"), "line 1"),
            ("key = [1, 2]\ntimestamp = 1\n".to_owned(), "quoted string"),
        ];
        for (text, want) in cases {
            let err = SigningState::parse(&text, &path).unwrap_err().to_string();
            assert!(err.contains(want), "{text:?}: {err}");
            assert!(err.contains("signing.toml"), "{err}");
            assert!(!err.contains(&hex[..16]), "key bytes in error: {err}");
        }
        let missing = dir.path().join("nope");
        assert!(matches!(
            SigningState::load(&missing),
            Err(SigningFileError::Read { .. })
        ));
        // Key files.
        let key_file = dir.path().join("key");
        std::fs::write(&key_file, format!("{hex}\n")).unwrap();
        assert_eq!(SigningKey::from_key_file(&key_file).unwrap(), key());
        std::fs::write(&key_file, "not a key").unwrap();
        let err = SigningKey::from_key_file(&key_file)
            .unwrap_err()
            .to_string();
        assert!(err.contains("64 hex characters, got 9"), "{err}");
        assert!(!err.contains("not a key"), "{err}");
        // Saving where no file can be written is an error, not a panic.
        assert!(matches!(
            state.save(&dir.path().join("no/such/dir/state")),
            Err(SigningFileError::Write { .. })
        ));
    }

    fn any_frame() -> impl Strategy<Value = Frame> {
        let ids = crate::frame::known_message_ids();
        (
            proptest::sample::select(ids),
            any::<u8>(),
            any::<u8>(),
            any::<u8>(),
            proptest::collection::vec(any::<u8>(), 1..=255),
        )
            .prop_map(|(id, sys, comp, seq, payload)| {
                Frame::encode_raw_v2(
                    crate::SystemId(sys),
                    crate::ComponentId(comp),
                    seq,
                    id,
                    &payload,
                    crc_extra(id).unwrap_or_default(),
                )
                .unwrap_or_else(|e| unreachable!("{e}"))
            })
    }

    proptest! {
        #![proptest_config(ProptestConfig { cases: 256, ..ProptestConfig::default() })]

        #[test]
        fn sign_then_verify_round_trip(
            frame in any_frame(),
            link in any::<u8>(),
            secs in 0.0f64..2.0e9,
            pass in "[ -~]{0,40}",
        ) {
            let k = SigningKey::from_passphrase(&pass);
            let mut tx = Signing::new(k.clone(), link, 0);
            let mut rx = Signing::new(k, 0, 0);
            let signed = tx.sign(&frame, at(secs)).unwrap();
            let parsed = Frame::from_bytes(signed.bytes().clone()).unwrap();
            prop_assert_eq!(parsed.payload(), frame.payload());
            prop_assert!(rx.verify(&parsed, at(secs)).is_ok());
            let replayed = matches!(rx.verify(&parsed, at(secs)), Err(Refusal::Replayed { .. }));
            prop_assert!(replayed);
        }

        #[test]
        fn any_flipped_byte_fails(
            frame in any_frame(),
            index in any::<proptest::sample::Index>(),
            bit in 0u8..8,
        ) {
            let now = at(T0);
            let signed = Signing::new(key(), 3, 0).sign(&frame, now).unwrap();
            let mut b = signed.as_bytes().to_vec();
            let i = index.index(b.len());
            b[i] ^= 1 << bit;
            // Either the framing refuses it, or the signature check does.
            if let Ok(f) = Frame::from_bytes(Bytes::from(b)) {
                let verdict = Signing::new(key(), 0, 0).verify(&f, now);
                prop_assert!(verdict.is_err(), "byte {} bit {} accepted", i, bit);
            }
        }
    }
}
