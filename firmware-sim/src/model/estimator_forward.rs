//! The attitude estimate in forward flight and the transitions (`docs/forward-flight.md`).
//!
//! The hover estimator ([`super::estimator`]) integrates Euler angles, singular where a
//! tailsitter flies level, and fills the accelerometer's missing z axis with the hover's thrust.
//! From the start of a forward transition to the end of the back transition the vehicle flies
//! on this filter instead: a quaternion integrates the gyros (bias from the hover estimator's
//! calibration), and two vector measurements correct it (Mahony, Hamel & Pflimlin 2008):
//!
//! * the specific force: the accelerometer's x and y with the modelled z (commanded thrust plus
//!   the airframe's aerodynamic force along the nose, over the mass) must equal Rᵀ(a + g e_z),
//!   with a the acceleration of the position sensor's velocity. Unlike the hover's "f ≈ thrust
//!   along z_B", this holds with the nose horizontal and the wing lifting;
//! * the heading fix, as a rotation about the vertical.
//!
//! When the hover takes over again, the hover estimator is realigned on this one.

use nalgebra::{UnitQuaternion, Vector3};

use crate::model::frames::{Euler, wrap_pi};

/// Gain of the specific-force correction, rad/s.
const FORCE_GAIN_RAD_S: f64 = 1.0;
/// Gain of the heading correction, rad/s.
const HEADING_GAIN_RAD_S: f64 = 1.0;
/// Time constant of the low-pass on the velocity's derivative, s.
const ACCEL_FILTER_S: f64 = 0.1;
/// Below this magnitude a vector carries no direction, m/s².
const MIN_VECTOR_M_S2: f64 = 2.0;

/// The forward-flight attitude filter.
#[derive(Debug, Clone, PartialEq)]
pub struct ForwardAttitude {
    q: UnitQuaternion<f64>,
    gyro_bias_rad_s: Vector3<f64>,
    last_vel_m_s: Option<Vector3<f64>>,
    accel_m_s2: Vector3<f64>,
    omega_rad_s: Vector3<f64>,
}

impl ForwardAttitude {
    /// Starts from the hover estimator's attitude and gyro bias.
    #[must_use]
    pub fn new(euler: Euler, gyro_bias_rad_s: Vector3<f64>) -> Self {
        let r = euler.rotation_body_to_inertial();
        Self {
            q: UnitQuaternion::from_matrix(&r),
            gyro_bias_rad_s,
            last_vel_m_s: None,
            accel_m_s2: Vector3::zeros(),
            omega_rad_s: Vector3::zeros(),
        }
    }

    /// One update: `gyro` the gyros, `specific_force` the accelerometer's x, y and the modelled
    /// z (B, m/s²), `vel_m_s` the position sensor's velocity (inertial, z up), `heading_rad` the
    /// heading fix if fused.
    pub fn update(
        &mut self,
        dt_s: f64,
        gravity_m_s2: f64,
        gyro: &Vector3<f64>,
        specific_force: &Vector3<f64>,
        vel_m_s: &Vector3<f64>,
        heading_rad: Option<f64>,
    ) {
        self.omega_rad_s = gyro - self.gyro_bias_rad_s;
        if let Some(last) = self.last_vel_m_s {
            let raw = (vel_m_s - last) / dt_s.max(1e-6);
            self.accel_m_s2 += (raw - self.accel_m_s2) * (dt_s / ACCEL_FILTER_S).min(1.0);
        }
        self.last_vel_m_s = Some(*vel_m_s);
        let r = self.q.to_rotation_matrix();
        let mut correction = Vector3::zeros();
        let predicted =
            r.inverse_transform_vector(&(self.accel_m_s2 + Vector3::new(0.0, 0.0, gravity_m_s2)));
        let (nf, np) = (specific_force.norm(), predicted.norm());
        if nf > MIN_VECTOR_M_S2 && np > MIN_VECTOR_M_S2 {
            correction += FORCE_GAIN_RAD_S * specific_force.cross(&predicted) / (nf * np);
        }
        if let Some(h) = heading_rad {
            let psi = self.euler().psi;
            let about_vertical = HEADING_GAIN_RAD_S * wrap_pi(h - psi);
            correction += r.inverse_transform_vector(&Vector3::new(0.0, 0.0, about_vertical));
        }
        let step = (self.omega_rad_s + correction) * dt_s;
        self.q *= UnitQuaternion::from_scaled_axis(step);
        self.q.renormalize();
    }

    /// The attitude as the paper's Euler angles (well defined short of θ = ±90°, which forward
    /// flight keeps away from).
    #[must_use]
    pub fn euler(&self) -> Euler {
        let r = self.q.to_rotation_matrix();
        let m = r.matrix();
        Euler::new(
            m[(1, 0)].atan2(m[(0, 0)]),
            (-m[(2, 0)]).clamp(-1.0, 1.0).asin(),
            m[(2, 1)].atan2(m[(2, 2)]),
        )
    }

    /// Body rates, gyro minus bias, rad/s.
    #[must_use]
    pub fn omega_rad_s(&self) -> Vector3<f64> {
        self.omega_rad_s
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn euler_round_trips_near_level_flight() {
        let e = Euler::new(0.4, 1.45, -0.2);
        let f = ForwardAttitude::new(e, Vector3::zeros());
        let back = f.euler();
        assert!((back.psi - e.psi).abs() < 1e-9 && (back.theta - e.theta).abs() < 1e-9);
        assert!((back.phi - e.phi).abs() < 1e-9, "{back:?}");
    }

    #[test]
    fn a_tilt_error_in_level_flight_is_pulled_out_by_the_specific_force() {
        // Level flight, nose along +x, 5° above the horizon: the wing's lift holds the weight,
        // the specific force is g along −x_B.
        let truth = Euler::new(0.0, std::f64::consts::FRAC_PI_2 - 0.087, 0.0);
        let r = truth.rotation_body_to_inertial();
        let force = r.transpose() * Vector3::new(0.0, 0.0, 9.8);
        let mut f = ForwardAttitude::new(Euler { phi: 0.1, ..truth }, Vector3::zeros());
        for _ in 0..1000 {
            f.update(
                0.01,
                9.8,
                &Vector3::zeros(),
                &force,
                &Vector3::new(12.0, 0.0, 0.0),
                Some(0.0),
            );
        }
        let e = f.euler();
        let err = (e.rotation_body_to_inertial() - r).norm();
        assert!(err < 0.01, "{e:?}");
    }
}
