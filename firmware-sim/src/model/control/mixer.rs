//! Actuator mapping of `PHYSICS.md` §5: from the commanded thrust f_z and body torques
//! Γc = (Γx, Γy, Γz) of (33) to rotor speeds, surface deflections and PWM pulse widths.
//!
//! Body frame (§1): rotor 1 and the right aileron at y = +l, rotor 2 and the left aileron at
//! y = −l; Γx = l_r (T1 − T2) (10); Γy = l_e L_e with the elevator below the CG [I15];
//! Γz = l_a (L_aL − L_aR) with signed lifts [I14]. The aileron behind rotor i sits in its
//! prop-wash υ_i = k_υ ω_i; the elevator spans both slipstreams (υ_e² = (υ1² + υ2²)/2).
//!
//! `paper` mode: actuators are ideal [I18], so nothing is limited except T ≥ 0 (a rotor cannot
//! push). `physical` mode: |Γx| ≤ l_r f_z (collective priority, so neither rotor is asked for
//! negative thrust and f_z is kept), ω ≤ ω_max and |δ| ≤ the surface limit. PWM is always
//! rounded and clamped to 1000–2000 µs.

use nalgebra::Vector3;

use crate::model::airframe::{Airframe, ModelMode};
use crate::model::signals::{ActuatorCommand, PwmOutputs};

/// Below this prop-wash (υ1² + υ2², m²/s²) the surfaces have no authority: they are left
/// neutral rather than commanded to a huge deflection (rotors stopped, e.g. on the ground).
pub const MIN_WASH_SQ_M2_S2: f64 = 0.01;

/// Rotor speeds (ω1, ω2), rad/s, that produce thrust f_z and roll torque Γx (§5 steps 1–2).
#[must_use]
pub fn rotor_speeds_rad_s(
    airframe: &Airframe,
    model: ModelMode,
    fz_n: f64,
    gx_nm: f64,
) -> [f64; 2] {
    let lr = airframe.rotor_arm_m;
    let gx = match model {
        ModelMode::Paper => gx_nm,
        // Collective priority: with |Γx| ≤ l_r f_z both thrusts stay in [0, f_z].
        ModelMode::Physical => {
            let lim = lr * fz_n.max(0.0);
            gx_nm.min(lim).max(-lim)
        }
    };
    let t1 = (0.5 * fz_n + gx / (2.0 * lr)).max(0.0);
    let t2 = (0.5 * fz_n - gx / (2.0 * lr)).max(0.0);
    let kt = airframe.k_thrust_n_per_rad2_s2;
    let w = [(t1 / kt).sqrt(), (t2 / kt).sqrt()];
    match model {
        ModelMode::Paper => w,
        ModelMode::Physical => w.map(|wi| wi.min(airframe.rotor_speed_max_rad_s)),
    }
}

/// Surface deflections (δ_e, δ_L, δ_R), rad, that produce Γy and Γz at the given rotor speeds
/// (§5 steps 3–5).
#[must_use]
pub fn surface_deflections_rad(
    airframe: &Airframe,
    model: ModelMode,
    rotor_speed_rad_s: [f64; 2],
    gy_nm: f64,
    gz_nm: f64,
) -> [f64; 3] {
    let kv = airframe.k_wash_m_per_rad;
    let v1_sq = (kv * rotor_speed_rad_s[0]).powi(2);
    let v2_sq = (kv * rotor_speed_rad_s[1]).powi(2);
    let sum_sq = v1_sq + v2_sq;
    if sum_sq.is_nan() || sum_sq < MIN_WASH_SQ_M2_S2 {
        return [0.0; 3];
    }
    let cl = airframe.lift_slope_per_rad;
    let de = gy_nm / (airframe.elevator_arm_m * airframe.k_elevator_kg_m * cl * 0.5 * sum_sq);
    let da = gz_nm / (airframe.aileron_arm_m * airframe.k_aileron_kg_m * cl * sum_sq);
    let d = [de, da, -da];
    match model {
        ModelMode::Paper => d,
        ModelMode::Physical => {
            let lim = airframe.surface_limit_rad;
            d.map(|x| x.min(lim).max(-lim))
        }
    }
}

/// The whole mixer: f_z and Γc to an [`ActuatorCommand`].
#[must_use]
pub fn mix(
    airframe: &Airframe,
    model: ModelMode,
    fz_n: f64,
    torque_nm: &Vector3<f64>,
) -> ActuatorCommand {
    let w = rotor_speeds_rad_s(airframe, model, fz_n, torque_nm.x);
    let [de, dl, dr] = surface_deflections_rad(airframe, model, w, torque_nm.y, torque_nm.z);
    ActuatorCommand {
        rotor_speed_rad_s: w,
        elevator_rad: de,
        aileron_left_rad: dl,
        aileron_right_rad: dr,
    }
}

/// PWM pulse widths (§5 step 6), µs, in the order [ESC1, ESC2, aileron L, aileron R, elevator].
/// ESC = 1000 + 1000 ω/ω_max, servo = 1500 + 500 δ/throw; rounded and clamped to 1000–2000.
#[must_use]
pub fn pwm_us(airframe: &Airframe, cmd: &ActuatorCommand) -> PwmOutputs {
    pwm_us_dithered(airframe, cmd, &mut [0.0; 5])
}

/// Exact (unrounded) pulse widths, µs, in the order of [`pwm_us`].
fn pwm_exact_us(airframe: &Airframe, cmd: &ActuatorCommand) -> [f64; 5] {
    let esc = |w: f64| 1000.0 + 1000.0 * w / airframe.rotor_speed_max_rad_s;
    let servo = |d: f64| 1500.0 + 500.0 * d / airframe.servo_throw_rad;
    [
        esc(cmd.rotor_speed_rad_s[0]),
        esc(cmd.rotor_speed_rad_s[1]),
        servo(cmd.aileron_left_rad),
        servo(cmd.aileron_right_rad),
        servo(cmd.elevator_rad),
    ]
}

/// [`pwm_us`] with error diffusion: each channel's rounding error is carried into the next
/// tick through `residual_us`, so the average pulse equals the exact command. One microsecond
/// of elevator is about 1 mrad, ≈ 0.04 rad/s² of pitch: rounded plainly, that step holds the
/// x chain in a ±9 cm limit cycle with ideal sensors; dithered, the servo lag averages it out.
#[must_use]
pub fn pwm_us_dithered(
    airframe: &Airframe,
    cmd: &ActuatorCommand,
    residual_us: &mut [f64; 5],
) -> PwmOutputs {
    let exact = pwm_exact_us(airframe, cmd);
    let mut out = [1000u16; 5];
    for ((o, e), r) in out.iter_mut().zip(exact).zip(residual_us.iter_mut()) {
        if !e.is_finite() {
            *r = 0.0;
            continue;
        }
        let wanted = e + *r;
        let us = wanted.round().clamp(1000.0, 2000.0);
        // At the range limits the error cannot be paid back; keep it bounded.
        *r = (wanted - us).clamp(-0.5, 0.5);
        // Exact: a whole number within 1000..=2000.
        *o = us as u16;
    }
    out
}

/// What an [`ActuatorCommand`] produces on the plant, by the §5 force and torque model (drag
/// coefficients zero): (f_z, Γc, f_x of the surfaces). The inverse of [`mix`] when nothing
/// saturates; the plant implements the same formulas.
#[must_use]
pub fn forces_from_actuators(
    airframe: &Airframe,
    cmd: &ActuatorCommand,
) -> (f64, Vector3<f64>, f64) {
    let kt = airframe.k_thrust_n_per_rad2_s2;
    let [w1, w2] = cmd.rotor_speed_rad_s;
    let (t1, t2) = (kt * w1 * w1, kt * w2 * w2);
    let kv = airframe.k_wash_m_per_rad;
    let (v1_sq, v2_sq) = ((kv * w1).powi(2), (kv * w2).powi(2));
    let cl = airframe.lift_slope_per_rad;
    let lift_e = airframe.k_elevator_kg_m * 0.5 * (v1_sq + v2_sq) * cl * cmd.elevator_rad;
    // Left aileron behind rotor 2, right aileron behind rotor 1.
    let lift_l = airframe.k_aileron_kg_m * v2_sq * cl * cmd.aileron_left_rad;
    let lift_r = airframe.k_aileron_kg_m * v1_sq * cl * cmd.aileron_right_rad;
    let torque = Vector3::new(
        airframe.rotor_arm_m * (t1 - t2),
        airframe.elevator_arm_m * lift_e,
        airframe.aileron_arm_m * (lift_l - lift_r),
    );
    (t1 + t2, torque, lift_l + lift_r - lift_e)
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;
    use proptest::test_runner::{Config as ProptestConfig, RngSeed};

    #[test]
    fn hover_is_1681_us_and_neutral() {
        let a = Airframe::default();
        let cmd = mix(&a, ModelMode::Physical, a.weight_n(), &Vector3::zeros());
        let pwm = pwm_us(&a, &cmd);
        assert_eq!(pwm, [1681, 1681, 1500, 1500, 1500]);
    }

    #[test]
    fn positive_roll_torque_speeds_up_rotor_one() {
        let a = Airframe::default();
        let cmd = mix(
            &a,
            ModelMode::Physical,
            a.weight_n(),
            &Vector3::new(0.1, 0.0, 0.0),
        );
        assert!(cmd.rotor_speed_rad_s[0] > cmd.rotor_speed_rad_s[1]);
    }

    #[test]
    fn stopped_rotors_leave_surfaces_neutral() {
        let a = Airframe::default();
        for m in [ModelMode::Paper, ModelMode::Physical] {
            let cmd = mix(&a, m, 0.0, &Vector3::new(0.0, 0.3, -0.2));
            assert_eq!(cmd.elevator_rad, 0.0);
            assert_eq!(cmd.aileron_left_rad, 0.0);
            assert_eq!(cmd.aileron_right_rad, 0.0);
            assert_eq!(pwm_us(&a, &cmd), [1000, 1000, 1500, 1500, 1500]);
        }
    }

    #[test]
    fn physical_limits_apply_and_paper_does_not() {
        let a = Airframe::default();
        let big = Vector3::new(1.0, 5.0, 5.0);
        let p = mix(&a, ModelMode::Physical, 20.0, &big);
        assert!(
            p.rotor_speed_rad_s
                .iter()
                .all(|w| *w <= a.rotor_speed_max_rad_s)
        );
        for d in [p.elevator_rad, p.aileron_left_rad, p.aileron_right_rad] {
            assert!(d.abs() <= a.surface_limit_rad);
        }
        let q = mix(&a, ModelMode::Paper, 20.0, &big);
        assert!(q.rotor_speed_rad_s[0] > a.rotor_speed_max_rad_s);
        let (fz, tq, _) = forces_from_actuators(&a, &q);
        assert!(
            (fz - 20.0).abs() < 1e-9 && (tq - big).norm() < 1e-9,
            "{fz} {tq}"
        );
        assert!(pwm_us(&a, &q).iter().all(|p| (1000..=2000).contains(p)));
    }

    #[test]
    fn physical_collective_priority_keeps_thrust() {
        let a = Airframe::default();
        let cmd = mix(&a, ModelMode::Physical, 2.0, &Vector3::new(1.0, 0.0, 0.0));
        let (fz, tq, _) = forces_from_actuators(&a, &cmd);
        assert!((fz - 2.0).abs() < 1e-12);
        assert!((tq.x - a.rotor_arm_m * 2.0).abs() < 1e-12);
    }

    proptest! {
        #![proptest_config(ProptestConfig {
            cases: 256,
            rng_seed: RngSeed::Fixed(0x000B_1E4D),
            failure_persistence: None,
            ..ProptestConfig::default()
        })]

        /// Unsaturated requests come back exactly through the §5 force model, in both modes;
        /// a pure differential aileron deflection adds no net f_x (the couple of [I14]) when
        /// the two slipstreams are equal.
        #[test]
        fn mixer_inverts_the_force_model(
            fz in 2.0..9.0f64,
            gx in -0.2..0.2f64,
            gy in -0.1..0.1f64,
            gz in -0.1..0.1f64,
        ) {
            let a = Airframe::default();
            let req = Vector3::new(gx, gy, gz);
            for m in [ModelMode::Paper, ModelMode::Physical] {
                let cmd = mix(&a, m, fz, &req);
                let (fz_back, tq_back, _) = forces_from_actuators(&a, &cmd);
                prop_assert!((fz_back - fz).abs() < 1e-9, "{m:?} fz {fz_back} vs {fz}");
                prop_assert!((tq_back - req).norm() < 1e-9, "{m:?} {tq_back} vs {req}");
            }
            let cmd = mix(&a, ModelMode::Paper, fz, &Vector3::new(0.0, 0.0, gz));
            let (_, _, fx) = forces_from_actuators(&a, &cmd);
            prop_assert!(fx.abs() < 1e-12);
        }

        /// PWM stays in 1000–2000 µs for any finite command, in both modes.
        #[test]
        fn pwm_always_in_range(
            fz in -1e6..1e6f64,
            t in proptest::array::uniform3(-1e6..1e6f64),
        ) {
            let a = Airframe::default();
            for m in [ModelMode::Paper, ModelMode::Physical] {
                let cmd = mix(&a, m, fz, &Vector3::from(t));
                let pwm = pwm_us(&a, &cmd);
                prop_assert!(pwm.iter().all(|p| (1000..=2000).contains(p)), "{pwm:?}");
                prop_assert!(cmd.rotor_speed_rad_s.iter().all(|w| w.is_finite() && *w >= 0.0));
                prop_assert!(cmd.elevator_rad.is_finite() && cmd.aileron_left_rad.is_finite());
            }
        }
    }
}
