//! A SiK telemetry radio between the twin and each of its links (`serve --radio-baud`): its
//! transmit buffer fills with what the twin sends faster than the radio's rate and drains at
//! that rate (a baud of 8N1 serial: a tenth of it in bytes per second); a frame that does not
//! fit is lost; and once a second the radio tells the ground how full it is, in RADIO_STATUS
//! from system 51, component 68 (`txbuf`: percent of the buffer free), as SiK firmware does, so
//! that a ground station can slow the vehicle's streams down before the radio loses frames.

use std::collections::HashMap;
use std::time::Duration;

use mavlink::dialects::ardupilotmega as apm;
use tokio::time::Instant;
use vtol_link::{ComponentId, Frame, LinkId, SystemId};

/// The radio's transmit buffer.
pub const BUFFER_BYTES: f64 = 2048.0;
/// How often the radio reports.
pub const REPORT_PERIOD: Duration = Duration::from_secs(1);
/// SiK's own identity on the link ('3', 'D').
pub const SIK_ID: (SystemId, ComponentId) = (SystemId(51), ComponentId(68));

/// The radios, one a link.
#[derive(Debug)]
pub(crate) struct Sik {
    bytes_per_s: f64,
    /// Per link: bytes in the buffer, as of when.
    buffers: HashMap<LinkId, (f64, Instant)>,
    next_report: Option<Instant>,
    seq: u8,
}

impl Sik {
    /// Radios at `baud` (bits per second on the serial side).
    pub(crate) fn new(baud: u32) -> Self {
        Self {
            bytes_per_s: f64::from(baud) / 10.0,
            buffers: HashMap::new(),
            next_report: None,
            seq: 0,
        }
    }

    /// The buffer of link `id` at `now`, drained since it was last looked at.
    fn level(&mut self, id: LinkId, now: Instant) -> &mut f64 {
        let rate = self.bytes_per_s;
        let (level, at) = self.buffers.entry(id).or_insert((0.0, now));
        let drained = now.saturating_duration_since(*at).as_secs_f64() * rate;
        *level = (*level - drained).max(0.0);
        *at = now;
        level
    }

    /// Whether a frame of `len` bytes for link `id` fits in its buffer at `now` (and takes its
    /// place there); a frame that does not is lost.
    pub(crate) fn admit(&mut self, id: LinkId, len: usize, now: Instant) -> bool {
        let level = self.level(id, now);
        if *level + len as f64 > BUFFER_BYTES {
            return false;
        }
        *level += len as f64;
        true
    }

    /// Once a [`REPORT_PERIOD`], a RADIO_STATUS for each of `links`.
    pub(crate) fn reports(
        &mut self,
        now: Instant,
        links: impl Iterator<Item = LinkId>,
    ) -> Vec<(LinkId, Frame)> {
        let due = *self.next_report.get_or_insert(now);
        if now < due {
            return Vec::new();
        }
        self.next_report = Some(now + REPORT_PERIOD);
        let mut out = Vec::new();
        for id in links {
            let level = *self.level(id, now);
            let free = 100.0 * (1.0 - level / BUFFER_BYTES);
            let msg = apm::MavMessage::RADIO_STATUS(apm::RADIO_STATUS_DATA {
                rxerrors: 0,
                fixed: 0,
                rssi: 200,
                remrssi: 200,
                txbuf: free.round().clamp(0.0, 100.0) as u8,
                noise: 40,
                remnoise: 40,
            });
            out.push((id, Frame::encode_v2(SIK_ID.0, SIK_ID.1, self.seq, &msg)));
            self.seq = self.seq.wrapping_add(1);
        }
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn txbuf(f: &Frame) -> u8 {
        match f.decode() {
            Ok(apm::MavMessage::RADIO_STATUS(r)) => r.txbuf,
            other => panic!("{other:?}"),
        }
    }

    #[tokio::test(start_paused = true)]
    async fn the_buffer_fills_past_the_rate_drains_at_it_and_is_reported() {
        let mut sik = Sik::new(57_600);
        let t0 = Instant::now();
        let link = LinkId(1);
        // 2048 bytes fit, the next frame does not.
        for _ in 0..32 {
            assert!(sik.admit(link, 64, t0));
        }
        assert!(!sik.admit(link, 64, t0));
        let r = sik.reports(t0, [link].into_iter());
        assert_eq!(r.len(), 1);
        assert_eq!(r[0].1.system_id(), 51);
        assert_eq!(txbuf(&r[0].1), 0);
        // Not again before a second.
        assert!(
            sik.reports(t0 + Duration::from_millis(500), [link].into_iter())
                .is_empty()
        );
        // 5760 bytes a second: a quarter second drains 1440 of them.
        let later = t0 + Duration::from_millis(1000);
        assert!(sik.admit(link, 64, t0 + Duration::from_millis(250)));
        let r = sik.reports(later, [link].into_iter());
        assert_eq!(txbuf(&r[0].1), 100);
    }
}
