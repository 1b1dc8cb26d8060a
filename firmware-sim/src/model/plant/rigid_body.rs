//! Newton–Euler rigid body in the paper's frames (`PHYSICS.md` §2): translational dynamics in
//! the body frame (7) with the corrected gravity signs ([I3]), rotational dynamics (13) with the
//! corrected z term ([I13]), and the kinematics ξ̇ = R vᴮ, η̇ = W_n⁻¹ Ω (3).
//!
//! The sines and cosines of η are computed once per evaluation ([`EulerTrig`]), because the
//! derivative runs four times per 1 kHz physics step.

use nalgebra::{Matrix3, Vector3};

use crate::model::airframe::Airframe;
use crate::model::frames::Euler;

/// Sines and cosines of η = (ψ, θ, φ), computed once and shared by R and W_n⁻¹.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct EulerTrig {
    /// (sin ψ, cos ψ).
    psi: (f64, f64),
    /// (sin θ, cos θ).
    theta: (f64, f64),
    /// (sin φ, cos φ).
    phi: (f64, f64),
}

impl EulerTrig {
    /// The trigonometric functions of `e`.
    #[must_use]
    pub fn new(e: &Euler) -> Self {
        Self {
            psi: e.psi.sin_cos(),
            theta: e.theta.sin_cos(),
            phi: e.phi.sin_cos(),
        }
    }

    /// The trigonometric functions of `to`, from those of `from` (`self`) by the angle-addition
    /// formulas with a Taylor series for the small increment: the RK4 stages sit within a few
    /// mrad of the step's start, so this replaces three `sin_cos` per stage by a few products.
    /// Exact to rounding for increments up to [`SHIFT_MAX_RAD`]; larger ones are recomputed.
    #[inline]
    #[must_use]
    pub fn shifted(&self, from: &Euler, to: &Euler) -> Self {
        let d = [to.psi - from.psi, to.theta - from.theta, to.phi - from.phi];
        // Plain comparisons rather than `f64::max`, whose NaN rule costs instructions here: a
        // NaN angle makes the trig NaN either way.
        let largest = larger(larger(d[0].abs(), d[1].abs()), d[2].abs());
        if largest > SHIFT_MAX_RAD {
            return Self::exact(to);
        }
        // One branch for all three angles, so the common path is straight-line arithmetic.
        let short = largest <= SHIFT_SHORT_MAX_RAD;
        Self {
            psi: shift(self.psi, d[0], short),
            theta: shift(self.theta, d[1], short),
            phi: shift(self.phi, d[2], short),
        }
    }

    /// [`EulerTrig::new`] out of line: the rare fallback of [`EulerTrig::shifted`].
    #[cold]
    #[inline(never)]
    fn exact(e: &Euler) -> Self {
        Self::new(e)
    }

    /// R_B→I = Rz(ψ)·Ry(θ)·Rx(φ), identical to [`Euler::rotation_body_to_inertial`].
    #[inline]
    #[must_use]
    pub fn rotation_body_to_inertial(&self) -> Matrix3<f64> {
        crate::model::frames::rotation_from_sin_cos(self.psi, self.theta, self.phi)
    }

    /// R_B→I v without forming R: the three elementary rotations Rz(ψ)(Ry(θ)(Rx(φ) v)), 12
    /// products instead of the 23 of building R and multiplying. Equal to
    /// `self.rotation_body_to_inertial() * v` up to rounding.
    #[inline]
    #[must_use]
    pub fn rotate_body_to_inertial(&self, v: &Vector3<f64>) -> Vector3<f64> {
        let ((sps, cps), (sth, cth), (sph, cph)) = (self.psi, self.theta, self.phi);
        let (x, y, z) = (v[0], v[1], v[2]);
        // Rx(φ): roll about x_B.
        let (y1, z1) = (cph * y - sph * z, sph * y + cph * z);
        // Ry(θ): pitch about y.
        let (x2, z2) = (cth * x + sth * z1, cth * z1 - sth * x);
        // Rz(ψ): heading about z_I.
        Vector3::new(cps * x2 - sps * y1, sps * x2 + cps * y1, z2)
    }

    /// η̇ = W_n⁻¹ Ω, identical to [`Euler::rates_from_body`].
    #[inline]
    #[must_use]
    pub fn euler_rates(&self, omega_body_rad_s: &Vector3<f64>) -> Vector3<f64> {
        let ((sth, cth), (sph, cph)) = (self.theta, self.phi);
        let (q, r) = (omega_body_rad_s[1], omega_body_rad_s[2]);
        let qr_over_cth = (sph * q + cph * r) / cth;
        Vector3::new(
            qr_over_cth,
            cph * q - sph * r,
            omega_body_rad_s[0] + qr_over_cth * sth,
        )
    }

    /// cos θ cos φ: the cosine of the angle between z_B and the vertical.
    #[must_use]
    pub fn cos_tilt(&self) -> f64 {
        let ((_, cth), (_, cph)) = (self.theta, self.phi);
        cth * cph
    }

    /// Gravity in B per unit mass: Rᵀ (0, 0, −g) = −g (−sθ, sφcθ, cφcθ) ([I3]).
    #[inline]
    #[must_use]
    pub fn gravity_body_m_s2(&self, g_m_s2: f64) -> Vector3<f64> {
        let ((sth, cth), (sph, cph)) = (self.theta, self.phi);
        Vector3::new(g_m_s2 * sth, -g_m_s2 * sph * cth, -g_m_s2 * cph * cth)
    }
}

/// The larger of `a` and `b` (either when one is NaN).
#[inline]
fn larger(a: f64, b: f64) -> f64 {
    if a > b { a } else { b }
}

/// Largest angle increment [`EulerTrig::shifted`] handles by series, rad (the first series
/// terms kept out, δ⁷/7! and δ⁸/8!, are below 2e-18 there).
pub const SHIFT_MAX_RAD: f64 = 0.01;

/// Below this shift the series of [`EulerTrig::shifted`] stops at δ⁴: the omitted terms are
/// under 1e-17.
const SHIFT_SHORT_MAX_RAD: f64 = 1e-3;

/// (sin, cos) of a + δ from (sin a, cos a), for |δ| ≤ [`SHIFT_MAX_RAD`]; `short` when
/// |δ| ≤ [`SHIFT_SHORT_MAX_RAD`]. δ = 0 returns (sin a, cos a) exactly.
#[inline]
fn shift((s, c): (f64, f64), d: f64, short: bool) -> (f64, f64) {
    // Taylor series in Horner form with the reciprocal factorials as constants: a division by
    // a constant that is not a power of two stays a division, and these sit in the RK4 stages.
    // The first omitted terms, δ⁷/7! and δ⁸/8!, are below 2e-18 for |δ| ≤ SHIFT_MAX_RAD.
    const S3: f64 = 1.0 / 6.0;
    const S5: f64 = 1.0 / 120.0;
    const C4: f64 = 1.0 / 24.0;
    const C6: f64 = 1.0 / 720.0;
    let d2 = d * d;
    let (sd, cd) = if short {
        // A stage moves an angle by ω·h/2, a fraction of a mrad: there δ⁵/5! and δ⁶/6! are
        // below 1e-17 and the series ends two terms earlier.
        (d * (1.0 - d2 * S3), 1.0 - d2 * (0.5 - d2 * C4))
    } else {
        (
            d * (1.0 - d2 * (S3 - d2 * S5)),
            1.0 - d2 * (0.5 - d2 * (C4 - d2 * C6)),
        )
    };
    (s * cd + c * sd, c * cd - s * sd)
}

/// The airframe's mass properties in the form the equations of motion use them: reciprocals
/// and inertia differences, computed once (a division per term is the dearest operation of a
/// derivative evaluation, and the vehicle runs four of those per physics step).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RigidBody {
    inv_mass_per_kg: f64,
    gravity_m_s2: f64,
    inv_inertia_per_kg_m2: [f64; 3],
    /// (Iz − Iy, Ix − Iz, Iy − Ix), kg·m².
    inertia_diff_kg_m2: [f64; 3],
}

impl RigidBody {
    /// From Table I.
    #[must_use]
    pub fn new(af: &Airframe) -> Self {
        let [ix, iy, iz] = af.inertia_kg_m2;
        Self {
            inv_mass_per_kg: 1.0 / af.mass_kg,
            gravity_m_s2: af.gravity_m_s2,
            inv_inertia_per_kg_m2: [1.0 / ix, 1.0 / iy, 1.0 / iz],
            inertia_diff_kg_m2: [iz - iy, ix - iz, iy - ix],
        }
    }

    /// Translational acceleration in B: v̇ = −Ω × v + F/m + Rᵀ(0, 0, −g) (1), (7).
    #[inline]
    #[must_use]
    pub fn body_acceleration_m_s2(
        &self,
        trig: &EulerTrig,
        vel_body_m_s: &Vector3<f64>,
        omega_body_rad_s: &Vector3<f64>,
        force_body_n: &Vector3<f64>,
    ) -> Vector3<f64> {
        -omega_body_rad_s.cross(vel_body_m_s)
            + force_body_n * self.inv_mass_per_kg
            + trig.gravity_body_m_s2(self.gravity_m_s2)
    }

    /// Angular acceleration: Ω̇ = I⁻¹ (Γ − Ω × IΩ) (2), (13) with [I13].
    #[inline]
    #[must_use]
    pub fn angular_acceleration_rad_s2(
        &self,
        omega_body_rad_s: &Vector3<f64>,
        torque_body_nm: &Vector3<f64>,
    ) -> Vector3<f64> {
        let [jx, jy, jz] = self.inv_inertia_per_kg_m2;
        let [dx, dy, dz] = self.inertia_diff_kg_m2;
        let (p, q, r) = (
            omega_body_rad_s[0],
            omega_body_rad_s[1],
            omega_body_rad_s[2],
        );
        // Ω × IΩ written out: (qr(Iz − Iy), pr(Ix − Iz), pq(Iy − Ix)).
        Vector3::new(
            (torque_body_nm[0] - q * r * dx) * jx,
            (torque_body_nm[1] - p * r * dy) * jy,
            (torque_body_nm[2] - p * q * dz) * jz,
        )
    }
}

/// Translational acceleration in B: v̇ = −Ω × v + F/m + Rᵀ(0, 0, −g) (1), (7).
#[must_use]
pub fn body_acceleration_m_s2(
    af: &Airframe,
    trig: &EulerTrig,
    vel_body_m_s: &Vector3<f64>,
    omega_body_rad_s: &Vector3<f64>,
    force_body_n: &Vector3<f64>,
) -> Vector3<f64> {
    RigidBody::new(af).body_acceleration_m_s2(trig, vel_body_m_s, omega_body_rad_s, force_body_n)
}

/// Angular acceleration: Ω̇ = I⁻¹ (Γ − Ω × IΩ) (2), (13) with [I13].
#[must_use]
pub fn angular_acceleration_rad_s2(
    af: &Airframe,
    omega_body_rad_s: &Vector3<f64>,
    torque_body_nm: &Vector3<f64>,
) -> Vector3<f64> {
    RigidBody::new(af).angular_acceleration_rad_s2(omega_body_rad_s, torque_body_nm)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn trig_matches_frames() {
        let e = Euler::new(0.9, -0.3, 0.45);
        let t = EulerTrig::new(&e);
        assert!((t.rotation_body_to_inertial() - e.rotation_body_to_inertial()).norm() < 1e-15);
        let w = Vector3::new(0.3, -1.2, 0.7);
        assert!((t.euler_rates(&w) - e.rates_from_body(&w)).norm() < 1e-14);
        let g = t.rotation_body_to_inertial().transpose() * Vector3::new(0.0, 0.0, -9.8);
        assert!((t.gravity_body_m_s2(9.8) - g).norm() < 1e-14);
        let v = Vector3::new(1.5, -0.4, 2.25);
        let rv = t.rotation_body_to_inertial() * v;
        assert!((t.rotate_body_to_inertial(&v) - rv).amax() < 4.0 * f64::EPSILON * rv.amax());
    }

    #[test]
    fn shifted_trig_is_exact_to_rounding() {
        let a = Euler::new(0.9, -0.3, 0.45);
        let t = EulerTrig::new(&a);
        for d in [0.0, 1e-6, -3e-3, 0.0099, 0.05] {
            let b = Euler::new(a.psi + d, a.theta - d, a.phi + 0.5 * d);
            let diff = t.shifted(&a, &b).rotation_body_to_inertial()
                - EulerTrig::new(&b).rotation_body_to_inertial();
            assert!(diff.amax() < 4e-16, "δ = {d}: {diff}");
        }
    }

    #[test]
    fn euler_equation_matches_matrix_form() {
        let af = Airframe::default();
        let i = Matrix3::from_diagonal(&Vector3::from(af.inertia_kg_m2));
        let w = Vector3::new(0.4, -0.9, 1.3);
        let tau = Vector3::new(0.01, -0.02, 0.005);
        let expect = i.try_inverse().unwrap() * (tau - w.cross(&(i * w)));
        assert!((angular_acceleration_rad_s2(&af, &w, &tau) - expect).norm() < 1e-12);
    }
}
