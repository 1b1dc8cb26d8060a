//! STATUSTEXT reassembly. MAVLink 2 carries a text longer than one STATUSTEXT (50 characters) in
//! chunks that share a non-zero `id`, numbered by `chunk_seq` 0, 1, …; the last chunk is shorter
//! than 50 characters (empty when the text fills its chunks exactly). A text with `id` 0 stands
//! alone. This is how ArduPilot and the twin send them and how MAVProxy reads them; a vehicle's
//! refusal reason is often longer than one message.

use crate::dialect as apm;

/// Characters of text in one STATUSTEXT.
const CHUNK_CHARS: usize = 50;

/// Texts still waiting for chunks; a few at once at most.
const MAX_PENDING: usize = 8;

/// Puts chunked STATUSTEXTs back together (one sender's).
#[derive(Debug, Clone, Default)]
pub struct TextAssembler {
    /// (id, chunks received as (chunk_seq, text)), oldest first.
    pending: Vec<(u16, Vec<(u8, String)>)>,
}

impl TextAssembler {
    /// Takes one STATUSTEXT; returns the whole text when this message completes one.
    pub fn push(&mut self, t: &apm::STATUSTEXT_DATA) -> Option<String> {
        let text = t
            .text
            .to_str()
            .unwrap_or("")
            .trim_end_matches('\0')
            .to_owned();
        if t.id == 0 {
            return Some(text);
        }
        let last = text.len() < CHUNK_CHARS;
        let k = match self.pending.iter().position(|(id, _)| *id == t.id) {
            Some(k) => k,
            None => {
                if self.pending.len() == MAX_PENDING {
                    // A text whose last chunk was lost: give up the oldest.
                    self.pending.remove(0);
                }
                self.pending.push((t.id, Vec::new()));
                self.pending.len() - 1
            }
        };
        let chunks = &mut self.pending[k].1;
        if !chunks.iter().any(|(seq, _)| *seq == t.chunk_seq) {
            chunks.push((t.chunk_seq, text));
        }
        if !last {
            return None;
        }
        let (_, mut chunks) = self.pending.remove(k);
        chunks.sort_by_key(|(seq, _)| *seq);
        // A lost middle chunk shows as "...", as MAVProxy shows it.
        let mut out = String::new();
        let mut next = 0u8;
        for (seq, part) in chunks {
            if seq != next {
                out.push_str(" ... ");
            }
            out.push_str(&part);
            next = seq.wrapping_add(1);
        }
        Some(out)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use mavlink::types::CharArray;

    fn st(text: &str, id: u16, chunk_seq: u8) -> apm::STATUSTEXT_DATA {
        apm::STATUSTEXT_DATA {
            severity: apm::MavSeverity::MAV_SEVERITY_CRITICAL,
            text: CharArray::from(text),
            id,
            chunk_seq,
        }
    }

    #[test]
    fn whole_texts_and_chunks() {
        let mut a = TextAssembler::default();
        assert_eq!(a.push(&st("short", 0, 0)).as_deref(), Some("short"));
        let first = "PreArm: pre-arm check failed: gyro calibration in ";
        assert_eq!(first.len(), 50);
        assert_eq!(a.push(&st(first, 7, 0)), None);
        // Another text's chunk in between does not mix in.
        assert_eq!(a.push(&st("x".repeat(50).as_str(), 8, 0)), None);
        assert_eq!(
            a.push(&st("progress", 7, 1)).as_deref(),
            Some("PreArm: pre-arm check failed: gyro calibration in progress")
        );
        // Exactly 100 characters: two full chunks and an empty one.
        let y = "y".repeat(50);
        assert_eq!(a.push(&st(&y, 9, 0)), None);
        assert_eq!(a.push(&st(&y, 9, 1)), None);
        assert_eq!(a.push(&st("", 9, 2)).map(|s| s.len()), Some(100));
        // A lost chunk is marked; a repeated one counted once.
        assert_eq!(a.push(&st(&y, 10, 0)), None);
        assert_eq!(a.push(&st(&y, 10, 0)), None);
        assert_eq!(
            a.push(&st("end", 10, 2)).as_deref(),
            Some(format!("{y} ... end").as_str())
        );
    }
}
