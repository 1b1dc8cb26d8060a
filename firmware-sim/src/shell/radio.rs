//! The radio between the twin and its links: the impairment the server is configured with
//! ([`Impairment`]) and the simulated radio the vehicle loop passes every frame through
//! ([`Radio`]: seeded loss, a fixed delay, a SiK radio's buffer). `serve` configures it and
//! `vehicle_loop` runs it, so neither imports the other for it.

use tokio::time::Instant;
use vtol_link::{Frame, LinkId};

/// A lossy, slow radio between the twin and its links, in each direction.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Impairment {
    /// Fraction of frames dropped, 0..1.
    pub loss: f64,
    /// Delay of every frame.
    pub latency: std::time::Duration,
    /// Seed of the loss draws.
    pub seed: u64,
    /// A SiK radio at this baud on each link, reporting RADIO_STATUS ([`crate::shell::sik`]).
    pub radio_baud: Option<u32>,
}

impl Default for Impairment {
    fn default() -> Self {
        Self {
            loss: 0.0,
            latency: std::time::Duration::ZERO,
            seed: 1,
            radio_baud: None,
        }
    }
}

/// Which way a frame goes through the simulated radio.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum Way {
    /// From a link to the twin.
    In,
    /// From the twin to a link.
    Out,
}

/// The simulated radio: seeded loss, then a fixed delay (a FIFO, since every frame waits the
/// same time).
pub(crate) struct Radio {
    imp: Impairment,
    rng: rand_chacha::ChaCha8Rng,
    delayed: std::collections::VecDeque<(Instant, Way, LinkId, Frame, bool)>,
    /// A SiK radio's buffer and reports, with `--radio-baud`.
    pub(crate) sik: Option<crate::shell::sik::Sik>,
}

impl Radio {
    pub(crate) fn new(imp: Impairment) -> Self {
        use rand::SeedableRng as _;
        Self {
            imp,
            rng: rand_chacha::ChaCha8Rng::seed_from_u64(imp.seed),
            delayed: std::collections::VecDeque::new(),
            sik: imp.radio_baud.map(crate::shell::sik::Sik::new),
        }
    }

    /// The frame if it goes through now; `None` if lost or delayed (`telemetry` travels with a
    /// delayed frame).
    pub(crate) fn pass(
        &mut self,
        way: Way,
        id: LinkId,
        frame: Frame,
        telemetry: bool,
    ) -> Option<Frame> {
        use rand::Rng as _;
        if self.imp.loss > 0.0 && self.rng.random_bool(self.imp.loss) {
            return None;
        }
        if self.imp.latency.is_zero() {
            return Some(frame);
        }
        let due = Instant::now() + self.imp.latency;
        self.delayed.push_back((due, way, id, frame, telemetry));
        None
    }

    pub(crate) async fn next_due(&self) {
        match self.delayed.front() {
            Some((due, ..)) => tokio::time::sleep_until(*due).await,
            None => std::future::pending().await,
        }
    }

    pub(crate) fn pop_due(&mut self, now: Instant) -> Option<(Way, LinkId, Frame, bool)> {
        if self.delayed.front()?.0 > now {
            return None;
        }
        self.delayed
            .pop_front()
            .map(|(_, w, id, f, t)| (w, id, f, t))
    }
}
