//! External disturbances on the airframe (body frame B): the drag of the relative wind and a
//! torque pulse (the paper's experiments push the vehicle by hand about one axis). The paper's
//! model has neither; they exist for perturbation tests (`DESIGN.md` §3).

use nalgebra::{Matrix3, Vector3};

use crate::model::airframe::Airframe;

/// Linear drag of the whole airframe against the relative wind, in B:
/// F = −c (v − w) in I, rotated into B. `rot_b_to_i` is R_B→I; `wind_m_s` is inertial.
#[must_use]
pub fn wind_drag_body_n(
    af: &Airframe,
    rot_b_to_i: &Matrix3<f64>,
    vel_body_m_s: &Vector3<f64>,
    wind_m_s: &Vector3<f64>,
) -> Vector3<f64> {
    // −c (vᴮ − Rᵀ w): avoids rotating the velocity back and forth.
    -af.body_drag_n_s_per_m * (vel_body_m_s - rot_b_to_i.tr_mul(wind_m_s))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::model::frames::Euler;

    #[test]
    fn still_air_opposes_motion_and_wind_pushes_downwind() {
        let af = Airframe::default();
        let r = Euler::new(0.5, 0.1, -0.2).rotation_body_to_inertial();
        let v_i = Vector3::new(1.0, 0.0, 0.0);
        let v_b = r.transpose() * v_i;
        let f_i = r * wind_drag_body_n(&af, &r, &v_b, &Vector3::zeros());
        assert!((f_i - (-af.body_drag_n_s_per_m * v_i)).norm() < 1e-12);
        let f_i = r * wind_drag_body_n(&af, &r, &Vector3::zeros(), &Vector3::new(0.0, 2.0, 0.0));
        assert!(f_i.y > 0.0 && f_i.x.abs() < 1e-12);
    }
}
