//! The lateral (y–φ) and longitudinal (x–θ) position chains of `PHYSICS.md` §3, the heading-frame
//! rotation of `physical` mode (§0), f_x of (43), and the attitude-hold laws of the pilot modes.
//!
//! Frames: positions and velocities are inertial (z up). Sign derivation from the inertial form
//! (9) with fy = 0 and f_z ≈ mg, small angles:
//! * ÿ ∋ (−cψ sφ + sψ sθ cφ) f_z/m → at ψ = 0, ÿ = −g φ (38). With X̄ = −y/g, X̄″ = φ,
//!   X̄‴ = φ̇ and X̄⁽⁴⁾ = τ̃φ, so τ̃φ = chain(−y/g, −ẏ/g, φ, φ̇), which expands to
//!   −σa(φ̇) − σb(φ̇+φ) − σc(φ̇+2φ−ẏ/g) − σd(φ̇+3φ−(3ẏ+y)/g) ([I7]).
//! * ẍ ∋ cψ cθ f_x/m + cψ sθ cφ f_z/m. `paper`: f_x of (43) makes ẍ = θ (44), X = x.
//!   `physical`: f_x = 0 and ẍ = gθ, X̄ = x/g ([I16]), the mirror of the lateral chain.
//! * Heading frame (`physical` only): rotating (9) by Rz(−ψ) gives exactly
//!   ẍ_h = sθ cφ f_z/m and ÿ_h = −sφ f_z/m for every ψ, so the chains above hold in the heading
//!   frame without the yaw coupling the paper's design neglects. At ψ = 0 it is the paper's law.
//!
//! Here y and x are always position ERRORS (y − y_d, x − x_d): the chains regulate to zero.

use nalgebra::Vector2;

use super::SaturationLevels;
use super::saturation::{attitude_law, chain_law};
use crate::model::airframe::ModelMode;

/// Largest |θ| used in the f_x formula (43): keeps 1/cos θ finite. The paper's loop never gets
/// near it (its own x loop reverses sign beyond 0.464 rad, `PHYSICS.md` §0).
pub const FX_TILT_LIMIT_RAD: f64 = 1.2;

/// Lateral chain (38)–(39) in its normalised form [I7]: τ̃φ in rad/s², |τ̃φ| ≤ a + b + c + d.
///
/// `y_err_m` = y − y_d, `y_dot_m_s` = ẏ (in the heading frame in `physical` mode), `phi_rad` and
/// `phi_dot_rad_s` the roll angle and its Euler rate.
#[must_use]
pub fn lateral_tau(
    levels: &SaturationLevels,
    gravity_m_s2: f64,
    y_err_m: f64,
    y_dot_m_s: f64,
    phi_rad: f64,
    phi_dot_rad_s: f64,
) -> f64 {
    let g = gravity_m_s2;
    chain_law(
        levels,
        [-y_err_m / g, -y_dot_m_s / g, phi_rad, phi_dot_rad_s],
    )
}

/// Longitudinal chain (40)–(44): τ̃θ in rad/s², |τ̃θ| ≤ a + b + c + d.
///
/// `paper`: ẍ = θ, τ̃θ = −σa(θ̇) − σb(θ̇+θ) − σc(θ̇+2θ+ẋ) − σd(θ̇+3θ+3ẋ+x).
/// `physical`: ẍ = gθ, τ̃θ = −σa(θ̇) − σb(θ̇+θ) − σc(θ̇+2θ+ẋ/g) − σd(θ̇+3θ+(3ẋ+x)/g).
#[must_use]
pub fn longitudinal_tau(
    levels: &SaturationLevels,
    model: ModelMode,
    gravity_m_s2: f64,
    x_err_m: f64,
    x_dot_m_s: f64,
    theta_rad: f64,
    theta_dot_rad_s: f64,
) -> f64 {
    let scale = match model {
        ModelMode::Paper => 1.0,
        ModelMode::Physical => 1.0 / gravity_m_s2,
    };
    chain_law(
        levels,
        [
            x_err_m * scale,
            x_dot_m_s * scale,
            theta_rad,
            theta_dot_rad_s,
        ],
    )
}

/// f_x of (43) with the mass restored ([I8]): f_x = m (θ − g sin θ)/cos θ, N. Applied as an
/// independent body force in `paper` mode only; with f_z = mg it makes ẍ = θ exactly.
/// θ is clamped to ±[`FX_TILT_LIMIT_RAD`] so the output stays finite.
#[must_use]
pub fn paper_fx_n(mass_kg: f64, gravity_m_s2: f64, theta_rad: f64) -> f64 {
    let th = theta_rad.clamp(-FX_TILT_LIMIT_RAD, FX_TILT_LIMIT_RAD);
    mass_kg * (th - gravity_m_s2 * th.sin()) / th.cos()
}

/// Rotates an inertial horizontal vector (x, y) into the heading frame: Rz(−ψ)·v.
#[must_use]
pub fn to_heading_frame(psi_rad: f64, v: Vector2<f64>) -> Vector2<f64> {
    let (s, c) = psi_rad.sin_cos();
    Vector2::new(c * v.x + s * v.y, -s * v.x + c * v.y)
}

/// Attitude hold for one axis (pilot modes): the inner two terms of the chain with time scale
/// `bandwidth_rad_s`, driving `angle_rad` to `setpoint_rad`. Bounded by a + b.
#[must_use]
pub fn attitude_hold_tau(
    levels: &SaturationLevels,
    bandwidth_rad_s: f64,
    angle_rad: f64,
    setpoint_rad: f64,
    rate_rad_s: f64,
) -> f64 {
    attitude_law(
        levels,
        bandwidth_rad_s,
        angle_rad - setpoint_rad,
        rate_rad_s,
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    const L: SaturationLevels = SaturationLevels::DEFAULT;
    const G: f64 = 9.8;

    #[test]
    fn lateral_expands_to_the_normalised_form() {
        let (y, yd, ph, phd) = (0.05, -0.02, 0.01, 0.003);
        let s = |v: f64, e: f64| v.clamp(-e, e);
        let expect = -s(phd, L.a)
            - s(phd + ph, L.b)
            - s(phd + 2.0 * ph - yd / G, L.c)
            - s(phd + 3.0 * ph - (3.0 * yd + y) / G, L.d);
        assert!((lateral_tau(&L, G, y, yd, ph, phd) - expect).abs() < 1e-15);
    }

    #[test]
    fn longitudinal_expands_per_model() {
        let (x, xd, th, thd) = (0.05, -0.02, 0.01, 0.003);
        let s = |v: f64, e: f64| v.clamp(-e, e);
        let paper = -s(thd, L.a)
            - s(thd + th, L.b)
            - s(thd + 2.0 * th + xd, L.c)
            - s(thd + 3.0 * th + 3.0 * xd + x, L.d);
        let phys = -s(thd, L.a)
            - s(thd + th, L.b)
            - s(thd + 2.0 * th + xd / G, L.c)
            - s(thd + 3.0 * th + (3.0 * xd + x) / G, L.d);
        assert!((longitudinal_tau(&L, ModelMode::Paper, G, x, xd, th, thd) - paper).abs() < 1e-15);
        assert!(
            (longitudinal_tau(&L, ModelMode::Physical, G, x, xd, th, thd) - phys).abs() < 1e-15
        );
    }

    /// The vehicle right of the setpoint (y > 0) must roll so as to accelerate toward −y:
    /// ÿ = −gφ, so it must command φ̈ > 0 at rest. Ahead of it (x > 0) it must pitch to θ < 0.
    #[test]
    fn chains_push_back_toward_the_setpoint() {
        assert!(lateral_tau(&L, G, 0.5, 0.0, 0.0, 0.0) > 0.0);
        assert!(lateral_tau(&L, G, -0.5, 0.0, 0.0, 0.0) < 0.0);
        for m in [ModelMode::Paper, ModelMode::Physical] {
            assert!(longitudinal_tau(&L, m, G, 0.5, 0.0, 0.0, 0.0) < 0.0);
            assert!(longitudinal_tau(&L, m, G, -0.5, 0.0, 0.0, 0.0) > 0.0);
        }
    }

    #[test]
    fn fx_43_gives_x_ddot_equal_theta_at_hover_thrust() {
        let (m, th) = (0.5, 0.2_f64);
        let fx = paper_fx_n(m, G, th);
        // (9) at ψ = φ = 0 with f_z = mg: ẍ = cθ fx/m + sθ g.
        let xdd = th.cos() * fx / m + th.sin() * G;
        assert!((xdd - th).abs() < 1e-12, "{xdd}");
        assert!(paper_fx_n(m, G, std::f64::consts::FRAC_PI_2).is_finite());
    }

    #[test]
    fn heading_frame_rotation() {
        let v = to_heading_frame(std::f64::consts::FRAC_PI_2, Vector2::new(1.0, 0.0));
        // Heading along +y: an inertial +x offset is to the heading frame's −y (right-handed).
        assert!((v - Vector2::new(0.0, -1.0)).norm() < 1e-15);
        let v = to_heading_frame(0.0, Vector2::new(0.3, -0.2));
        assert_eq!(v, Vector2::new(0.3, -0.2));
    }
}
