//! Altitude law (37) of `PHYSICS.md` §3 and its thrust conversion [I6], plus the QLAND descent.
//!
//! Frame: inertial, z up. The decoupled loop is z̈ = r_z (s² + a_z1 s + a_z2); the thrust that
//! realises it is f_z = m (r_z + g)/(cos φ cos θ), because (9) gives z̈ = cθ cφ f_z/m − g with the
//! f_x term dropped, as the paper does.

/// Smallest cos φ · cos θ used in the divisor of (37): beyond 60° of tilt the thrust is no longer
/// increased. This keeps f_z finite when the vehicle is far from hover (or inverted, where the
/// product is negative and dividing by it would reverse the thrust).
pub const MIN_TILT_COS: f64 = 0.5;

/// r_z of (37): −a_z1 ż − a_z2 (z − z_d), m/s².
#[must_use]
pub fn altitude_accel_m_s2(kd: f64, kp: f64, z_m: f64, z_dot_m_s: f64, z_setpoint_m: f64) -> f64 {
    -kd * z_dot_m_s - kp * (z_m - z_setpoint_m)
}

/// r_z of (37) with the climb and descent speeds bounded (`physical` mode): written as
/// r_z = a_z1 (v_cmd − ż) with v_cmd = (a_z2/a_z1)(z_d − z), the law (37) is unchanged while
/// v_cmd lies within [−`sink_m_s`, `climb_m_s`], and beyond it the vehicle climbs or sinks at
/// that speed instead of accelerating on a large altitude error (a step of `HOVER_ALT` to 20 m
/// would otherwise ask for 50 m/s and tumble the airframe in its own downwash), as ArduPlane's
/// `Q_PILOT_SPEED_UP`/`_DN` bound the Q modes' climb.
#[must_use]
pub fn altitude_accel_bounded_m_s2(
    kd: f64,
    kp: f64,
    z_m: f64,
    z_dot_m_s: f64,
    z_setpoint_m: f64,
    climb_m_s: f64,
    sink_m_s: f64,
) -> f64 {
    let v_cmd = kp / kd * (z_setpoint_m - z_m);
    if v_cmd > climb_m_s || v_cmd < -sink_m_s {
        kd * (v_cmd.clamp(-sink_m_s, climb_m_s) - z_dot_m_s)
    } else {
        altitude_accel_m_s2(kd, kp, z_m, z_dot_m_s, z_setpoint_m)
    }
}

/// QLAND: the same derivative gain drives ż to −`land_speed_m_s`: r_z = −a_z1 (ż + v_land).
/// The position term is dropped so the descent does not stop at any altitude; the vehicle
/// detects touchdown and disarms.
#[must_use]
pub fn land_accel_m_s2(kd: f64, z_dot_m_s: f64, land_speed_m_s: f64) -> f64 {
    -kd * (z_dot_m_s + land_speed_m_s)
}

/// Thrust f_z = m (r_z + g)/(cos φ cos θ) of (37) with the longitudinal factor of [I6], N.
/// The divisor is floored at [`MIN_TILT_COS`].
#[must_use]
pub fn thrust_n(
    mass_kg: f64,
    gravity_m_s2: f64,
    r_z_m_s2: f64,
    phi_rad: f64,
    theta_rad: f64,
) -> f64 {
    let tilt_cos = (phi_rad.cos() * theta_rad.cos()).max(MIN_TILT_COS);
    mass_kg * (r_z_m_s2 + gravity_m_s2) / tilt_cos
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn law_37_values() {
        // z = 0.1, z_d = 1, ż = 0: r_z = −5·(−0.9) = 4.5.
        assert!((altitude_accel_m_s2(2.0, 5.0, 0.1, 0.0, 1.0) - 4.5).abs() < 1e-12);
        // Rising at 1 m/s at the setpoint: r_z = −2.
        assert!((altitude_accel_m_s2(2.0, 5.0, 1.0, 1.0, 1.0) + 2.0).abs() < 1e-12);
    }

    #[test]
    fn bounded_law_is_37_near_the_setpoint_and_a_speed_far_from_it() {
        // Within the bounds: exactly (37).
        let near = altitude_accel_bounded_m_s2(2.0, 5.0, 0.5, 0.3, 1.0, 2.5, 1.5);
        assert_eq!(near, altitude_accel_m_s2(2.0, 5.0, 0.5, 0.3, 1.0));
        // 19 m below: climb at 2.5 m/s, so r_z vanishes once ż = 2.5.
        assert!(altitude_accel_bounded_m_s2(2.0, 5.0, 1.0, 2.5, 20.0, 2.5, 1.5).abs() < 1e-12);
        // 19 m above: sink at 1.5 m/s.
        assert!(altitude_accel_bounded_m_s2(2.0, 5.0, 20.0, -1.5, 1.0, 2.5, 1.5).abs() < 1e-12);
    }

    #[test]
    fn thrust_compensates_tilt_and_realises_r_z() {
        let (m, g, rz, ph, th) = (0.5, 9.8, 1.3, 0.2, -0.15_f64);
        let fz = thrust_n(m, g, rz, ph, th);
        // (9): z̈ = cθ cφ f_z/m − g must equal r_z.
        assert!((th.cos() * ph.cos() * fz / m - g - rz).abs() < 1e-12);
        // Hover: f_z = mg.
        assert!((thrust_n(m, g, 0.0, 0.0, 0.0) - m * g).abs() < 1e-12);
        // Guarded: tipped over, finite and capped at 2 m (r_z + g).
        let f = thrust_n(m, g, 0.0, std::f64::consts::FRAC_PI_2, 3.0);
        assert!((f - 2.0 * m * g).abs() < 1e-12, "{f}");
    }

    #[test]
    fn land_descends_at_land_speed() {
        assert!(land_accel_m_s2(2.0, 0.0, 0.5) < 0.0);
        assert!(land_accel_m_s2(2.0, -0.5, 0.5).abs() < 1e-15);
        assert!(land_accel_m_s2(2.0, -1.0, 0.5) > 0.0);
    }
}
