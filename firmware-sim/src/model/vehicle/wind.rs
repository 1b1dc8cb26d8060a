//! The wind the airframe flies in: a steady wind plus a seeded gust.

use nalgebra::Vector3;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rand_distr::StandardNormal;

/// Correlation time of the gust model (first-order Gauss–Markov per axis), s.
pub const GUST_TIME_CONSTANT_S: f64 = 1.0;
/// Seed offset of the wind RNG, so that turning wind on leaves the sensor noise unchanged.
const WIND_SEED_SALT: u64 = 0x5749_4e44;

/// Steady wind plus a seeded first-order Gauss–Markov gust (inertial frame).
#[derive(Debug, Clone)]
pub(super) struct Wind {
    pub(super) mean_m_s: Vector3<f64>,
    pub(super) gust_sigma_m_s: f64,
    pub(super) gust_m_s: Vector3<f64>,
    keep: f64,
    rng: ChaCha8Rng,
}

impl Wind {
    pub(super) fn new(seed: u64, dt_s: f64) -> Self {
        Self {
            mean_m_s: Vector3::zeros(),
            gust_sigma_m_s: 0.0,
            gust_m_s: Vector3::zeros(),
            keep: (-dt_s / GUST_TIME_CONSTANT_S).exp(),
            rng: ChaCha8Rng::seed_from_u64(seed ^ WIND_SEED_SALT),
        }
    }

    /// Advances the gust one physics step and returns the wind, m/s, or `None` when the wind
    /// perturbation is off (the paper's drag-free model).
    pub(super) fn step(&mut self) -> Option<Vector3<f64>> {
        if self.gust_sigma_m_s == 0.0 && self.mean_m_s == Vector3::zeros() {
            return None;
        }
        if self.gust_sigma_m_s > 0.0 {
            let drive = self.gust_sigma_m_s * (1.0 - self.keep * self.keep).sqrt();
            for i in 0..3 {
                let n: f64 = self.rng.sample(StandardNormal);
                self.gust_m_s[i] = self.keep * self.gust_m_s[i] + drive * n;
            }
        }
        Some(self.mean_m_s + self.gust_m_s)
    }
}
