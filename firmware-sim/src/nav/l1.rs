//! L1 lateral guidance for the fixed-wing legs (Park, Deyst & How 2004, as ArduPilot's
//! `AP_L1_Control`): a lateral acceleration that steers the ground track onto the line from A to
//! B, or around a circle, turned into a bank for the forward-flight law.
//!
//! Frame: local NED, horizontal components only. A positive acceleration (and bank) turns to
//! the right (clockwise seen from above), as ArduPilot's roll.

use nalgebra::Vector2;

/// Groundspeed below which the geometry uses this instead, m/s.
const SPEED_FLOOR_M_S: f64 = 1.0;

/// The L1 tuning (`NAVL1_PERIOD`, `NAVL1_DAMPING`).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct L1Params {
    /// Period of the track's response, s.
    pub period_s: f64,
    /// Damping ratio.
    pub damping: f64,
}

impl L1Params {
    /// L1 distance for this groundspeed: damping · period · V / π, m.
    #[must_use]
    pub fn distance_m(&self, groundspeed_m_s: f64) -> f64 {
        (self.damping * self.period_s * groundspeed_m_s / std::f64::consts::PI).max(0.1)
    }

    fn gain(&self) -> f64 {
        4.0 * self.damping * self.damping
    }
}

/// Lateral acceleration (m/s², positive right) that follows the line A → B.
#[must_use]
pub fn track_accel(
    p: &L1Params,
    pos: &Vector2<f64>,
    vel: &Vector2<f64>,
    a: &Vector2<f64>,
    b: &Vector2<f64>,
) -> f64 {
    let speed = vel.norm().max(SPEED_FLOOR_M_S);
    let l1 = p.distance_m(speed);
    let ab = b - a;
    let ab = if ab.norm() < 1e-6 {
        // A degenerate line: head for B.
        return heading_accel(p, vel, &(b - pos));
    } else {
        ab / ab.norm()
    };
    let a_air = pos - a;
    let cross = |u: &Vector2<f64>, v: &Vector2<f64>| u.x * v.y - u.y * v.x;
    let along = a_air.dot(&ab);
    let nu = if a_air.norm() > l1 && along < 0.0 {
        // Behind A and farther than L1: head for A first.
        let to_a = -a_air;
        cross(vel, &to_a).atan2(vel.dot(&to_a))
    } else {
        let xtrack = cross(&a_air, &ab);
        let nu2 = cross(vel, &ab).atan2(vel.dot(&ab));
        let nu1 = (xtrack / l1)
            .clamp(
                -std::f64::consts::FRAC_1_SQRT_2,
                std::f64::consts::FRAC_1_SQRT_2,
            )
            .asin();
        nu1 + nu2
    };
    let nu = nu.clamp(-std::f64::consts::FRAC_PI_2, std::f64::consts::FRAC_PI_2);
    p.gain() * speed * speed / l1 * nu.sin()
}

/// Lateral acceleration that turns the velocity toward `direction`.
fn heading_accel(p: &L1Params, vel: &Vector2<f64>, direction: &Vector2<f64>) -> f64 {
    let speed = vel.norm().max(SPEED_FLOOR_M_S);
    let l1 = p.distance_m(speed);
    let cross = vel.x * direction.y - vel.y * direction.x;
    let nu = cross
        .atan2(vel.dot(direction))
        .clamp(-std::f64::consts::FRAC_PI_2, std::f64::consts::FRAC_PI_2);
    p.gain() * speed * speed / l1 * nu.sin()
}

/// Lateral acceleration that circles `centre` clockwise at `radius_m`: the centripetal V²/R plus
/// a proportional-derivative correction of the radial error, or L1 toward the circle from
/// outside its capture distance.
#[must_use]
pub fn loiter_accel(
    p: &L1Params,
    pos: &Vector2<f64>,
    vel: &Vector2<f64>,
    centre: &Vector2<f64>,
    radius_m: f64,
) -> f64 {
    let speed = vel.norm().max(SPEED_FLOOR_M_S);
    let l1 = p.distance_m(speed);
    let out = pos - centre;
    let dist = out.norm();
    if dist > radius_m + l1 {
        return heading_accel(p, vel, &(centre - pos));
    }
    let radial = if dist > 1e-6 {
        out / dist
    } else {
        Vector2::new(1.0, 0.0)
    };
    let omega = 2.0 * std::f64::consts::PI / p.period_s;
    let kx = omega * omega;
    let kv = 2.0 * p.damping * omega;
    let radial_speed = vel.dot(&radial);
    speed * speed / radius_m.max(1.0) + kx * (dist - radius_m) + kv * radial_speed
}

#[cfg(test)]
mod tests {
    use super::*;

    const P: L1Params = L1Params {
        period_s: 17.0,
        damping: 0.75,
    };

    #[test]
    fn on_the_line_flying_along_it_asks_for_nothing() {
        let acc = track_accel(
            &P,
            &Vector2::new(50.0, 0.0),
            &Vector2::new(12.0, 0.0),
            &Vector2::zeros(),
            &Vector2::new(100.0, 0.0),
        );
        assert!(acc.abs() < 1e-9, "{acc}");
    }

    #[test]
    fn left_of_a_northbound_line_it_turns_right() {
        // NED: west of the line is y < 0.
        let acc = track_accel(
            &P,
            &Vector2::new(50.0, -10.0),
            &Vector2::new(12.0, 0.0),
            &Vector2::zeros(),
            &Vector2::new(100.0, 0.0),
        );
        assert!(acc > 0.0, "{acc}");
    }

    #[test]
    fn flying_across_the_line_it_turns_back_along_it() {
        let acc = track_accel(
            &P,
            &Vector2::new(50.0, 0.0),
            &Vector2::new(0.0, 12.0),
            &Vector2::zeros(),
            &Vector2::new(100.0, 0.0),
        );
        assert!(
            acc < 0.0,
            "heading east on a northbound line: turn left, got {acc}"
        );
    }

    #[test]
    fn on_the_circle_it_asks_for_the_centripetal_acceleration() {
        let acc = loiter_accel(
            &P,
            &Vector2::new(0.0, -30.0),
            &Vector2::new(12.0, 0.0),
            &Vector2::zeros(),
            30.0,
        );
        assert!((acc - 144.0 / 30.0).abs() < 1e-9, "{acc}");
    }
}
