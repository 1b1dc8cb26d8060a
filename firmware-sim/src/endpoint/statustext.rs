//! STATUSTEXT out, long texts in chunks as MAVLink 2 allows (common.xml, STATUSTEXT `id` and
//! `chunk_seq`), the way ArduPilot sends them.
//!
//! A text of up to 50 bytes is one message with `id` 0. A longer one is cut into 50-byte chunks
//! that share a non-zero `id` (counting up, skipping 0) and carry `chunk_seq` 0, 1, 2…; the
//! last chunk is shorter than 50 bytes, which is how a receiver knows the text is complete
//! (MAVProxy's reassembly), so a text whose length is a multiple of 50 ends with an empty chunk.
//! Texts are ASCII (anything else becomes `?`, so that no character is split between chunks)
//! and at most [`MAX_TEXT_BYTES`] long.

use mavlink::dialects::ardupilotmega as apm;
use mavlink::types::CharArray;

use super::{Endpoint, LinkKey};

/// Bytes of text per STATUSTEXT.
pub const CHUNK_BYTES: usize = 50;

/// Longest text sent, bytes (five chunks); longer texts are cut.
pub const MAX_TEXT_BYTES: usize = 5 * CHUNK_BYTES - 1;

/// The STATUSTEXT messages that carry `text` (`id` is used only when it takes several).
#[must_use]
pub fn chunks(severity: apm::MavSeverity, text: &str, id: u16) -> Vec<apm::MavMessage> {
    let ascii: String = text
        .chars()
        .map(|c| if c.is_ascii() && c != '\0' { c } else { '?' })
        .take(MAX_TEXT_BYTES)
        .collect();
    let msg = |part: &str, id: u16, chunk_seq: u8| {
        apm::MavMessage::STATUSTEXT(apm::STATUSTEXT_DATA {
            severity,
            text: CharArray::from(part),
            id,
            chunk_seq,
        })
    };
    if ascii.len() <= CHUNK_BYTES {
        return vec![msg(&ascii, 0, 0)];
    }
    // len/50 full chunks, then the (possibly empty) rest.
    (0..=ascii.len() / CHUNK_BYTES)
        .map(|k| {
            let start = k * CHUNK_BYTES;
            let end = (start + CHUNK_BYTES).min(ascii.len());
            msg(&ascii[start..end], id, k as u8)
        })
        .collect()
}

impl Endpoint {
    /// The id of the next multi-chunk text (1, 2, … 65535, 1, …).
    fn next_text_id(&mut self) -> u16 {
        self.text_id = self.text_id.checked_add(1).unwrap_or(1);
        self.text_id
    }

    fn text_messages(&mut self, severity: apm::MavSeverity, text: &str) -> Vec<apm::MavMessage> {
        let id = if text.len() > CHUNK_BYTES {
            self.next_text_id()
        } else {
            0
        };
        chunks(severity, text, id)
    }

    /// A STATUSTEXT (in chunks if long) to one link: the answer to what that link asked.
    pub(super) fn say(&mut self, link: LinkKey, severity: apm::MavSeverity, text: &str) {
        tracing::debug!(target: "firmware_sim::endpoint", "{text}");
        for m in self.text_messages(severity, text) {
            self.send(link, &m);
        }
    }

    /// A STATUSTEXT (in chunks if long) on every link: events concern every GCS.
    pub(super) fn announce(&mut self, severity: apm::MavSeverity, text: &str) {
        tracing::info!(target: "firmware_sim::endpoint", "{text}");
        for m in self.text_messages(severity, text) {
            self.broadcast(&m);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn parts(msgs: &[apm::MavMessage]) -> Vec<(String, u16, u8)> {
        msgs.iter()
            .map(|m| match m {
                apm::MavMessage::STATUSTEXT(s) => {
                    (s.text.to_str().unwrap_or("").to_owned(), s.id, s.chunk_seq)
                }
                other => panic!("{other:?}"),
            })
            .collect()
    }

    #[test]
    fn short_text_is_one_message_with_id_zero() {
        let sev = apm::MavSeverity::MAV_SEVERITY_INFO;
        assert_eq!(
            parts(&chunks(sev, "hello", 7)),
            vec![("hello".into(), 0, 0)]
        );
        let fifty = "x".repeat(50);
        assert_eq!(parts(&chunks(sev, &fifty, 7)), vec![(fifty, 0, 0)]);
    }

    #[test]
    fn long_text_is_chunked_and_reassembles() {
        let sev = apm::MavSeverity::MAV_SEVERITY_WARNING;
        let text = "Reposition refused: 150.0 m from home, beyond NAV_RADIUS_MAX 100 m";
        assert!(text.len() > 60);
        let p = parts(&chunks(sev, text, 9));
        assert_eq!(p.len(), 2);
        assert_eq!((p[0].1, p[0].2, p[1].1, p[1].2), (9, 0, 9, 1));
        assert_eq!(p[0].0.len(), 50);
        assert_eq!(format!("{}{}", p[0].0, p[1].0), text);
        // A multiple of 50 ends with an empty chunk, so the receiver knows it is complete.
        let hundred = "y".repeat(100);
        let p = parts(&chunks(sev, &hundred, 3));
        assert_eq!(p.len(), 3);
        assert_eq!(p[2].0, "");
        // Cut at the cap; non-ASCII never splits.
        let long = "é".repeat(400);
        let p = parts(&chunks(sev, &long, 1));
        let joined: String = p.iter().map(|x| x.0.as_str()).collect();
        assert_eq!(joined, "?".repeat(MAX_TEXT_BYTES));
    }
}
