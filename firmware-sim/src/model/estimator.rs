//! Attitude estimator of the `physical` twin: a complementary filter over the three gyros and the
//! two-axis accelerometer, with gyro-bias calibration at rest after power-up.
//!
//! Frames: gyro and accelerometer in B, the estimate as η = (ψ, θ, φ) of `PHYSICS.md` §1.
//! The gyros are integrated through W_n⁻¹ (3). The accelerometer measures the specific force
//! f = Rᵀ(ξ̈ + g e_z); in hover the thrust makes f_x ≈ f_y ≈ 0 whatever the tilt, so the classic
//! "accelerometer = gravity" correction drags the estimate toward level during every manoeuvre.
//!
//! With the position sensor (the modes that hold position need it anyway) the tilt is made
//! observable the way the chains use it: the filter predicts position from the measured specific
//! force rotated by the estimated attitude (ξ̈ = R(η̂) f − g e_z, with f_z ≈ g / (cos φ cos θ)),
//! and feeds the position residual back into position, velocity, tilt (ẍ_h = g θ, ÿ_h = −g φ in
//! the heading frame) and the roll/pitch gyro biases: a fourth-order complementary filter with
//! all error poles at −[`NAV_BANDWIDTH_RAD_S`]. The position is used directly, not
//! differentiated twice: with the chains' gains a tilt error of 1 mrad holds the vehicle about
//! 6 cm off its setpoint, so low-frequency attitude noise is what limits the hold. Without a
//! position sensor (the prototype) the filter falls back to the plain accelerometer correction.
//!
//! Yaw is not observable from gravity. When the motion-capture heading is fused (the modes that
//! fly on the motion capture), a second-order complementary filter pulls ψ̂ to the delayed
//! heading fix and estimates the yaw-gyro bias, both error poles at −[`HEADING_BANDWIDTH_RAD_S`];
//! without it (QSTABILIZE, the paper's experiment, or the heading sensor switched off) yaw comes
//! from gyro integration only and drifts with the residual bias of the calibration.
//! `paper` mode bypasses this module ([I17]).
//!
//! Large tilts: the gyros are integrated through W_n⁻¹ with a second-order (midpoint) step, so
//! a fast swing from 0.8 rad does not leave a first-order integration error in the estimate.

use nalgebra::Vector3;

use crate::model::frames::{Euler, wrap_pi};
use crate::model::plant::rigid_body::EulerTrig;
use crate::model::sensors::ImuSample;

/// Time constant of the accelerometer correction, s: the gyros are trusted above ~0.16 Hz,
/// the accelerometer below.
pub const ACCEL_CORRECTION_TIME_S: f64 = 1.0;
/// Bandwidth of the position-aided filter: its four error poles sit at −ω, rad/s. With the
/// chains' gains 1 mrad of tilt error holds the vehicle about 6 cm off, and below the filter's
/// bandwidth the tilt error is gyro noise shaped by ~6s/ω²: at 4 rad/s that alone wandered
/// ±3 cm in ten minutes, at 6 rad/s the hold is about ±2 cm. 8 rad/s is no better, and at
/// 10 rad/s the filter, sampled at 100 Hz behind the fix's 10 ms latency, goes unstable.
pub const NAV_BANDWIDTH_RAD_S: f64 = 6.0;
/// Bandwidth of the heading filter: both error poles at −ω, rad/s. Slow enough that the 0.1°
/// heading noise stays below 0.05°, fast enough to track the gyro-bias drift.
pub const HEADING_BANDWIDTH_RAD_S: f64 = 1.0;
/// Latency of the position sensor the filter compensates, s (`sensors::POSITION_LATENCY_S`).
const POSITION_LATENCY_S: f64 = crate::model::sensors::POSITION_LATENCY_S;
/// Length of the history of predicted positions kept for the latency.
const NAV_HISTORY: usize = 32;
/// Duration of the gyro calibration at rest, s.
pub const CALIBRATION_TIME_S: f64 = 1.0;
/// Largest plausible tilt correction per update (guards against saturated readings), rad.
const MAX_CORRECTION_RAD: f64 = 0.01;

/// Complementary attitude filter with gyro-bias calibration.
#[derive(Debug, Clone, PartialEq)]
pub struct Estimator {
    euler: Euler,
    omega_rad_s: Vector3<f64>,
    gyro_bias_rad_s: Vector3<f64>,
    accel_bias_m_s2: [f64; 2],
    cal_sum_rad_s: Vector3<f64>,
    cal_sum_accel_m_s2: [f64; 2],
    cal_count: u32,
    cal_needed: u32,
    calibrated: bool,
    dt_s: f64,
    gravity_m_s2: f64,
    nav_initialised: bool,
    pos_m: Vector3<f64>,
    vel_m_s: Vector3<f64>,
    pos_history_m: [Vector3<f64>; NAV_HISTORY],
    /// Specific thrust along z_B the firmware commands, m/s² (`None`: assume hover).
    thrust_accel_m_s2: Option<f64>,
    /// ψ̂ of the last updates minus `psi_shift_rad` at the time of writing, indexed like
    /// `pos_history_m` (for the heading fix's latency). Unwrapped: only differences are used.
    psi_history_rad: [f64; NAV_HISTORY],
    /// Sum of the heading corrections so far: every stored ψ̂ moves with each correction, and
    /// keeping the sum apart makes that O(1) instead of a pass over the history.
    psi_shift_rad: f64,
    history_head: usize,
    delay_samples: usize,
}

impl Estimator {
    /// An estimator updated every `dt_s`, starting from `initial` (the heading reference is
    /// aligned at power-up, as an operator or the motion-capture rig would do).
    #[must_use]
    pub fn new(initial: Euler, dt_s: f64, gravity_m_s2: f64) -> Self {
        Self {
            euler: initial,
            omega_rad_s: Vector3::zeros(),
            gyro_bias_rad_s: Vector3::zeros(),
            accel_bias_m_s2: [0.0; 2],
            cal_sum_rad_s: Vector3::zeros(),
            cal_sum_accel_m_s2: [0.0; 2],
            cal_count: 0,
            cal_needed: ((CALIBRATION_TIME_S / dt_s).round() as u32).max(1),
            calibrated: false,
            dt_s,
            gravity_m_s2,
            nav_initialised: false,
            pos_m: Vector3::zeros(),
            vel_m_s: Vector3::zeros(),
            pos_history_m: [Vector3::zeros(); NAV_HISTORY],
            psi_history_rad: [initial.psi; NAV_HISTORY],
            psi_shift_rad: 0.0,
            thrust_accel_m_s2: None,
            history_head: 0,
            delay_samples: ((POSITION_LATENCY_S / dt_s).round() as usize).min(NAV_HISTORY - 1),
        }
    }

    /// Feeds one IMU sample taken at rest on level ground; returns true once the biases are
    /// known. Gyro bias = mean rate; accelerometer bias = mean reading (level: f_x = f_y = 0),
    /// the "level trim" of common autopilots. Both matter: with the chains' gains an attitude
    /// offset of 1 mrad holds the vehicle about 6 cm off its setpoint.
    pub fn calibrate(&mut self, imu: &ImuSample) -> bool {
        if self.calibrated {
            return true;
        }
        self.cal_sum_rad_s += imu.gyro_rad_s;
        self.cal_sum_accel_m_s2[0] += imu.accel_m_s2[0];
        self.cal_sum_accel_m_s2[1] += imu.accel_m_s2[1];
        self.cal_count += 1;
        if self.cal_count >= self.cal_needed {
            let n = f64::from(self.cal_count);
            self.gyro_bias_rad_s = self.cal_sum_rad_s / n;
            self.accel_bias_m_s2 = [
                self.cal_sum_accel_m_s2[0] / n,
                self.cal_sum_accel_m_s2[1] / n,
            ];
            self.calibrated = true;
        }
        self.calibrated
    }

    /// Marks the gyros calibrated without a bias (ideal sensors, `paper` mode).
    pub fn skip_calibration(&mut self) {
        self.calibrated = true;
    }

    /// Whether the gyro bias is known.
    #[must_use]
    pub fn is_calibrated(&self) -> bool {
        self.calibrated
    }

    /// The current gyro-bias estimate, rad/s.
    #[must_use]
    pub fn gyro_bias_rad_s(&self) -> Vector3<f64> {
        self.gyro_bias_rad_s
    }

    /// The accelerometer bias the calibration found, m/s².
    #[must_use]
    pub fn accel_bias_m_s2(&self) -> [f64; 2] {
        self.accel_bias_m_s2
    }

    /// One update: integrate the gyros, then correct with the position sensor's fix
    /// (`pos_m`, delayed by the sensor's latency) if there is one, else with the accelerometer,
    /// and with the heading fix (`heading_rad`, same latency) if it is fused.
    pub fn update(
        &mut self,
        imu: &ImuSample,
        pos_m: Option<&Vector3<f64>>,
        heading_rad: Option<f64>,
    ) {
        let dt = self.dt_s;
        let g = self.gravity_m_s2;
        self.omega_rad_s = imu.gyro_rad_s - self.gyro_bias_rad_s;
        // Midpoint rule on η̇ = W_n⁻¹(η) Ω: W_n⁻¹ changes fast at large tilt, and a plain Euler
        // step there leaves an error of order Ω²Δt per update that never comes back.
        let trig0 = EulerTrig::new(&self.euler);
        let rates0 = trig0.euler_rates(&self.omega_rad_s);
        let half = Euler::new(
            self.euler.psi + 0.5 * rates0[0] * dt,
            self.euler.theta + 0.5 * rates0[1] * dt,
            self.euler.phi + 0.5 * rates0[2] * dt,
        );
        // The half step moves the angles by a few mrad: angle addition, not three sin_cos.
        let rates = trig0
            .shifted(&self.euler, &half)
            .euler_rates(&self.omega_rad_s);
        let mut e = Euler::new(
            self.euler.psi + rates[0] * dt,
            self.euler.theta + rates[1] * dt,
            self.euler.phi + rates[2] * dt,
        );
        // Heading first: the position correction works in the heading frame.
        if let Some(h) = heading_rad {
            self.heading_correction(&mut e, h);
        }
        let f_x = imu.accel_m_s2[0] - self.accel_bias_m_s2[0];
        let f_y = imu.accel_m_s2[1] - self.accel_bias_m_s2[1];

        match pos_m {
            Some(p) => self.position_correction(&mut e, f_x, f_y, p),
            None => {
                // Plain filter: at rest f = Rᵀ g e_z, so f_x ≈ −g θ and f_y ≈ g φ near level.
                let k = dt / ACCEL_CORRECTION_TIME_S;
                let predicted = EulerTrig::new(&e)
                    .rotation_body_to_inertial()
                    .tr_mul(&Vector3::new(0.0, 0.0, g));
                let d_theta = -(f_x - predicted.x) / g;
                let d_phi = (f_y - predicted.y) / g;
                e.theta += (k * d_theta).clamp(-MAX_CORRECTION_RAD, MAX_CORRECTION_RAD);
                e.phi += (k * d_phi).clamp(-MAX_CORRECTION_RAD, MAX_CORRECTION_RAD);
            }
        }
        e.psi = wrap_pi(e.psi);
        // The history advances once per update, with or without a position fix.
        if pos_m.is_none() {
            self.history_head = (self.history_head + 1) % NAV_HISTORY;
        }
        self.psi_history_rad[self.history_head] = e.psi - self.psi_shift_rad;
        self.euler = e;
    }

    /// The heading correction: ψ̂ toward the delayed fix, the residual that persists into the
    /// yaw-gyro bias (near level ψ̇ ≈ r).
    fn heading_correction(&mut self, e: &mut Euler, heading_rad: f64) {
        let dt = self.dt_s;
        let w = HEADING_BANDWIDTH_RAD_S;
        let (k1, k2) = (2.0 * w, w * w);
        // The fix is `delay_samples` old: compare it with ψ̂ of that instant (the slots are
        // indexed as the position history's; the current update's slot is written after).
        let idx = (self.history_head + NAV_HISTORY - self.delay_samples) % NAV_HISTORY;
        let r = wrap_pi(heading_rad - (self.psi_history_rad[idx] + self.psi_shift_rad));
        let d = (k1 * r * dt).clamp(-MAX_CORRECTION_RAD, MAX_CORRECTION_RAD);
        e.psi += d;
        // The whole history moves by the same correction, so that it stays consistent.
        self.psi_shift_rad += d;
        self.gyro_bias_rad_s.z -= k2 * r * dt;
    }

    /// The position-aided correction (see the module header).
    fn position_correction(&mut self, e: &mut Euler, f_x: f64, f_y: f64, p: &Vector3<f64>) {
        let dt = self.dt_s;
        let g = self.gravity_m_s2;
        if !self.nav_initialised {
            self.pos_m = *p;
            self.vel_m_s = Vector3::zeros();
            self.pos_history_m = [*p; NAV_HISTORY];
            self.nav_initialised = true;
        }
        let w = NAV_BANDWIDTH_RAD_S;
        let (k1, k2, k3, k4) = (4.0 * w, 6.0 * w * w, 4.0 * w * w * w, w * w * w * w);

        // Compare the fix with the prediction of the same instant.
        let idx = (self.history_head + NAV_HISTORY - self.delay_samples) % NAV_HISTORY;
        let r = p - self.pos_history_m[idx];

        let trig = EulerTrig::new(e);
        // The accelerometer has no z axis: the thrust is the firmware's own command when it
        // flies (what the altitude law asked for, tilt compensation and climb included), else
        // the hover assumption.
        let f_z = self.thrust_accel_m_s2.unwrap_or_else(|| {
            let tilt_cos = (e.theta.cos() * e.phi.cos()).max(0.5);
            g / tilt_cos
        });
        let f_body = Vector3::new(f_x, f_y, f_z);
        let accel = trig.rotation_body_to_inertial() * f_body - Vector3::new(0.0, 0.0, g);
        self.pos_m += (self.vel_m_s + k1 * r) * dt;
        self.vel_m_s += (accel + k2 * r) * dt;
        for (i, c) in self.pos_history_m.iter_mut().enumerate() {
            // Shift the whole history by the same correction so that it stays consistent.
            if i != self.history_head {
                *c += k1 * r * dt;
            }
        }
        self.history_head = (self.history_head + 1) % NAV_HISTORY;
        self.pos_history_m[self.history_head] = self.pos_m;

        // Residual in the heading frame: ẍ_h = g θ, ÿ_h = −g φ near level.
        let (s, c) = e.psi.sin_cos();
        let r_xh = c * r.x + s * r.y;
        let r_yh = -s * r.x + c * r.y;
        e.theta += (k3 / g * r_xh * dt).clamp(-MAX_CORRECTION_RAD, MAX_CORRECTION_RAD);
        e.phi -= (k3 / g * r_yh * dt).clamp(-MAX_CORRECTION_RAD, MAX_CORRECTION_RAD);
        // A tilt error that persists is a gyro bias (near level θ̇ ≈ q and φ̇ ≈ p).
        self.gyro_bias_rad_s.y -= k4 / g * r_xh * dt;
        self.gyro_bias_rad_s.x += k4 / g * r_yh * dt;
    }

    /// Takes over from the forward-flight filter at the end of a back transition: its
    /// attitude, and the position sensor's position and velocity for the position-aided part
    /// (this filter was not updated in forward flight). The gyro biases are kept.
    pub fn realign(&mut self, euler: Euler, pos_m: &Vector3<f64>, vel_m_s: &Vector3<f64>) {
        self.euler = euler;
        self.psi_history_rad = [euler.psi - self.psi_shift_rad; NAV_HISTORY];
        self.pos_m = *pos_m;
        self.vel_m_s = *vel_m_s;
        self.pos_history_m = [*pos_m; NAV_HISTORY];
        self.nav_initialised = true;
    }

    /// Estimated attitude.
    #[must_use]
    pub fn euler(&self) -> Euler {
        self.euler
    }

    /// The specific thrust f_z/m the firmware is commanding, m/s², used in place of the
    /// accelerometer's missing z axis; `None` assumes hover thrust g/(cos φ cos θ).
    pub fn set_thrust_accel(&mut self, thrust_accel_m_s2: Option<f64>) {
        self.thrust_accel_m_s2 = thrust_accel_m_s2;
    }

    /// Position of the position-aided filter (latency compensated; inertial, z up), m, once a
    /// fix has been fused.
    #[must_use]
    pub fn position_m(&self) -> Option<Vector3<f64>> {
        self.nav_initialised.then_some(self.pos_m)
    }

    /// Velocity of the position-aided filter (inertial, z up), m/s, once a fix has been fused.
    #[must_use]
    pub fn velocity_m_s(&self) -> Option<Vector3<f64>> {
        self.nav_initialised.then_some(self.vel_m_s)
    }

    /// Estimated body rates (gyro minus bias), rad/s.
    #[must_use]
    pub fn omega_rad_s(&self) -> Vector3<f64> {
        self.omega_rad_s
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::model::sensors::Sensors;

    const G: f64 = 9.8;

    #[test]
    fn calibration_finds_the_bias() {
        let mut s = Sensors::new(false, 5, 0.01);
        let mut est = Estimator::new(Euler::default(), 0.01, G);
        let rest = Vector3::new(0.0, 0.0, G);
        while !est.calibrate(&s.sample_imu(&Vector3::zeros(), &rest)) {}
        let err = (est.gyro_bias_rad_s() - s.imu.gyro_bias_rad_s).norm();
        // 1 s of 0.05 °/s/√Hz noise averages to ~0.05 °/s per axis.
        assert!(err < 0.2_f64.to_radians(), "bias error {err}");
        let b = est.accel_bias_m_s2();
        let truth = s.imu.accel_bias_m_s2;
        // One ADC count is 1.2 mg; the noise dithers the mean to a fraction of it.
        assert!(
            (b[0] - truth[0]).abs() < 0.01 && (b[1] - truth[1]).abs() < 0.01,
            "{b:?}"
        );
    }

    #[test]
    fn converges_to_static_tilt_from_level() {
        let mut s = Sensors::new(false, 9, 0.01);
        let mut est = Estimator::new(Euler::default(), 0.01, G);
        let e = Euler::new(0.0, 0.1, -0.15);
        let f = e.rotation_body_to_inertial().transpose() * Vector3::new(0.0, 0.0, G);
        while !est.calibrate(&s.sample_imu(&Vector3::zeros(), &Vector3::new(0.0, 0.0, G))) {}
        for _ in 0..1000 {
            let imu = s.sample_imu(&Vector3::zeros(), &f);
            est.update(&imu, None, None);
        }
        let got = est.euler();
        assert!(
            (got.theta - 0.1).abs() < 0.01 && (got.phi + 0.15).abs() < 0.01,
            "{got:?}"
        );
    }

    #[test]
    fn position_aiding_finds_a_tilt_and_a_gyro_bias() {
        // Start 0.02 rad wrong in θ with an uncalibrated pitch gyro bias; hovering still (the
        // fix does not move), the filter must find both.
        let mut s = Sensors::new(true, 1, 0.01);
        let mut est = Estimator::new(Euler::new(0.0, 0.02, 0.0), 0.01, G);
        est.skip_calibration();
        let bias = 0.01;
        let fix = Vector3::new(0.0, 0.0, 1.0);
        for _ in 0..2000 {
            let imu = s.sample_imu(&Vector3::new(0.0, bias, 0.0), &Vector3::new(0.0, 0.0, G));
            est.update(&imu, Some(&fix), None);
        }
        assert!(est.euler().theta.abs() < 1e-4, "{:?}", est.euler());
        assert!(
            (est.gyro_bias_rad_s().y - bias).abs() < 1e-4,
            "{:?}",
            est.gyro_bias_rad_s()
        );
    }

    #[test]
    fn tilted_hover_is_not_pulled_level_when_acceleration_is_known() {
        // Thrust-only flight: the accelerometer reads 0 on x_B, y_B while the vehicle, tilted
        // by φ, accelerates at −g tan φ along y. With that acceleration known the estimate holds.
        let phi = 0.1_f64;
        let mut s = Sensors::new(true, 1, 0.01);
        let mut est = Estimator::new(Euler::new(0.0, 0.0, phi), 0.01, G);
        est.skip_calibration();
        let a_y = -G * phi.tan();
        let mut seen = Vector3::zeros();
        for k in 0..500 {
            let imu = s.sample_imu(&Vector3::zeros(), &Vector3::new(0.0, 0.0, G / phi.cos()));
            let t = f64::from(k) * 0.01;
            // The fix lags the truth by one 10 ms sample.
            let fix = seen;
            seen = Vector3::new(0.0, 0.5 * a_y * t * t, 1.0);
            est.update(&imu, Some(&fix), None);
        }
        assert!((est.euler().phi - phi).abs() < 2e-3, "{:?}", est.euler());
    }
}
