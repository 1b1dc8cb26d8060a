//! The aerodynamic model against published flat-plate and low-aspect-ratio wing data, and its
//! physical self-checks (direction of forces, symmetry, continuity).

use super::*;

/// Reference ranges for a thin rectangular flat plate of aspect ratio 1–1.5 at Re ≈ 10⁵, flow
/// along the chord. Each range is a summary of the spread the cited works report (the model must
/// fall inside it). The ranges are summarised from the papers' text and figures, not digitised
/// from their data: a finer check would read the published curves point by point.
///
/// * [PM] Pelletier & Mueller, "Low Reynolds number aerodynamics of low-aspect-ratio,
///   thin/flat/cambered-plate wings", J. Aircraft 37(5), 2000: minimum C_D of the thin flat
///   plates 0.015–0.025; maximum L/D of the flat plates of AR 1–1.5 about 4–6 at 5–10°.
/// * [TM] Torres & Mueller, "Low-aspect-ratio wing aerodynamics at low Reynolds numbers",
///   AIAA J. 42(5), 2004: lift slope 1.5–2.0 /rad for AR 1–1.5 rectangular plates, C_L rising
///   nearly linearly to 20–25°, C_L,max 0.85–1.25 reached at 25–45° (the lower the AR, the later
///   the stall).
/// * [GY] Gyllhem, Mohseni, Lawrence & Geuzaine, AIAA 2005-4757: an AR 1.2 plate wing, C_L,max
///   about 1.2 at 30°, maximum L/D about 4.
/// * [HO] Hoerner, Fluid-Dynamic Drag (1965) ch. 3: a rectangular plate of AR 1–2 normal to the
///   flow, C_D = 1.17–1.19; past stall the resultant is normal to the plate (C_L / C_D = cot α).
///
/// (α in degrees, quantity, low, high, source)
const REFERENCE: &[(f64, &str, f64, f64, &str)] = &[
    (0.0, "CD", 0.015, 0.025, "PM"),
    (0.0, "CL", -0.01, 0.01, "PM"),
    (5.0, "CL", 0.13, 0.20, "TM"),
    (10.0, "CL", 0.26, 0.45, "TM"),
    (15.0, "CL", 0.40, 0.65, "TM"),
    (20.0, "CL", 0.52, 0.85, "TM"),
    (45.0, "CL/CD", 0.75, 1.25, "HO"),
    (60.0, "CL/CD", 0.45, 0.75, "HO"),
    (90.0, "CD", 1.10, 1.25, "HO"),
    (90.0, "CL", -0.02, 0.02, "HO"),
];

fn coefficients(alpha_deg: f64) -> (f64, f64) {
    lift_drag_coefficients(alpha_deg.to_radians())
}

#[test]
fn lift_and_drag_match_the_flat_plate_data_over_0_to_90_degrees() {
    for &(alpha, what, lo, hi, source) in REFERENCE {
        let (cl, cd) = coefficients(alpha);
        let value = match what {
            "CL" => cl,
            "CD" => cd,
            "CL/CD" => cl / cd,
            other => unreachable!("{other}"),
        };
        assert!(
            (lo..=hi).contains(&value),
            "{what} at {alpha}° = {value:.3}, outside [{lo}, {hi}] of [{source}]"
        );
    }
}

#[test]
fn maximum_lift_and_lift_to_drag_fall_where_the_data_put_them() {
    let curve: Vec<(f64, f64, f64)> = (0..=900)
        .map(|i| {
            let a = f64::from(i) * 0.1;
            let (cl, cd) = coefficients(a);
            (a, cl, cd)
        })
        .collect();
    let (a_clmax, clmax, _) = curve
        .iter()
        .copied()
        .fold((0.0, f64::MIN, 0.0), |m, p| if p.1 > m.1 { p } else { m });
    // [TM], [GY]: C_L,max 0.85–1.25 at 25–45°.
    assert!((0.85..=1.25).contains(&clmax), "C_L,max {clmax}");
    assert!((25.0..=45.0).contains(&a_clmax), "α at C_L,max {a_clmax}");
    let (a_ld, ld) = curve
        .iter()
        .map(|&(a, cl, cd)| (a, cl / cd))
        .fold((0.0, f64::MIN), |m, p| if p.1 > m.1 { p } else { m });
    // [PM], [GY]: maximum L/D about 4–6 at 5–10°.
    assert!((4.0..=6.0).contains(&ld), "max L/D {ld}");
    assert!((4.0..=10.0).contains(&a_ld), "α at max L/D {a_ld}");
}

#[test]
fn lift_slope_is_helmbolds() {
    let a = ASPECT_RATIO;
    let helmbold = 2.0 * std::f64::consts::PI * a / (2.0 + (a * a + 4.0).sqrt());
    assert!((LIFT_SLOPE_PER_RAD - helmbold).abs() < 1e-3, "{helmbold}");
    assert!((STALL_BLEND_SIN_END - 46f64.to_radians().sin()).abs() < 1e-12);
    assert!((STALL_BLEND_SIN_START - 30f64.to_radians().sin()).abs() < 1e-12);
}

#[test]
fn coefficients_are_continuous() {
    let mut last = coefficients(0.0);
    for i in 1..=9000 {
        let now = coefficients(f64::from(i) * 0.01);
        assert!(
            (now.0 - last.0).abs() < 2e-3 && (now.1 - last.1).abs() < 2e-3,
            "{i}"
        );
        last = now;
    }
}

#[test]
fn the_wing_opposes_motion_in_every_direction() {
    let af = Airframe::default();
    for i in 0..36 {
        for j in 0..18 {
            let (az, el) = (
                f64::from(i) * 10f64.to_radians(),
                f64::from(j) * 10f64.to_radians(),
            );
            let v = Vector3::new(el.sin() * az.cos(), el.sin() * az.sin(), el.cos()) * 8.0;
            let l = loads(&af, &v, &[0.0, 0.0]);
            // Power dissipated: F·v ≤ 0 (a plate never pushes the body along its motion).
            assert!(l.force_body_n.dot(&v) <= 1e-12, "{i} {j}");
        }
    }
}

#[test]
fn broadside_is_flat_plate_drag_and_edgewise_is_friction() {
    let af = Airframe::default();
    let q_s = 0.5 * AIR_DENSITY_KG_M3 * 25.0 * WING_AREA_M2;
    let broad = loads(&af, &Vector3::new(5.0, 0.0, 0.0), &[0.0, 0.0]);
    assert!((broad.force_body_n.x + q_s * NORMAL_DRAG_COEFF).abs() < 1e-9);
    // Broadside the centre of pressure is the plate's centre, a quarter chord behind the CG.
    let arm = broad.torque_body_nm.y / broad.force_body_n.x;
    assert!((arm + CG_AHEAD_OF_CENTRE_M).abs() < 1e-12, "{arm}");
    let edge = loads(&af, &Vector3::new(0.0, 5.0, 0.0), &[0.0, 0.0]);
    assert!((edge.force_body_n.y + q_s * FRICTION_DRAG_COEFF).abs() < 1e-9);
}

#[test]
fn hover_in_still_air_has_no_aerodynamic_load() {
    let af = Airframe::default();
    let w = af.hover_rotor_speed_rad_s();
    let l = loads(&af, &Vector3::zeros(), &[w, w]);
    assert_eq!(l, Loads::default());
}

#[test]
fn the_slipstream_damps_broadside_motion_in_hover() {
    let af = Airframe::default();
    let w = af.hover_rotor_speed_rad_s();
    let l = loads(&af, &Vector3::new(0.2, 0.0, 0.0), &[w, w]);
    // ½ ρ κ S C_Lα ῡ u, the slipstream's mass flow (0.55 kg/s) times u, plus the H-force.
    let per_m_s = -l.force_body_n.x / 0.2;
    assert!((0.65..0.85).contains(&per_m_s), "{per_m_s}");
    let mass_flow = 2.0 * AIR_DENSITY_KG_M3 * 0.0507 * 4.44;
    let washed = 0.5 * AIR_DENSITY_KG_M3 * WASHED_SPAN_FRACTION * WING_AREA_M2 * LIFT_SLOPE_PER_RAD;
    let washed = washed * af.k_wash_m_per_rad * w;
    assert!(
        (washed - mass_flow).abs() < 0.02 * mass_flow,
        "{washed} vs {mass_flow}"
    );
    // The slipstream's centre of pressure (quarter chord) is on the CG: almost no moment.
    assert!(l.torque_body_nm.y.abs() < 0.002, "{}", l.torque_body_nm.y);
    // Edgewise in hover: friction and the rotors' H-force, 0.35 /s per unit mass.
    let e = loads(&af, &Vector3::new(0.0, 0.2, 0.0), &[w, w]);
    let per_kg = -e.force_body_n.y / 0.2 / af.mass_kg;
    assert!((0.3..0.4).contains(&per_kg), "{per_kg}");
}

#[test]
fn forward_flight_lifts_toward_minus_x() {
    // Nose (z_B) into the air at 12 m/s and 6° of angle of attack: the air velocity leans toward
    // +x_B, so the lift acts along −x_B (up, in level flight with x_B pointing down).
    let af = Airframe::default();
    let a = 6f64.to_radians();
    let v = Vector3::new(a.sin(), 0.0, a.cos()) * 12.0;
    assert!((angle_of_attack_rad(&v) - a).abs() < 1e-12);
    let l = loads(&af, &v, &[0.0, 0.0]);
    let (cl, cd) = lift_drag_coefficients(a);
    let q_s = 0.5 * AIR_DENSITY_KG_M3 * 144.0 * WING_AREA_M2;
    let lift_dir = Vector3::new(-a.cos(), 0.0, a.sin());
    let drag_dir = -v.normalize();
    assert!((l.force_body_n.dot(&lift_dir) - q_s * cl).abs() < 1e-9);
    assert!((l.force_body_n.dot(&drag_dir) - q_s * cd).abs() < 1e-9);
    // 12 m/s at 6° carries about the 4.9 N weight.
    assert!((4.0..6.0).contains(&(q_s * cl)), "{}", q_s * cl);
    // Neutral in attached flow (the CG on the quarter chord), stable past stall: a nose-up angle
    // of attack (air along +x_B) gives a moment about +y_B, which turns the nose toward the air.
    let small = loads(&af, &v, &[0.0, 0.0]).torque_body_nm.y;
    assert!(small.abs() < 1e-12, "{small}");
    let v_up = Vector3::new(0.7f64.sin(), 0.0, 0.7f64.cos()) * 12.0;
    let up = loads(&af, &v_up, &[0.0, 0.0]);
    assert!(up.torque_body_nm.y > 0.0, "{}", up.torque_body_nm.y);
}

#[test]
fn hover_damping_is_the_slope_of_the_loads() {
    let af = Airframe::default();
    let w = af.hover_rotor_speed_rad_s();
    let (dx, dy) = hover_damping_per_kg(&af, &[w, w]);
    let u = 1e-4;
    let fx = loads(&af, &Vector3::new(u, 0.0, 0.0), &[w, w])
        .force_body_n
        .x;
    let fy = loads(&af, &Vector3::new(0.0, u, 0.0), &[w, w])
        .force_body_n
        .y;
    assert!(
        (-fx / u / af.mass_kg - dx).abs() < 0.01 * dx,
        "{dx} {}",
        -fx / u / af.mass_kg
    );
    assert!(
        (-fy / u / af.mass_kg - dy).abs() < 0.01 * dy,
        "{dy} {}",
        -fy / u / af.mass_kg
    );
}
