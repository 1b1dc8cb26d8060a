//! Aerodynamics of the airframe at every angle of attack and sideslip (`physical` mode only;
//! `docs/model.md` gives every constant with its source).
//!
//! The airframe is the paper's flat plate (Table I: 0.6 m span along y_B, 0.46 m chord along
//! z_B, x_B its normal, [I1]). Its force is written in normal-force form, which holds from 0° to
//! 360° in both angle of attack and sideslip: a normal force −q S C_N(α) sign(u) x_B at the centre
//! of pressure, and skin friction along the plate through the centre of gravity. α ∈ [0°, 90°] is
//! the angle between the air-relative velocity and the plate. C_N blends an attached-flow
//! low-aspect-ratio law (Helmbold lift slope, Polhamus side-edge vortex lift) into the flat-plate
//! normal force past stall (Hoerner's C_D,90, Lindenburg's shape).
//!
//! The rotors' slipstream (the paper's (24), υ = k_υ ω) blows over the fraction
//! [`WASHED_SPAN_FRACTION`] of the wing: that part sees v_a + ῡ z_B, the rest v_a. The rotors
//! add their in-plane H-force. Pure functions: no state, no I/O.

use nalgebra::Vector3;

use crate::model::airframe::Airframe;

use super::Loads;

/// Air density, kg/m³ (ISA sea level).
pub const AIR_DENSITY_KG_M3: f64 = 1.225;
/// Wing span along y_B, m (paper, Table I: width).
pub const SPAN_M: f64 = 0.6;
/// Wing chord along z_B, m (paper, Table I: height).
pub const CHORD_M: f64 = 0.46;
/// Wing area S = b c, m².
pub const WING_AREA_M2: f64 = SPAN_M * CHORD_M;
/// Aspect ratio b / c.
pub const ASPECT_RATIO: f64 = SPAN_M / CHORD_M;
/// Attached-flow lift slope, /rad: Helmbold's low-aspect-ratio formula 2πA / (2 + √(A² + 4))
/// at A = 1.30 (checked in the tests). Torres & Mueller (AIAA J. 42(5), 2004) measure
/// 1.5–2.0 /rad on flat plates of aspect ratio 1–1.5.
pub const LIFT_SLOPE_PER_RAD: f64 = 1.868;
/// Side-edge vortex-lift constant K_v of the Polhamus form C_N = C_Lα sin α cos α + K_v sin²α
/// (Polhamus 1966; Lamar 1974 for side edges), set so that C_L peaks near 0.9–1.0 at 30–38° as
/// the low-aspect-ratio plates of Torres & Mueller do.
pub const VORTEX_LIFT_K: f64 = 1.0;
/// sin of the angle where the stall blend starts (30°).
pub const STALL_BLEND_SIN_START: f64 = 0.5;
/// sin of the angle where the stall blend ends (46°); the blend is centred on 38°.
pub const STALL_BLEND_SIN_END: f64 = 0.719_339_800_338_651_1;
/// Normal-force coefficient of the plate broadside to the flow: Hoerner, Fluid-Dynamic Drag
/// (1965) ch. 3, rectangular plate of aspect ratio ≈ 1.
pub const NORMAL_DRAG_COEFF: f64 = 1.17;
/// Lindenburg's (ECN-C--03-025, 2003) flat-plate shape C_N = C_D,90 sin α / (A + B sin α).
pub const FLAT_PLATE_SHAPE_A: f64 = 0.56;
/// See [`FLAT_PLATE_SHAPE_A`].
pub const FLAT_PLATE_SHAPE_B: f64 = 0.44;
/// Skin-friction drag of both faces, on the wing area (Pelletier & Mueller, J. Aircraft 37(5),
/// 2000: 0.015–0.025 for thin flat plates at Re 0.6–2·10⁵).
pub const FRICTION_DRAG_COEFF: f64 = 0.02;
/// Fraction of the wing that works in the slipstream. A wing in a slipstream cannot turn more
/// air than the slipstream carries: momentum theory gives each 10" rotor a mass flow
/// ṁ = ρ A v_i (A = 0.0507 m², v_i = 4.4 m/s at hover: 0.55 kg/s for two), so the slipstream's
/// crossflow force is at most ṁ u. The washed part's attached-flow slope ½ ρ κ S C_Lα ῡ equals
/// that bound for κ = 2 ṁ / (ρ S C_Lα ῡ) = 0.22, the same at every rotor speed (v_i and ῡ both
/// scale with ω). (The slipstream's geometric share of the span, 2 × 0.18 m of 0.6 m, would
/// give three times the momentum bound.)
pub const WASHED_SPAN_FRACTION: f64 = 0.22;
/// Rotor H-force per rotor: F = −λ_h ω v_⊥, N·s/(m·rad): the in-plane drag of a translating
/// propeller (Martin & Salaün, ICRA 2010), sized so that at hover it is 0.35 /s per unit mass,
/// the rotor drag Faessler, Franchi & Scaramuzza (RA-L 2018) identify on a small quadrotor.
pub const ROTOR_H_FORCE_N_S_PER_M_RAD: f64 = 2.0e-4;
/// The centre of gravity sits on the quarter chord, this far toward the nose (+z_B) from the
/// plate's centre, m: on the attached-flow aerodynamic centre, so the wing in the slipstream has
/// no pitching moment in hover (the paper's L_w = 0, its trim unchanged), and past stall the
/// centre of pressure moves aft of it, turning the nose into the wind. (A 5 % static margin,
/// usual on a flying wing, put the slipstream's centre of pressure 2.3 cm behind the CG: its
/// moment at 1 m/s broadside exceeded the pitch torque the paper's saturated chains allow.)
pub const CG_AHEAD_OF_CENTRE_M: f64 = 0.25 * CHORD_M;
/// Below this air speed (squared, m²/s²) a plate part carries no force.
const STILL_AIR_M2_S2: f64 = 1e-10;

/// Normal-force coefficient C_N from sin α and cos α, α ∈ [0°, 90°] the angle between the air
/// velocity and the plate.
#[inline]
#[must_use]
pub fn normal_coefficient(sin_a: f64, cos_a: f64) -> f64 {
    normal_coefficient_blended(sin_a, cos_a, stall_blend(sin_a))
}

/// [`normal_coefficient`] with the stall blend σ already computed.
#[inline]
fn normal_coefficient_blended(sin_a: f64, cos_a: f64, blend: f64) -> f64 {
    let attached = LIFT_SLOPE_PER_RAD * sin_a * cos_a + VORTEX_LIFT_K * sin_a * sin_a;
    let plate = NORMAL_DRAG_COEFF * sin_a / (FLAT_PLATE_SHAPE_A + FLAT_PLATE_SHAPE_B * sin_a);
    attached + blend * (plate - attached)
}

/// 0 in attached flow, 1 past stall: a cubic smoothstep in sin α between
/// [`STALL_BLEND_SIN_START`] and [`STALL_BLEND_SIN_END`] (continuous with its slope, and free of
/// the exponentials of the usual sigmoid).
#[inline]
fn stall_blend(sin_a: f64) -> f64 {
    let t = ((sin_a - STALL_BLEND_SIN_START) / (STALL_BLEND_SIN_END - STALL_BLEND_SIN_START))
        .clamp(0.0, 1.0);
    t * t * (3.0 - 2.0 * t)
}

/// Lift and drag coefficients (on the wing area) at angle of attack `alpha_rad` ∈ [0, π/2],
/// flow along the chord: C_L = C_N cos α − C_D,0 cos α sin α, C_D = C_N sin α + C_D,0 cos²α.
#[must_use]
pub fn lift_drag_coefficients(alpha_rad: f64) -> (f64, f64) {
    let (s, c) = alpha_rad.sin_cos();
    let cn = normal_coefficient(s, c);
    (
        cn * c - FRICTION_DRAG_COEFF * c * s,
        cn * s + FRICTION_DRAG_COEFF * c * c,
    )
}

/// Normal force and its moment about the CG of a plate part of `area_m2` moving through the air
/// at `v_air` (the body's velocity relative to the air, in B). The normal force acts at the
/// centre of pressure, (0.25 + 0.25 σ(α)) of the plate's length from its leading edge (the edge
/// ahead in the direction of motion; σ the stall blend); the CG is [`CG_AHEAD_OF_CENTRE_M`] toward the nose from the
/// plate's centre.
#[inline]
fn normal_loads(v_air: &Vector3<f64>, area_m2: f64) -> Loads {
    let (u, vy, vz) = (v_air.x, v_air.y, v_air.z);
    let in_plane_sq = vy * vy + vz * vz;
    let speed_sq = u * u + in_plane_sq;
    if speed_sq < STILL_AIR_M2_S2 {
        return Loads::default();
    }
    let speed = speed_sq.sqrt();
    let in_plane = in_plane_sq.sqrt();
    let sin_a = u.abs() / speed;
    let cos_a = in_plane / speed;
    let blend = stall_blend(sin_a);
    let normal = -0.5
        * AIR_DENSITY_KG_M3
        * area_m2
        * speed_sq
        * normal_coefficient_blended(sin_a, cos_a, blend)
        * u.signum();
    // Centre of pressure ahead of the plate's centre by ¼ (1 − σ) of the plate's length along
    // the in-plane flow (chord along z_B, span along y_B): the quarter chord in attached flow,
    // the centre once stalled.
    let (r_y, r_z) = if in_plane > 0.0 {
        let k = 0.25 * (1.0 - blend) / in_plane;
        (k * SPAN_M * vy, k * CHORD_M * vz - CG_AHEAD_OF_CENTRE_M)
    } else {
        (0.0, -CG_AHEAD_OF_CENTRE_M)
    };
    // r × (N, 0, 0) = (0, r_z N, −r_y N).
    let torque = Vector3::new(0.0, r_z * normal, -r_y * normal);
    Loads {
        force_body_n: Vector3::new(normal, 0.0, 0.0),
        torque_body_nm: torque,
    }
}

/// Air-relative velocity of the body in B: v_a = vᴮ − Rᵀ w, with `wind_body_m_s` = Rᵀ w.
#[inline]
#[must_use]
pub fn air_velocity_body(
    vel_body_m_s: &Vector3<f64>,
    wind_body_m_s: &Vector3<f64>,
) -> Vector3<f64> {
    vel_body_m_s - wind_body_m_s
}

/// Angle of attack of the plate, rad, in (−π, π]: the angle of the air-relative velocity from
/// the nose (z_B) toward the plate's normal x_B. Zero in level forward flight with the plate
/// edge-on; ±π/2 broadside; undefined (0) in still air.
#[must_use]
pub fn angle_of_attack_rad(v_air: &Vector3<f64>) -> f64 {
    if v_air.x == 0.0 && v_air.z == 0.0 {
        0.0
    } else {
        v_air.x.atan2(v_air.z)
    }
}

/// All aerodynamic loads on the airframe in B: the wing (washed and clean parts), its skin
/// friction and the rotors' H-force. `v_air` is the air-relative velocity ([`air_velocity_body`]),
/// `rotor_speed_rad_s` the actual rotor speeds.
#[must_use]
pub fn loads(af: &Airframe, v_air: &Vector3<f64>, rotor_speed_rad_s: &[f64; 2]) -> Loads {
    let [w1, w2] = *rotor_speed_rad_s;
    let wash = 0.5 * af.k_wash_m_per_rad * (w1.abs() + w2.abs());
    // The slipstream blows along −z_B: relative to it the washed wing moves along +z_B.
    let washed = normal_loads(
        &Vector3::new(v_air.x, v_air.y, v_air.z + wash),
        WASHED_SPAN_FRACTION * WING_AREA_M2,
    );
    let clean = normal_loads(v_air, (1.0 - WASHED_SPAN_FRACTION) * WING_AREA_M2);
    // Friction on the free-stream velocity only: the wash's own friction is part of the
    // installed thrust constant kT (docs/model.md).
    let speed = v_air.norm();
    let friction_gain = -0.5 * AIR_DENSITY_KG_M3 * WING_AREA_M2 * FRICTION_DRAG_COEFF * speed;
    let friction = Vector3::new(0.0, friction_gain * v_air.y, friction_gain * v_air.z);
    let h_gain = -ROTOR_H_FORCE_N_S_PER_M_RAD * (w1.abs() + w2.abs());
    let h_force = Vector3::new(h_gain * v_air.x, h_gain * v_air.y, 0.0);
    Loads {
        force_body_n: washed.force_body_n + clean.force_body_n + friction + h_force,
        torque_body_nm: washed.torque_body_nm + clean.torque_body_nm,
    }
}

/// Linear aerodynamic damping per unit mass near hover, 1/s, along x_B (broadside: the washed
/// wing's normal force ½ ρ κ S C_Lα ῡ plus the rotors' H-force) and along y_B (edgewise: the
/// H-force; skin friction is quadratic and vanishes at small speed): the slopes of [`loads`] at
/// zero air speed. The controller compensates them in `physical` mode.
#[must_use]
pub fn hover_damping_per_kg(af: &Airframe, rotor_speed_rad_s: &[f64; 2]) -> (f64, f64) {
    let [w1, w2] = *rotor_speed_rad_s;
    let spin = w1.abs() + w2.abs();
    let wash = 0.5 * af.k_wash_m_per_rad * spin;
    let h = ROTOR_H_FORCE_N_S_PER_M_RAD * spin;
    let washed =
        0.5 * AIR_DENSITY_KG_M3 * WASHED_SPAN_FRACTION * WING_AREA_M2 * LIFT_SLOPE_PER_RAD * wash;
    ((washed + h) / af.mass_kg, h / af.mass_kg)
}

#[cfg(test)]
#[path = "aero_tests.rs"]
mod tests;
