//! The prototype's embedded hardware as the firmware sees it (`PHYSICS.md` §0, Section V of the
//! paper): three ADXRS150 rate gyros, one two-axis ADXL203 accelerometer, a 12-bit ADC between
//! them and the firmware, the RC receiver, and an external position sensor (motion capture) that
//! the altitude and position modes need but the prototype did not have. Motion-capture rigs
//! measure pose, so that sensor also reports a heading, with its own noise and the same latency.
//!
//! Frames: gyros and accelerometer measure in the body frame B (x_B, y_B, z_B; the accelerometer
//! has x_B and y_B only); the position sensor measures in the inertial frame I (z up). Every
//! random draw comes from one seeded [`ChaCha8Rng`]; `ideal` turns off noise, bias and
//! quantisation (full-scale saturation and the position sensor's latency stay: they are not
//! noise). Sensors are sampled once per control tick.

use nalgebra::Vector3;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rand_distr::StandardNormal;

use crate::model::signals::PilotInput;

/// ADXRS150 full scale, °/s (the output saturates beyond it).
pub const GYRO_RANGE_DEG_S: f64 = 150.0;
/// ADXRS150 rate-noise density, °/s/√Hz.
pub const GYRO_NOISE_DEG_S_RT_HZ: f64 = 0.05;
/// ADXRS150 sensitivity, V per °/s (about a 2.5 V null).
pub const GYRO_SENSITIVITY_V_PER_DEG_S: f64 = 0.0125;
/// Standard deviation of the seeded, uncalibrated gyro bias, °/s.
pub const GYRO_BIAS_SIGMA_DEG_S: f64 = 0.5;
/// ADXL203 full scale, g.
pub const ACCEL_RANGE_G: f64 = 1.7;
/// ADXL203 noise density, g/√Hz.
pub const ACCEL_NOISE_G_RT_HZ: f64 = 110e-6;
/// ADXL203 sensitivity, V/g (about a 2.5 V null).
pub const ACCEL_SENSITIVITY_V_PER_G: f64 = 1.0;
/// Standard deviation of the seeded accelerometer bias (after factory trim), g.
pub const ACCEL_BIAS_SIGMA_G: f64 = 0.002;
/// Analog null of both sensors, V.
pub const SENSOR_NULL_V: f64 = 2.5;
/// ADC reference (full scale), V.
pub const ADC_REF_V: f64 = 5.0;
/// Largest 12-bit ADC count.
pub const ADC_MAX_COUNTS: u16 = 4095;
/// Position-sensor noise (1σ per axis), m.
pub const POSITION_NOISE_M: f64 = 0.001;
/// Position-sensor latency, s.
pub const POSITION_LATENCY_S: f64 = 0.010;
/// Motion-capture heading noise (1σ), rad (0.1°: a rig that resolves 1 mm on markers 0.3 m
/// apart resolves a few mrad of heading, and averages several markers).
pub const HEADING_NOISE_RAD: f64 = 0.1 * std::f64::consts::PI / 180.0;
/// Time constant of the low-pass filter on the differenced position, s.
pub const POSITION_VEL_FILTER_S: f64 = 0.04;
/// Standard gravity used to scale the accelerometer, m/s² (Table I).
const G_M_S2: f64 = crate::model::airframe::GRAVITY_M_S2;
/// Longest latency buffer, in samples.
const POSITION_HISTORY: usize = 32;

/// 12-bit conversion of a voltage: counts = round(V / V_ref · 4095), clamped to the range.
#[must_use]
pub fn adc_counts(volts: f64) -> u16 {
    // Clamped to 0..=4095 first, so the cast is exact.
    (volts / ADC_REF_V * f64::from(ADC_MAX_COUNTS))
        .round()
        .clamp(0.0, f64::from(ADC_MAX_COUNTS)) as u16
}

/// The voltage a count stands for (what the firmware reconstructs).
#[must_use]
pub fn adc_volts(counts: u16) -> f64 {
    f64::from(counts) * ADC_REF_V / f64::from(ADC_MAX_COUNTS)
}

/// One IMU sample as the firmware reads it.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct ImuSample {
    /// Gyro rates about x_B, y_B, z_B, rad/s (after the ADC).
    pub gyro_rad_s: Vector3<f64>,
    /// Accelerometer specific force along x_B, y_B, m/s² (after the ADC).
    pub accel_m_s2: [f64; 2],
    /// Raw ADC counts: gyro x, y, z, accel x, y.
    pub adc_counts: [u16; 5],
}

/// The gyros and the accelerometer with their (seeded) biases.
#[derive(Debug, Clone, PartialEq)]
pub struct Imu {
    ideal: bool,
    /// True gyro bias, rad/s (what the calibration must find).
    pub gyro_bias_rad_s: Vector3<f64>,
    /// True accelerometer bias, m/s².
    pub accel_bias_m_s2: [f64; 2],
    gyro_sigma_deg_s: f64,
    accel_sigma_g: f64,
}

impl Imu {
    /// Sensors sampled at `sample_rate_hz`; biases are drawn from `rng` unless `ideal`.
    #[must_use]
    pub fn new(ideal: bool, sample_rate_hz: f64, rng: &mut ChaCha8Rng) -> Self {
        if ideal {
            return Self {
                ideal,
                gyro_bias_rad_s: Vector3::zeros(),
                accel_bias_m_s2: [0.0; 2],
                gyro_sigma_deg_s: 0.0,
                accel_sigma_g: 0.0,
            };
        }
        let mut n = || rng.sample::<f64, _>(StandardNormal);
        let gyro_bias_rad_s = Vector3::new(n(), n(), n()) * GYRO_BIAS_SIGMA_DEG_S.to_radians();
        let accel_bias_m_s2 = [
            n() * ACCEL_BIAS_SIGMA_G * G_M_S2,
            n() * ACCEL_BIAS_SIGMA_G * G_M_S2,
        ];
        // White noise of density N seen through the Nyquist bandwidth fs/2.
        let bw = (0.5 * sample_rate_hz).sqrt();
        Self {
            ideal,
            gyro_bias_rad_s,
            accel_bias_m_s2,
            gyro_sigma_deg_s: GYRO_NOISE_DEG_S_RT_HZ * bw,
            accel_sigma_g: ACCEL_NOISE_G_RT_HZ * bw,
        }
    }

    /// Samples true body rates and the true specific force in B.
    pub fn sample(
        &self,
        omega_body_rad_s: &Vector3<f64>,
        specific_force_body_m_s2: &Vector3<f64>,
        rng: &mut ChaCha8Rng,
    ) -> ImuSample {
        let mut out = ImuSample::default();
        for i in 0..3 {
            let mut rate_deg_s = omega_body_rad_s[i].to_degrees();
            if !self.ideal {
                rate_deg_s += self.gyro_bias_rad_s[i].to_degrees()
                    + self.gyro_sigma_deg_s * rng.sample::<f64, _>(StandardNormal);
            }
            let rate_deg_s = rate_deg_s.clamp(-GYRO_RANGE_DEG_S, GYRO_RANGE_DEG_S);
            let counts = adc_counts(SENSOR_NULL_V + GYRO_SENSITIVITY_V_PER_DEG_S * rate_deg_s);
            out.adc_counts[i] = counts;
            out.gyro_rad_s[i] = if self.ideal {
                rate_deg_s.to_radians()
            } else {
                ((adc_volts(counts) - SENSOR_NULL_V) / GYRO_SENSITIVITY_V_PER_DEG_S).to_radians()
            };
        }
        for i in 0..2 {
            let mut a_g = specific_force_body_m_s2[i] / G_M_S2;
            if !self.ideal {
                a_g += self.accel_bias_m_s2[i] / G_M_S2
                    + self.accel_sigma_g * rng.sample::<f64, _>(StandardNormal);
            }
            let a_g = a_g.clamp(-ACCEL_RANGE_G, ACCEL_RANGE_G);
            let counts = adc_counts(SENSOR_NULL_V + ACCEL_SENSITIVITY_V_PER_G * a_g);
            out.adc_counts[3 + i] = counts;
            out.accel_m_s2[i] = if self.ideal {
                a_g * G_M_S2
            } else {
                (adc_volts(counts) - SENSOR_NULL_V) / ACCEL_SENSITIVITY_V_PER_G * G_M_S2
            };
        }
        out
    }
}

/// A position fix and the velocity differenced from the fixes (inertial frame, z up).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct PositionFix {
    /// Measured position, m (as of `latency` ago).
    pub pos_m: Vector3<f64>,
    /// Filtered velocity from differencing consecutive fixes, m/s.
    pub vel_m_s: Vector3<f64>,
    /// Measured heading ψ, rad in (−π, π] (as of `latency` ago, plus the rig's alignment
    /// offset).
    pub heading_rad: f64,
}

/// External position sensor (motion capture): noisy, delayed fixes of position and heading at
/// the control rate, velocity by low-pass filtered differencing.
#[derive(Debug, Clone, PartialEq)]
pub struct PositionSensor {
    ideal: bool,
    dt_s: f64,
    delay_samples: usize,
    history: [Vector3<f64>; POSITION_HISTORY],
    heading_history: [f64; POSITION_HISTORY],
    /// Constant error of the reported heading, rad: a rig whose frame is misaligned with the
    /// vehicle's reference (a fault to inject; 0 by default).
    pub heading_offset_rad: f64,
    head: usize,
    primed: bool,
    last_meas_m: Vector3<f64>,
    vel_m_s: Vector3<f64>,
    vel_gain: f64,
}

impl PositionSensor {
    /// A sensor sampled every `dt_s`.
    #[must_use]
    pub fn new(ideal: bool, dt_s: f64) -> Self {
        let delay = ((POSITION_LATENCY_S / dt_s).round() as usize).min(POSITION_HISTORY - 1);
        Self {
            ideal,
            dt_s,
            delay_samples: delay,
            history: [Vector3::zeros(); POSITION_HISTORY],
            heading_history: [0.0; POSITION_HISTORY],
            heading_offset_rad: 0.0,
            head: 0,
            primed: false,
            last_meas_m: Vector3::zeros(),
            vel_m_s: Vector3::zeros(),
            vel_gain: dt_s / (POSITION_VEL_FILTER_S + dt_s),
        }
    }

    /// Records the true position and heading and returns the fix the firmware gets now.
    pub fn sample(
        &mut self,
        true_pos_m: &Vector3<f64>,
        true_heading_rad: f64,
        rng: &mut ChaCha8Rng,
    ) -> PositionFix {
        if !self.primed {
            // Power-up: the rig has been tracking the vehicle where it stands.
            self.history = [*true_pos_m; POSITION_HISTORY];
            self.heading_history = [true_heading_rad; POSITION_HISTORY];
            self.last_meas_m = *true_pos_m;
            self.primed = true;
        }
        self.head = (self.head + 1) % POSITION_HISTORY;
        self.history[self.head] = *true_pos_m;
        self.heading_history[self.head] = true_heading_rad;
        let idx = (self.head + POSITION_HISTORY - self.delay_samples) % POSITION_HISTORY;
        let mut meas = self.history[idx];
        let mut heading = self.heading_history[idx] + self.heading_offset_rad;
        if !self.ideal {
            for i in 0..3 {
                meas[i] += POSITION_NOISE_M * rng.sample::<f64, _>(StandardNormal);
            }
            heading += HEADING_NOISE_RAD * rng.sample::<f64, _>(StandardNormal);
        }
        let raw_vel = (meas - self.last_meas_m) / self.dt_s;
        self.vel_m_s += (raw_vel - self.vel_m_s) * self.vel_gain;
        self.last_meas_m = meas;
        PositionFix {
            pos_m: meas,
            vel_m_s: self.vel_m_s,
            heading_rad: crate::model::frames::wrap_pi(heading),
        }
    }
}

/// Whether the receiver has a signal: any channel with a pulse.
#[must_use]
pub fn rc_has_signal(channels_us: &[u16; 8]) -> bool {
    channels_us[..4].iter().any(|&c| c != 0)
}

/// Pilot input from receiver pulse widths (channel 1 roll, 2 pitch, 3 throttle, 4 yaw).
/// A channel without signal (0 µs) reads as centred stick, or zero throttle.
#[must_use]
pub fn rc_to_pilot(channels_us: &[u16; 8]) -> PilotInput {
    let stick = |us: u16| {
        if us == 0 {
            0.0
        } else {
            ((f64::from(us) - 1500.0) / 500.0).clamp(-1.0, 1.0)
        }
    };
    let throttle = if channels_us[2] == 0 {
        0.0
    } else {
        ((f64::from(channels_us[2]) - 1000.0) / 1000.0).clamp(0.0, 1.0)
    };
    PilotInput {
        throttle,
        roll: stick(channels_us[0]),
        pitch: stick(channels_us[1]),
        yaw: stick(channels_us[3]),
    }
}

/// Every sensor of the twin and the one RNG that feeds them.
#[derive(Debug, Clone)]
pub struct Sensors {
    rng: ChaCha8Rng,
    /// Gyros + accelerometer.
    pub imu: Imu,
    /// Motion capture.
    pub position: PositionSensor,
}

impl Sensors {
    /// Sensors sampled every `dt_s`, seeded with `seed`.
    #[must_use]
    pub fn new(ideal: bool, seed: u64, dt_s: f64) -> Self {
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        let imu = Imu::new(ideal, 1.0 / dt_s, &mut rng);
        Self {
            rng,
            imu,
            position: PositionSensor::new(ideal, dt_s),
        }
    }

    /// Samples the IMU.
    pub fn sample_imu(
        &mut self,
        omega_body_rad_s: &Vector3<f64>,
        specific_force_body_m_s2: &Vector3<f64>,
    ) -> ImuSample {
        self.imu
            .sample(omega_body_rad_s, specific_force_body_m_s2, &mut self.rng)
    }

    /// Samples the position sensor (position and heading).
    pub fn sample_position(
        &mut self,
        true_pos_m: &Vector3<f64>,
        true_heading_rad: f64,
    ) -> PositionFix {
        self.position
            .sample(true_pos_m, true_heading_rad, &mut self.rng)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn at_rest() -> Vector3<f64> {
        Vector3::new(0.0, 0.0, G_M_S2)
    }

    #[test]
    fn gyro_saturates_and_quantises() {
        let mut s = Sensors::new(false, 7, 0.01);
        let r = s.sample_imu(&Vector3::new(10.0, -10.0, 0.0), &at_rest());
        let full = GYRO_RANGE_DEG_S.to_radians();
        assert!((r.gyro_rad_s.x - full).abs() < 0.01 && (r.gyro_rad_s.y + full).abs() < 0.01);
        // One count of the 12-bit ADC is about 0.1 °/s.
        let lsb = (ADC_REF_V / 4095.0 / GYRO_SENSITIVITY_V_PER_DEG_S).to_radians();
        let back = ((adc_volts(r.adc_counts[2]) - SENSOR_NULL_V) / GYRO_SENSITIVITY_V_PER_DEG_S)
            .to_radians();
        assert_eq!(back, r.gyro_rad_s.z, "the reading is what the counts say");
        let r2 = s.sample_imu(&Vector3::new(0.0, 0.0, 0.3), &at_rest());
        let steps = (r2.gyro_rad_s.z - r.gyro_rad_s.z) / lsb;
        assert!(
            (steps - steps.round()).abs() < 1e-6,
            "readings differ by whole counts"
        );
        assert!(r.adc_counts.iter().all(|&c| c <= ADC_MAX_COUNTS));
    }

    #[test]
    fn noise_statistics_and_seeding() {
        let mut s = Sensors::new(false, 3, 0.01);
        let n = 20_000;
        let (mut sum, mut sq) = (0.0, 0.0);
        for _ in 0..n {
            let r = s.sample_imu(&Vector3::zeros(), &at_rest());
            let x = r.gyro_rad_s.x.to_degrees();
            sum += x;
            sq += x * x;
        }
        let mean = sum / f64::from(n);
        let sd = (sq / f64::from(n) - mean * mean).sqrt();
        let expect_sd = GYRO_NOISE_DEG_S_RT_HZ * 50.0_f64.sqrt();
        assert!(
            (sd - expect_sd).abs() / expect_sd < 0.1,
            "sd {sd} vs {expect_sd}"
        );
        assert!((mean - s.imu.gyro_bias_rad_s.x.to_degrees()).abs() < 0.05);
        // Same seed, same draws; different seed, different draws.
        let a = Sensors::new(false, 11, 0.01).sample_imu(&Vector3::zeros(), &at_rest());
        let b = Sensors::new(false, 11, 0.01).sample_imu(&Vector3::zeros(), &at_rest());
        let c = Sensors::new(false, 12, 0.01).sample_imu(&Vector3::zeros(), &at_rest());
        assert_eq!(a, b);
        assert_ne!(a, c);
    }

    #[test]
    fn ideal_sensors_read_truth() {
        let mut s = Sensors::new(true, 3, 0.01);
        let w = Vector3::new(0.1, -0.2, 0.3);
        let f = Vector3::new(0.5, -1.0, 9.0);
        let r = s.sample_imu(&w, &f);
        assert!((r.gyro_rad_s - w).norm() < 1e-12);
        assert!((r.accel_m_s2[0] - 0.5).abs() < 1e-12 && (r.accel_m_s2[1] + 1.0).abs() < 1e-12);
    }

    #[test]
    fn accelerometer_reads_tilt_at_rest() {
        // Level: zero on both axes; tilted by θ about y_B: f_x = −g sin θ.
        let mut s = Sensors::new(true, 1, 0.01);
        let th: f64 = 0.2;
        let f = Vector3::new(-G_M_S2 * th.sin(), 0.0, G_M_S2 * th.cos());
        let r = s.sample_imu(&Vector3::zeros(), &f);
        assert!((r.accel_m_s2[0] + G_M_S2 * th.sin()).abs() < 1e-12);
    }

    #[test]
    fn position_sensor_delays_and_differences() {
        let mut p = PositionSensor::new(true, 0.01);
        let mut rng = ChaCha8Rng::seed_from_u64(0);
        let mut fix = PositionFix::default();
        for k in 0..200 {
            let truth = Vector3::new(0.5 * f64::from(k) * 0.01, 0.0, 1.0);
            fix = p.sample(&truth, 0.01 * f64::from(k), &mut rng);
        }
        assert!(
            (fix.heading_rad - 1.98).abs() < 1e-12,
            "heading delayed alike"
        );
        // One sample (10 ms) behind the truth at 0.5 m/s, velocity converged.
        assert!((fix.pos_m.x - 0.5 * 1.98).abs() < 1e-12, "{}", fix.pos_m.x);
        assert!((fix.vel_m_s.x - 0.5).abs() < 1e-6);
    }

    #[test]
    fn rc_mapping_and_failsafe() {
        let p = rc_to_pilot(&[2000, 1000, 1500, 1750, 0, 0, 0, 0]);
        assert_eq!((p.roll, p.pitch, p.throttle, p.yaw), (1.0, -1.0, 0.5, 0.5));
        assert_eq!(rc_to_pilot(&[0; 8]), PilotInput::default());
        assert!(!rc_has_signal(&[0; 8]));
    }
}
