//! Frames, Euler angles and the kinematic matrices of `PHYSICS.md` §1–§2.
//!
//! Inside the twin everything is in the paper's frames: the inertial frame has **z up**, the body
//! frame has thrust along +z_B, the span along y_B and x_B normal to the wing. Euler angles are
//! η = (ψ, θ, φ) with R_B→I = Rz(ψ)·Ry(θ)·Rx(φ). MAVLink's NED frame appears only at the wire,
//! through [`paper_to_ned`] and [`ned_to_paper`]; attitudes and body vectors are reported in
//! ArduPilot's fixed-wing body frame, through [`fixed_wing`].

pub mod fixed_wing;

use nalgebra::{Matrix3, Vector3};

/// Euler angles in the paper's order η = (ψ, θ, φ), radians.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Euler {
    /// Rotation about z_B (the thrust axis): yaw in the paper's hover names.
    pub psi: f64,
    /// Rotation about y_B (pitch, driven by the elevator).
    pub theta: f64,
    /// Rotation about x_B (roll, driven by the rotor thrust difference).
    pub phi: f64,
}

impl Euler {
    /// Builds angles from (ψ, θ, φ).
    #[must_use]
    pub const fn new(psi: f64, theta: f64, phi: f64) -> Self {
        Self { psi, theta, phi }
    }

    /// The angles stacked as the paper stacks η: (ψ, θ, φ).
    #[must_use]
    pub fn as_vector(&self) -> Vector3<f64> {
        Vector3::new(self.psi, self.theta, self.phi)
    }

    /// Inverse of [`Euler::as_vector`].
    #[must_use]
    pub fn from_vector(v: &Vector3<f64>) -> Self {
        Self::new(v[0], v[1], v[2])
    }

    /// R_B→I = Rz(ψ)·Ry(θ)·Rx(φ), as printed in the paper.
    #[must_use]
    pub fn rotation_body_to_inertial(&self) -> Matrix3<f64> {
        rotation_from_sin_cos(self.psi.sin_cos(), self.theta.sin_cos(), self.phi.sin_cos())
    }

    /// W_n of (3): Ω = W_n η̇ with η̇ = (ψ̇, θ̇, φ̇).
    #[must_use]
    pub fn w_n(&self) -> Matrix3<f64> {
        let (sth, cth) = self.theta.sin_cos();
        let (sph, cph) = self.phi.sin_cos();
        Matrix3::new(-sth, 0.0, 1.0, cth * sph, cph, 0.0, cth * cph, -sph, 0.0)
    }

    /// W_n⁻¹ in closed form: η̇ = W_n⁻¹ Ω. Singular at θ = ±π/2, which hover never reaches.
    #[must_use]
    pub fn w_n_inverse(&self) -> Matrix3<f64> {
        let (sth, cth) = self.theta.sin_cos();
        let (sph, cph) = self.phi.sin_cos();
        let tth = sth / cth;
        Matrix3::new(
            0.0,
            sph / cth,
            cph / cth,
            0.0,
            cph,
            -sph,
            1.0,
            sph * tth,
            cph * tth,
        )
    }

    /// Ẇ_n, the time derivative of W_n along the rates η̇ = (ψ̇, θ̇, φ̇).
    #[must_use]
    pub fn w_n_dot(&self, eta_dot: &Vector3<f64>) -> Matrix3<f64> {
        let (sth, cth) = self.theta.sin_cos();
        let (sph, cph) = self.phi.sin_cos();
        let th_d = eta_dot[1];
        let ph_d = eta_dot[2];
        Matrix3::new(
            -cth * th_d,
            0.0,
            0.0,
            -sth * sph * th_d + cth * cph * ph_d,
            -sph * ph_d,
            0.0,
            -sth * cph * th_d - cth * sph * ph_d,
            -cph * ph_d,
            0.0,
        )
    }

    /// Euler rates η̇ = (ψ̇, θ̇, φ̇) from body rates Ω = (p, q, r).
    #[must_use]
    pub fn rates_from_body(&self, omega_body_rad_s: &Vector3<f64>) -> Vector3<f64> {
        self.w_n_inverse() * omega_body_rad_s
    }

    /// Wraps ψ into (−π, π].
    #[must_use]
    pub fn wrapped(self) -> Self {
        Self {
            psi: wrap_pi(self.psi),
            ..self
        }
    }
}

/// R_B→I = Rz(ψ)·Ry(θ)·Rx(φ) from the (sin, cos) pairs of ψ, θ and φ: the one place the
/// matrix is written, for callers that already hold the trigonometry.
#[must_use]
pub fn rotation_from_sin_cos(
    (sps, cps): (f64, f64),
    (sth, cth): (f64, f64),
    (sph, cph): (f64, f64),
) -> Matrix3<f64> {
    Matrix3::new(
        cth * cps,
        sph * sth * cps - cph * sps,
        cph * sth * cps + sph * sps,
        cth * sps,
        sph * sth * sps + cph * cps,
        cph * sth * sps - sph * cps,
        -sth,
        sph * cth,
        cph * cth,
    )
}

/// Wraps an angle into (−π, π]. An angle already there is returned unchanged (exactly: a
/// small negative angle is not moved through 2π and back, which would round it).
#[inline]
#[must_use]
pub fn wrap_pi(a: f64) -> f64 {
    use std::f64::consts::PI;
    if a > -PI && a <= PI {
        return a;
    }
    let w = a.rem_euclid(2.0 * std::f64::consts::PI);
    if w > std::f64::consts::PI {
        w - 2.0 * std::f64::consts::PI
    } else {
        w
    }
}

/// The paper's inertial frame (z up) to NED: positions and velocities at the wire.
///
/// In hover the vehicle's "forward" (where a pilot behind it looks) is −x_B, its right is +y_B
/// (rotor 1 and aileron R of `PHYSICS.md` §1, so the paper's R/L names are right and left as a
/// pilot sees them) and its down is −z_B. That is a rotation of π about y: FRD = (−x, y, −z).
/// The same rotation maps the inertial frame (z up) to NED, so in this hover frame a level
/// vehicle heading north has roll = pitch = yaw = 0. Being a half-turn, the map is its own
/// inverse.
#[must_use]
pub fn paper_to_ned(v: &Vector3<f64>) -> Vector3<f64> {
    Vector3::new(-v[0], v[1], -v[2])
}

/// Inverse of [`paper_to_ned`] (the map is its own inverse).
#[must_use]
pub fn ned_to_paper(v: &Vector3<f64>) -> Vector3<f64> {
    paper_to_ned(v)
}

/// The hover frame's attitude (roll, pitch, yaw) in NED/FRD from the paper's angles: the axes a
/// pilot behind the hovering vehicle sees, in which `SIM_PUSH_*` and `simulate` push. What the
/// twin reports is in the fixed-wing frame ([`fixed_wing::attitude`]). Conjugating
/// Rz(ψ)·Ry(θ)·Rx(φ) by the half-turn about y gives Rz(−ψ)·Ry(θ)·Rx(−φ), so roll = −φ,
/// pitch = θ, yaw = −ψ.
#[must_use]
pub fn euler_to_ned_rpy(e: &Euler) -> [f64; 3] {
    [-e.phi, e.theta, wrap_pi(-e.psi)]
}

/// A body-frame vector (rates, torques, specific force) in the hover frame's FRD: (−x, y, −z)
/// (reported vectors are in the fixed-wing frame: [`fixed_wing::body_vector`]). Its own inverse,
/// so it also maps FRD vectors back to the paper's body frame.
#[must_use]
pub fn body_rates_to_frd(omega: &Vector3<f64>) -> [f64; 3] {
    [-omega[0], omega[1], -omega[2]]
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn w_n_inverse_is_inverse() {
        let e = Euler::new(0.7, -0.4, 0.3);
        let prod = e.w_n() * e.w_n_inverse();
        assert!((prod - Matrix3::identity()).norm() < 1e-12);
    }

    #[test]
    fn w_n_dot_matches_finite_difference() {
        let e = Euler::new(0.2, 0.3, -0.5);
        let rates = Vector3::new(0.4, -0.7, 1.1);
        let h = 1e-6;
        let e2 = Euler::from_vector(&(e.as_vector() + rates * h));
        let fd = (e2.w_n() - e.w_n()) / h;
        assert!((fd - e.w_n_dot(&rates)).norm() < 1e-5);
    }

    #[test]
    fn rotation_is_orthonormal() {
        let r = Euler::new(1.0, 0.2, -0.3).rotation_body_to_inertial();
        assert!((r.transpose() * r - Matrix3::identity()).norm() < 1e-12);
        assert!((r.determinant() - 1.0).abs() < 1e-12);
    }

    #[test]
    fn mavlink_attitude_matches_the_rotated_frames() {
        // R_ned = T R T with T the half-turn about y must equal the matrix of the reported
        // roll/pitch/yaw in the ZYX convention.
        let e = Euler::new(0.7, -0.3, 0.4);
        let t = Matrix3::new(-1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, -1.0);
        let r_ned = t * e.rotation_body_to_inertial() * t;
        let [roll, pitch, yaw] = euler_to_ned_rpy(&e);
        let r_rpy = Euler::new(yaw, pitch, roll).rotation_body_to_inertial();
        assert!((r_ned - r_rpy).norm() < 1e-12);
        // Rates: Ω_frd = T Ω.
        let w = Vector3::new(0.1, 0.2, 0.3);
        assert_eq!(body_rates_to_frd(&w), [-0.1, 0.2, -0.3]);
        // Up is −down, rotor 1 (+y_B) is on the right.
        assert_eq!(
            paper_to_ned(&Vector3::new(0.0, 1.0, 2.0)),
            Vector3::new(0.0, 1.0, -2.0)
        );
    }
}
