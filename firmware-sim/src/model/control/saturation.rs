//! The nested-saturation building blocks of `PHYSICS.md` §3 as pure functions: the saturation
//! σ_η of (28) and the four-integrator chain law (26)–(27).
//!
//! The chain is written for a generic state (X, X′, X″, X‴) of X⁽⁴⁾ = u. The lateral and
//! longitudinal laws (`chains.rs`) only decide which physical quantities play the role of X and
//! its derivatives ([I7], [I16]); the saturation logic lives here once, so the tests of the
//! convergence proof's hypotheses exercise exactly the code that flies.

use super::SaturationLevels;

/// σ_η(s) = clip(s, −η, η) of (28). A NaN argument gives 0 (no command) rather than
/// propagating: the firmware must never emit NaN, and 0 is the only neutral choice.
#[must_use]
pub fn sigma(s: f64, eta: f64) -> f64 {
    if s.is_nan() {
        return 0.0;
    }
    // `max`/`min` instead of `clamp`: clamp panics when the bounds are NaN or crossed, and a
    // level is validated elsewhere (`SaturationLevels::validate`), not here.
    s.min(eta).max(-eta)
}

/// The coordinates z1…z4 of (26) for the state `x = [X, X′, X″, X‴]`:
/// z1 = X‴, z2 = z1 + X″, z3 = z2 + X″ + X′, z4 = z3 + X″ + 2X′ + X.
#[must_use]
pub fn chain_coordinates(x: [f64; 4]) -> [f64; 4] {
    let [x0, x1, x2, x3] = x;
    let z1 = x3;
    let z2 = z1 + x2;
    let z3 = z2 + x2 + x1;
    let z4 = z3 + x2 + 2.0 * x1 + x0;
    [z1, z2, z3, z4]
}

/// The chain law (27): u = −σa(z1) − σb(z2) − σc(z3) − σd(z4) for X⁽⁴⁾ = u, with
/// `x = [X, X′, X″, X‴]`. |u| ≤ a + b + c + d always; in the linear region (every |z_i| below
/// its level) u = −(4X‴ + 6X″ + 4X′ + X), i.e. all four poles at −1.
#[must_use]
pub fn chain_law(levels: &SaturationLevels, x: [f64; 4]) -> f64 {
    let [z1, z2, z3, z4] = chain_coordinates(x);
    -sigma(z1, levels.a) - sigma(z2, levels.b) - sigma(z3, levels.c) - sigma(z4, levels.d)
}

/// The inner (attitude) part of a chain, used by the attitude-hold modes: for the double
/// integrator ë = τ̃ with e the attitude error,
/// τ̃ = −σa(λ ė) − σb(λ ė + λ² e).
///
/// With λ = 1 this is the first two terms of (27) with X″ = e, X‴ = ė. The time scale λ (rad/s)
/// moves both poles to −λ in the linear region ((s + λ)²) while keeping the same bounds a and b,
/// so the pilot modes respect the same torque budget as the position chains. a > b is the
/// two-integrator form of the proof's hypotheses and is implied by a valid level set.
#[must_use]
pub fn attitude_law(levels: &SaturationLevels, bandwidth_rad_s: f64, e: f64, e_dot: f64) -> f64 {
    let l = bandwidth_rad_s;
    -sigma(l * e_dot, levels.a) - sigma(l * e_dot + l * l * e, levels.b)
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;
    use proptest::test_runner::{Config as ProptestConfig, RngSeed};

    const L: SaturationLevels = SaturationLevels::DEFAULT;

    fn config(cases: u32) -> ProptestConfig {
        ProptestConfig {
            cases,
            rng_seed: RngSeed::Fixed(0x00C0_FFEE),
            failure_persistence: None,
            ..ProptestConfig::default()
        }
    }

    #[test]
    fn sigma_values_and_saturation() {
        assert_eq!(sigma(0.3, 1.0), 0.3);
        assert_eq!(sigma(-0.3, 1.0), -0.3);
        assert_eq!(sigma(2.5, 1.0), 1.0);
        assert_eq!(sigma(-2.5, 1.0), -1.0);
        assert_eq!(sigma(1.0, 1.0), 1.0);
        assert_eq!(sigma(f64::INFINITY, 0.2), 0.2);
        assert_eq!(sigma(f64::NEG_INFINITY, 0.2), -0.2);
        assert_eq!(sigma(f64::NAN, 0.2), 0.0);
    }

    #[test]
    fn chain_coordinates_match_26() {
        let z = chain_coordinates([1.0, 2.0, 3.0, 4.0]);
        // z1 = 4, z2 = 4 + 3, z3 = 7 + 3 + 2, z4 = 12 + 3 + 4 + 1.
        assert_eq!(z, [4.0, 7.0, 12.0, 20.0]);
    }

    #[test]
    fn chain_law_saturated_values() {
        // Every z_i huge and positive: u = −(a + b + c + d).
        let u = chain_law(&L, [100.0, 100.0, 100.0, 100.0]);
        assert!((u + (1.2 + 0.6 + 0.22 + 0.18)).abs() < 1e-15, "{u}");
        let u = chain_law(&L, [-100.0, -100.0, -100.0, -100.0]);
        assert!((u - 2.2).abs() < 1e-15, "{u}");
        // Only z4 saturated: X large, derivatives zero → u = −d.
        let u = chain_law(&L, [5.0, 0.0, 0.0, 0.0]);
        assert!((u + 0.18).abs() < 1e-15, "{u}");
        // X‴ = 1: z1 = 1 (< a, linear), z2..z4 = 1 (b saturates at 0.6 ... no: 1 > 0.6).
        let u = chain_law(&L, [0.0, 0.0, 0.0, 1.0]);
        assert!((u + (1.0 + 0.6 + 0.22 + 0.18)).abs() < 1e-15, "{u}");
    }

    #[test]
    fn chain_law_linear_region_is_s_plus_one_to_the_fourth() {
        let x = [0.01, -0.02, 0.015, 0.005];
        let u = chain_law(&L, x);
        let lin = -(4.0 * x[3] + 6.0 * x[2] + 4.0 * x[1] + x[0]);
        assert!((u - lin).abs() < 1e-15, "{u} vs {lin}");
    }

    #[test]
    fn attitude_law_linear_and_bounds() {
        let (e, ed) = (0.01, -0.02);
        let tau = attitude_law(&L, 2.0, e, ed);
        assert!((tau - (-(2.0 * 2.0 * ed) - 4.0 * e)).abs() < 1e-15, "{tau}");
        assert!((attitude_law(&L, 2.0, 10.0, 10.0) + 1.8).abs() < 1e-15);
    }

    /// Integrates X⁽⁴⁾ = chain_law(X) with classic RK4.
    fn simulate_chain(levels: &SaturationLevels, mut x: [f64; 4], t_end_s: f64) -> [f64; 4] {
        let f = |s: [f64; 4]| [s[1], s[2], s[3], chain_law(levels, s)];
        let h = 0.005;
        let steps = (t_end_s / h).round() as usize;
        for _ in 0..steps {
            let k1 = f(x);
            let k2 = f(std::array::from_fn(|i| x[i] + 0.5 * h * k1[i]));
            let k3 = f(std::array::from_fn(|i| x[i] + 0.5 * h * k2[i]));
            let k4 = f(std::array::from_fn(|i| x[i] + h * k3[i]));
            x = std::array::from_fn(|i| {
                x[i] + h / 6.0 * (k1[i] + 2.0 * k2[i] + 2.0 * k3[i] + k4[i])
            });
        }
        x
    }

    #[test]
    fn chain_from_paper_like_state_converges() {
        let x = simulate_chain(&L, [0.1, 0.0, 0.1, 0.0], 60.0);
        assert!(x.iter().all(|v| v.abs() < 1e-6), "{x:?}");
    }

    proptest! {
        #![proptest_config(config(48))]

        /// The chain of four integrators under (27) converges to the origin from random initial
        /// states, for the defaults (from a box of ±3 in X) and for random level sets satisfying
        /// the proof's hypotheses. In a saturated phase X′ moves at about d, so the time to
        /// converge grows like |X|/d: the random-level starts are scaled by d to keep 120 s
        /// enough.
        #[test]
        fn chain_converges_from_random_states(
            x in proptest::array::uniform4(-1.0..1.0f64),
            d in 0.05..0.3f64,
            c_over in 0.01..0.2f64,
            b_over in 0.01..0.5f64,
            a_over in 0.01..1.0f64,
        ) {
            let x_default = [3.0 * x[0], x[1], 0.5 * x[2], 0.5 * x[3]];
            let end = simulate_chain(&L, x_default, 80.0);
            prop_assert!(end.iter().all(|v| v.abs() < 1e-3), "defaults from {x_default:?}: {end:?}");
            let c = d + c_over;
            let b = c + d + b_over;
            let a = b + c + d + a_over;
            let levels = SaturationLevels { a, b, c, d };
            prop_assume!(levels.validate("TEST").is_ok());
            let x_scaled = [20.0 * d * x[0], 5.0 * d * x[1], d * x[2], d * x[3]];
            let end = simulate_chain(&levels, x_scaled, 120.0);
            prop_assert!(end.iter().all(|v| v.abs() < 1e-3), "{levels:?} from {x_scaled:?}: {end:?}");
        }

        /// |u| never exceeds a + b + c + d, and the law equals its linear form whenever every
        /// z_i is inside its level.
        #[test]
        fn chain_bounded_and_linear_inside(
            x in proptest::array::uniform4(-1e6..1e6f64),
            s in -0.05..0.05f64,
        ) {
            let u = chain_law(&L, x);
            prop_assert!(u.is_finite() && u.abs() <= 2.2 + 1e-12);
            let small = x.map(|v| v * 1e-9 + s * 0.1);
            let z = chain_coordinates(small);
            prop_assume!(z[0].abs() < L.a && z[1].abs() < L.b && z[2].abs() < L.c && z[3].abs() < L.d);
            let lin = -(4.0 * small[3] + 6.0 * small[2] + 4.0 * small[1] + small[0]);
            prop_assert!((chain_law(&L, small) - lin).abs() < 1e-12);
        }
    }
}
