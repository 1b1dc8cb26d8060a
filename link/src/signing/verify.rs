//! Verifying incoming frames per stream, and signing outgoing ones.

use std::collections::HashMap;
use std::time::SystemTime;

use super::{
    MAX_STREAMS, NEW_STREAM_WINDOW, SignError, SignatureFields, SigningKey, SigningState,
    TimestampSource, sign_frame, signature_matches,
};
use crate::frame::Frame;

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
            allow_unsigned: vec![crate::protocol::id::RADIO_STATUS],
        }
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
