//! ArduPilot's fixed-wing body frame: the frame the twin reports its attitude in.
//!
//! ArduPlane reports a tailsitter in its fixed-wing body frame: x along the
//! nose, y along the right wing, z down through the belly. Standing or hovering on its tail the
//! nose points up (pitch 90°); level on the wing the pitch is the angle of attack and the heading
//! the course.
//!
//! In the paper's body frame the nose is the thrust axis +z_B. On the wing x_B points down (the
//! plate's lift is along −x_B), so the belly is +x_B and the right wing −y_B:
//!
//! ```text
//! x_fw = z_B,   y_fw = −y_B,   z_fw = x_B        v_fw = M v_B,  M = [0 0 1; 0 −1 0; 1 0 0]
//! ```
//!
//! M is its own inverse. With T = diag(−1, 1, −1) the map from the paper's inertial frame (z up)
//! to NED ([`super::paper_to_ned`]), R_fw→NED = T · R_B→I · M.
//!
//! Against the hover frame of [`super::euler_to_ned_rpy`] (x_h = −x_B, y_h = y_B, z_h = −z_B),
//! x_fw = −z_h, y_fw = −y_h, z_fw = −x_h: the hover frame's "forward" is the wing's upper side,
//! so ArduPilot's VTOL view (the fixed-wing frame pitched by 90°, its x through the belly) is
//! the hover frame turned half a turn about the vertical.
//!
//! ArduPlane's ATTITUDE message (and only it: not ATTITUDE_QUATERNION, VFR_HUD's heading,
//! AHRS2 or GLOBAL_POSITION_INT's `hdg`) switches to that VTOL view while the tailsitter flies
//! as a multicopter (`GCS_MAVLINK_Plane::send_attitude`, `QuadPlane::show_vtol_view`: a VTOL
//! mode, or a forward transition still pitching down; not a back transition still pitching
//! up): upright on the tail reads roll 0°, pitch 0°, the yaw the belly's heading. Its body
//! rates stay the fixed-wing frame's. [`vtol_view`] gives those angles.
//!
//! Only what the twin reports goes through here: the model, the controller and `simulate` keep
//! the paper's frames.

use std::f64::consts::FRAC_PI_2;

use nalgebra::{Matrix3, Rotation3, UnitQuaternion, Vector3};

use super::{Euler, wrap_pi};

/// Below this cos(pitch) the nose is vertical to rounding and roll and yaw cannot be told apart
/// (gimbal lock): the roll is reported as 0 and the yaw carries the whole turn.
const GIMBAL_LOCK_COS: f64 = 1e-9;

/// An attitude in ArduPilot's fixed-wing body frame, NED.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FixedWingAttitude {
    /// Roll, rad, positive right wing down, (−π, π].
    pub roll_rad: f64,
    /// Pitch, rad, positive nose up, [−π/2, π/2]: π/2 on the tail.
    pub pitch_rad: f64,
    /// Yaw, rad, (−π, π]: the heading of the nose; on the tail (the nose exactly vertical),
    /// that of the belly.
    pub yaw_rad: f64,
    /// The same rotation as a unit quaternion (w, x, y, z), w ≥ 0.
    pub quaternion: [f64; 4],
}

impl FixedWingAttitude {
    /// The heading, degrees in [0, 360).
    #[must_use]
    pub fn heading_deg(&self) -> f64 {
        let h = self.yaw_rad.to_degrees().rem_euclid(360.0);
        if h >= 360.0 { 0.0 } else { h }
    }
}

/// A body-frame vector (rates, specific force, sensor axes) from the paper's body frame to the
/// fixed-wing body frame: (z, −y, x).
#[must_use]
pub fn body_vector(v: &Vector3<f64>) -> [f64; 3] {
    [v[2], -v[1], v[0]]
}

/// R_fw→NED = T · R_B→I · M.
#[must_use]
pub fn rotation_to_ned(e: &Euler) -> Matrix3<f64> {
    let r = e.rotation_body_to_inertial();
    // Columns of R·M are (r₂, −r₁, r₀); T negates rows 0 and 2.
    Matrix3::new(
        -r[(0, 2)],
        r[(0, 1)],
        -r[(0, 0)],
        r[(1, 2)],
        -r[(1, 1)],
        r[(1, 0)],
        -r[(2, 2)],
        r[(2, 1)],
        -r[(2, 0)],
    )
}

/// The attitude ArduPilot reports for the paper's angles `e`: roll, pitch and yaw taken from
/// R_fw→NED as ArduPilot's `Matrix3::to_euler` takes them (ZYX).
#[must_use]
pub fn attitude(e: &Euler) -> FixedWingAttitude {
    from_matrix(&rotation_to_ned(e))
}

/// ArduPilot's VTOL view of a fixed-wing attitude (`AP_AHRS_View` with `ROTATION_PITCH_90`):
/// R_view = R_fw→NED · Ry(90°)ᵀ, its roll, pitch and yaw taken as [`attitude`] takes them.
/// Its x axis is the fixed-wing frame's z (the belly), its z the nose reversed.
#[must_use]
pub fn vtol_view(a: &FixedWingAttitude) -> FixedWingAttitude {
    let [w, x, y, z] = a.quaternion;
    let q = UnitQuaternion::from_quaternion(nalgebra::Quaternion::new(w, x, y, z));
    let r = q.to_rotation_matrix().into_inner()
        * Rotation3::from_euler_angles(0.0, FRAC_PI_2, 0.0)
            .into_inner()
            .transpose();
    from_matrix(&r)
}

/// Roll, pitch, yaw and quaternion of a rotation to NED, as ArduPilot's `Matrix3::to_euler`.
fn from_matrix(r: &Matrix3<f64>) -> FixedWingAttitude {
    let pitch = -r[(2, 0)].clamp(-1.0, 1.0).asin();
    let (roll, yaw) = if r[(2, 1)].hypot(r[(2, 2)]) < GIMBAL_LOCK_COS {
        // R = Rz(ψ)·Ry(±π/2) with the roll put to 0: the right wing's column is (−sψ, cψ, 0).
        (0.0, (-r[(0, 1)]).atan2(r[(1, 1)]))
    } else {
        (r[(2, 1)].atan2(r[(2, 2)]), r[(1, 0)].atan2(r[(0, 0)]))
    };
    let q = UnitQuaternion::from_rotation_matrix(&Rotation3::from_matrix_unchecked(*r));
    let sign = if q.w < 0.0 { -1.0 } else { 1.0 };
    FixedWingAttitude {
        roll_rad: wrap_pi(roll),
        pitch_rad: pitch,
        yaw_rad: wrap_pi(yaw),
        quaternion: [sign * q.w, sign * q.i, sign * q.j, sign * q.k],
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::model::frames::paper_to_ned;
    use std::f64::consts::{FRAC_PI_2, PI};

    /// ZYX roll/pitch/yaw back to a matrix (NED).
    fn from_rpy(a: &FixedWingAttitude) -> Matrix3<f64> {
        Euler::new(a.yaw_rad, a.pitch_rad, a.roll_rad).rotation_body_to_inertial()
    }

    /// The paper's angles of R_B→I (away from θ = ±π/2).
    fn paper_euler(r: &Matrix3<f64>) -> Euler {
        Euler::new(
            r[(1, 0)].atan2(r[(0, 0)]),
            -r[(2, 0)].asin(),
            r[(2, 1)].atan2(r[(2, 2)]),
        )
    }

    /// On the wing, nose along `course` (NED heading), `alpha` above the horizon, banked `bank`
    /// (right wing down positive): the paper's angles of that attitude.
    fn on_the_wing(course: f64, alpha: f64, bank: f64) -> Euler {
        // Built in NED from the fixed-wing frame, then taken back through T·R·M.
        let r_fw = Euler::new(course, alpha, bank).rotation_body_to_inertial();
        let t = Matrix3::new(-1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, -1.0);
        let m = Matrix3::new(0.0, 0.0, 1.0, 0.0, -1.0, 0.0, 1.0, 0.0, 0.0);
        paper_euler(&(t * r_fw * m))
    }

    fn close(a: f64, b: f64) -> bool {
        wrap_pi(a - b).abs() < 1e-9
    }

    #[test]
    fn hovering_on_the_tail_is_pitch_90() {
        for psi in [0.0, 0.5, -2.0, PI] {
            let a = attitude(&Euler::new(psi, 0.0, 0.0));
            assert!(close(a.pitch_rad, FRAC_PI_2), "{a:?}");
            assert_eq!(a.roll_rad, 0.0);
            // Rz(yaw)·Ry(π/2): the yaw is the belly's heading. The belly faces the hover
            // frame's back, so that is the hover yaw (−ψ) + π.
            assert!(close(a.yaw_rad, PI - psi), "ψ {psi}: {a:?}");
            assert!((from_rpy(&a) - rotation_to_ned(&Euler::new(psi, 0.0, 0.0))).norm() < 1e-9);
        }
        // A small tilt leaves the pitch near 90°.
        let a = attitude(&Euler::new(0.3, 0.02, -0.01));
        assert!((a.pitch_rad.to_degrees() - 90.0).abs() < 1.5, "{a:?}");
    }

    #[test]
    fn the_vtol_view_of_a_hover_is_level_facing_the_belly() {
        for psi in [0.0, 0.5, -2.0, PI] {
            let fw = attitude(&Euler::new(psi, 0.0, 0.0));
            let v = vtol_view(&fw);
            assert!(v.roll_rad.abs() < 1e-9 && v.pitch_rad.abs() < 1e-9, "{v:?}");
            // The belly's heading, which is the fixed-wing yaw on the tail.
            assert!(close(v.yaw_rad, fw.yaw_rad), "ψ {psi}: {v:?} {fw:?}");
        }
        // ArduPlane SITL's tailsitter standing on its tail, read in MANUAL (fixed-wing frame)
        // and QSTABILIZE (VTOL view): roll 110.6° pitch 90° yaw 97.6° is roll 0°, pitch 0°,
        // yaw −13.0° (the yaw minus the roll).
        let fw = {
            let r = Euler::new(
                97.6_f64.to_radians(),
                90_f64.to_radians() - 1e-7,
                110.6_f64.to_radians(),
            )
            .rotation_body_to_inertial();
            from_matrix(&r)
        };
        let v = vtol_view(&fw);
        assert!(
            v.roll_rad.to_degrees().abs() < 0.01 && v.pitch_rad.to_degrees().abs() < 0.01,
            "{v:?}"
        );
        assert!((v.yaw_rad.to_degrees() + 13.0).abs() < 0.01, "{v:?}");
    }

    #[test]
    fn the_vtol_view_of_level_flight_on_the_wing_is_nose_down() {
        // On the wing at 5.5° of pitch the VTOL view reads pitch 5.5° − 90°, yaw the course.
        let alpha = 5.5_f64.to_radians();
        let v = vtol_view(&attitude(&on_the_wing(0.7, alpha, 0.0)));
        assert!(
            (v.pitch_rad.to_degrees() - (5.5 - 90.0)).abs() < 1e-6,
            "{v:?}"
        );
        assert!(close(v.yaw_rad, 0.7), "{v:?}");
    }

    #[test]
    fn level_on_the_wing_is_the_angle_of_attack_and_the_course() {
        for course in [0.0, 1.0, FRAC_PI_2, PI, -2.5] {
            let alpha = 5.5_f64.to_radians();
            let a = attitude(&on_the_wing(course, alpha, 0.0));
            assert!(close(a.pitch_rad, alpha), "{a:?}");
            assert!(close(a.yaw_rad, course), "{a:?}");
            assert!(a.roll_rad.abs() < 1e-9, "{a:?}");
        }
        // The twin's own numbers on the wing (hover frame: pitch 84.5°, yaw 179°) are pitch
        // 5.5° and heading 359°.
        let e = Euler::new(-179_f64.to_radians(), 84.5_f64.to_radians(), 0.0);
        let a = attitude(&e);
        assert!((a.pitch_rad.to_degrees() - 5.5).abs() < 1e-9, "{a:?}");
        assert!((a.heading_deg() - 359.0).abs() < 1e-6, "{a:?}");
    }

    #[test]
    fn a_bank_to_the_right_is_positive_roll() {
        let bank = 30_f64.to_radians();
        let e = on_the_wing(0.3, 4_f64.to_radians(), bank);
        let a = attitude(&e);
        assert!(close(a.roll_rad, bank), "{a:?}");
        // The right wing (−y_B) points down: positive NED z.
        let right = paper_to_ned(&(e.rotation_body_to_inertial() * Vector3::new(0.0, -1.0, 0.0)));
        assert!(right.z > 0.4, "{right}");
    }

    #[test]
    fn angles_and_quaternion_are_the_rotation() {
        for e in [
            Euler::new(0.7, -0.3, 0.4),
            Euler::new(-2.0, 1.2, 0.1),
            Euler::new(3.0, 0.2, -1.4),
        ] {
            let r = rotation_to_ned(&e);
            assert!((r.transpose() * r - Matrix3::identity()).norm() < 1e-12);
            assert!((r.determinant() - 1.0).abs() < 1e-12);
            let a = attitude(&e);
            assert!((from_rpy(&a) - r).norm() < 1e-9, "{e:?}");
            let [w, x, y, z] = a.quaternion;
            assert!(w >= 0.0);
            let q = UnitQuaternion::from_quaternion(nalgebra::Quaternion::new(w, x, y, z));
            assert!((q.to_rotation_matrix().into_inner() - r).norm() < 1e-9);
            // Body vectors: the nose is z_B, the belly x_B.
            let nose = r * Vector3::from(body_vector(&Vector3::new(0.0, 0.0, 1.0)));
            assert!((nose - r.column(0)).norm() < 1e-12);
            let belly_ned = paper_to_ned(&(e.rotation_body_to_inertial() * Vector3::x()));
            assert!((belly_ned - r.column(2)).norm() < 1e-12);
        }
        // Rates: the roll rate is the rate about the nose, r of the paper.
        assert_eq!(body_vector(&Vector3::new(0.1, 0.2, 0.3)), [0.3, -0.2, 0.1]);
    }
}
