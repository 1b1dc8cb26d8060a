//! The attitude as the operator reads it. ArduPlane reports a tailsitter's attitude in the
//! fixed-wing body frame — x out of the nose, z out of the belly — except in one message at
//! some times: while it flies as a multicopter (a VTOL mode, or a forward transition still
//! pitching down) its ATTITUDE is in its **VTOL view** (`GCS_MAVLINK_Plane::send_attitude`,
//! `QuadPlane::show_vtol_view`), the fixed-wing frame turned by −90° of pitch.
//! ATTITUDE_QUATERNION, AHRS2 and the headings stay in the fixed-wing frame, and so does
//! ATTITUDE on the wing and in a back transition. The twin reports the same way. Hovering on its
//! tail, the fixed-wing frame reads pitch +90° with roll and yaw degenerate (only their
//! difference means anything), so a horizon drawn from it is useless just when the operator
//! needs it.
//!
//! A tailsitter (`Q_TAILSIT_ENABLE` > 0 in its parameters — or other `Q_TAILSIT_*` ones,
//! which ArduPilot shows only while it is set —, or a `MAV_TYPE_VTOL_TAILSITTER*` heartbeat;
//! ArduPlane's own is `MAV_TYPE_FIXED_WING` while `Q_MAV_TYPE` is 0) in hover (EXTENDED_SYS_STATE's `vtol_state` MC or a forward transition under way,
//! or, without that message, a Q mode) is therefore shown in the **hover frame**, which is that
//! VTOL view: the wing frame turned by −90° of pitch about the wing's y axis (the right wing),
//! as ArduPilot's own tailsitter controller views it. In that frame
//!
//! - standing upright on the tail reads roll 0°, pitch 0°: a level horizon;
//! - x (the hover "nose") is the direction the **belly** faces — where the vehicle goes when it
//!   tips forward into a transition, and where the fixed-wing nose will point once level — so
//!   the heading is the belly's compass direction, continuous through the transition;
//! - pitch goes negative as the vehicle tips toward its belly (forward, as a multicopter pitches
//!   nose down to fly forward; level forward flight is −90°), roll positive toward the right
//!   wing;
//! - body rates become (p, q, r) = (r_wing, q_wing, −p_wing).
//!
//! In forward flight (and during a back transition, which the fixed-wing controller flies) the
//! wing frame is shown as reported. The readouts say which frame they are in. The quaternion is
//! preferred when the vehicle streams ATTITUDE_QUATERNION (no gimbal lock near 90° of pitch,
//! always the wing frame) and turned; otherwise ATTITUDE's angles, which in hover are the
//! VTOL view already when the vehicle is an ArduPilot — unless AHRS2 (always the wing frame)
//! says they are not, as on an ArduPlane SITL's first boot with a tailsitter's parameters
//! given as defaults, before the reboot that sets its VTOL view up — and are turned otherwise.

use std::time::Duration;

use nalgebra::{UnitQuaternion, Vector3};
use vtol_link::dialect::{MavAutopilot, MavMessage, MavType, MavVtolState};
use vtol_link::protocol::id::{AHRS2, ATTITUDE, ATTITUDE_QUATERNION, EXTENDED_SYS_STATE};

use crate::tracker::state::{VehicleState, VehicleView};

/// A quaternion this much older than the last ATTITUDE is no longer streamed.
const QUATERNION_FRESH: Duration = Duration::from_secs(1);

/// The frame an attitude is shown in.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum AttFrame {
    /// As the vehicle reports it: the body frame of a conventional aircraft (or the wing's).
    Body,
    /// A tailsitter in forward flight: the wing frame, as reported.
    Wing,
    /// A tailsitter in hover: upright on its tail is level, the heading is the belly's.
    Hover,
}

impl AttFrame {
    /// What the readouts call it; `None` for a vehicle that has only one.
    #[must_use]
    pub fn label(self) -> Option<&'static str> {
        match self {
            AttFrame::Body => None,
            AttFrame::Wing => Some("wing frame"),
            AttFrame::Hover => Some("hover frame"),
        }
    }
}

/// An attitude as shown: roll, pitch, yaw (rad, yaw from north) and body rates (rad/s).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Shown {
    /// Roll, pitch, yaw, rad.
    pub rpy_rad: [f32; 3],
    /// Roll, pitch, yaw rates about the shown frame's axes, rad/s.
    pub rates_rad_s: [f32; 3],
    /// The frame.
    pub frame: AttFrame,
}

/// Whether `v` is a tailsitter: `Q_TAILSIT_ENABLE` above 0 in its parameters (when known), or
/// a tailsitter MAV_TYPE in its heartbeat.
#[must_use]
pub fn is_tailsitter(v: &VehicleView, q_tailsit_enable: Option<f32>) -> bool {
    q_tailsit_enable.is_some_and(|x| x > 0.0)
        || matches!(
            v.mav_type,
            x if x == MavType::MAV_TYPE_VTOL_TAILSITTER as u8
                || x == MavType::MAV_TYPE_VTOL_TAILSITTER_DUOROTOR as u8
                || x == MavType::MAV_TYPE_VTOL_TAILSITTER_QUADROTOR as u8
        )
}

/// Whether `v` flies as a multicopter now: EXTENDED_SYS_STATE's MC or a forward transition
/// (still flown by the hover controller), else a Q mode.
#[must_use]
pub fn in_hover(state: &VehicleState, v: &VehicleView) -> bool {
    let ext = state
        .messages
        .get(&(v.system_id, v.component_id, EXTENDED_SYS_STATE))
        .and_then(|s| s.last.decode_lenient().ok().map(|l| l.msg));
    match ext {
        Some(MavMessage::EXTENDED_SYS_STATE(e))
            if e.vtol_state != MavVtolState::MAV_VTOL_STATE_UNDEFINED =>
        {
            matches!(
                e.vtol_state,
                MavVtolState::MAV_VTOL_STATE_MC | MavVtolState::MAV_VTOL_STATE_TRANSITION_TO_FW
            )
        }
        _ => v.mode_name().starts_with('Q'),
    }
}

/// The rotation from the hover frame's axes to the wing frame's: −90° about y.
fn hover_in_wing() -> UnitQuaternion<f64> {
    UnitQuaternion::from_euler_angles(0.0, -std::f64::consts::FRAC_PI_2, 0.0)
}

/// A wing-frame attitude (body to NED) as the hover frame's.
#[must_use]
pub fn wing_to_hover(q_wing: UnitQuaternion<f64>) -> UnitQuaternion<f64> {
    q_wing * hover_in_wing()
}

/// A hover-frame attitude as the wing frame's (what ArduPlane reports for it).
#[must_use]
pub fn hover_to_wing(q_hover: UnitQuaternion<f64>) -> UnitQuaternion<f64> {
    q_hover * hover_in_wing().inverse()
}

/// Wing-frame body rates (p, q, r) about the hover frame's axes.
#[must_use]
pub fn wing_rates_to_hover(rates: [f32; 3]) -> [f32; 3] {
    // `+ 0.0` makes a negated zero a plain one (no "-0.0" on screen).
    [rates[2], rates[1], -rates[0] + 0.0]
}

fn euler(q: &UnitQuaternion<f64>) -> [f32; 3] {
    let (r, p, y) = q.euler_angles();
    // `+ 0.0`: no "-0.0" on screen.
    [r as f32 + 0.0, p as f32 + 0.0, y as f32 + 0.0]
}

/// Where a reported attitude came from.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Source {
    /// ATTITUDE_QUATERNION: the wing frame.
    Quaternion,
    /// ATTITUDE's Euler angles: the wing frame, or an ArduPilot tailsitter's VTOL view.
    Attitude,
}

/// The reported attitude of `v` (quaternion and body rates), ATTITUDE_QUATERNION when streamed.
fn reported(
    state: &VehicleState,
    v: &VehicleView,
) -> Option<(UnitQuaternion<f64>, [f32; 3], Source)> {
    let key = |id| (v.system_id, v.component_id, id);
    let att_at = state.messages.get(&key(ATTITUDE)).map(|s| s.last_at);
    if let Some(s) = state.messages.get(&key(ATTITUDE_QUATERNION))
        && att_at.is_none_or(|a| a.saturating_duration_since(s.last_at) <= QUATERNION_FRESH)
        && let Ok(MavMessage::ATTITUDE_QUATERNION(q)) = s.last.decode()
    {
        let raw = nalgebra::Quaternion::new(
            f64::from(q.q1),
            f64::from(q.q2),
            f64::from(q.q3),
            f64::from(q.q4),
        );
        if raw.norm() > 0.5 && raw.coords.iter().all(|c| c.is_finite()) {
            return Some((
                UnitQuaternion::from_quaternion(raw),
                [q.rollspeed, q.pitchspeed, q.yawspeed],
                Source::Quaternion,
            ));
        }
    }
    let a = v.attitude?;
    let [r, p, y] = a.rpy_rad.map(f64::from);
    Some((
        UnitQuaternion::from_euler_angles(r, p, y),
        a.rates_rad_s,
        Source::Attitude,
    ))
}

/// Whether ATTITUDE (`q_att`) of a tailsitter in hover is its VTOL view already: told by AHRS2
/// (the wing frame) when it is streamed, which of the wing frame or its VTOL view ATTITUDE is
/// nearer; otherwise ArduPilot's convention for an ArduPilot vehicle, the wing frame for others.
fn attitude_is_vtol_view(
    state: &VehicleState,
    v: &VehicleView,
    q_att: &UnitQuaternion<f64>,
) -> bool {
    let key = |id| (v.system_id, v.component_id, id);
    let att_at = state.messages.get(&key(ATTITUDE)).map(|s| s.last_at);
    if let Some(s) = state.messages.get(&key(AHRS2))
        && att_at.is_none_or(|a| a.saturating_duration_since(s.last_at) <= QUATERNION_FRESH)
        && let Ok(MavMessage::AHRS2(a)) = s.last.decode_lenient().map(|l| l.msg)
        && [a.roll, a.pitch, a.yaw].iter().all(|x| x.is_finite())
    {
        let wing = UnitQuaternion::from_euler_angles(
            f64::from(a.roll),
            f64::from(a.pitch),
            f64::from(a.yaw),
        );
        return q_att.angle_to(&wing_to_hover(wing)) < q_att.angle_to(&wing);
    }
    v.autopilot == MavAutopilot::MAV_AUTOPILOT_ARDUPILOTMEGA as u8
}

/// The attitude of `v` as the operator should read it; `q_tailsit_enable` is the vehicle's
/// parameter when known.
#[must_use]
pub fn shown(
    state: &VehicleState,
    v: &VehicleView,
    q_tailsit_enable: Option<f32>,
) -> Option<Shown> {
    let (q, rates, source) = reported(state, v)?;
    if !is_tailsitter(v, q_tailsit_enable) {
        return Some(Shown {
            rpy_rad: v.attitude.map_or_else(|| euler(&q), |a| a.rpy_rad),
            rates_rad_s: rates,
            frame: AttFrame::Body,
        });
    }
    Some(if in_hover(state, v) {
        let already = source == Source::Attitude && attitude_is_vtol_view(state, v, &q);
        Shown {
            rpy_rad: if already {
                v.attitude.map_or_else(|| euler(&q), |a| a.rpy_rad)
            } else {
                euler(&wing_to_hover(q))
            },
            // ArduPilot's ATTITUDE keeps the wing frame's rates in its VTOL view.
            rates_rad_s: wing_rates_to_hover(rates),
            frame: AttFrame::Hover,
        }
    } else {
        Shown {
            rpy_rad: euler(&q),
            rates_rad_s: rates,
            frame: AttFrame::Wing,
        }
    })
}

/// Whether the shown vehicle's ATTITUDE history is to be turned into the hover frame for the
/// charts: not when ATTITUDE comes in the VTOL view already (then the charts show ATTITUDE as
/// reported, the hover's samples in the hover frame and the wing's in the wing frame).
#[must_use]
pub fn turn_history(state: &VehicleState, v: &VehicleView) -> bool {
    match reported(state, v) {
        Some((q, _, Source::Attitude)) => !attitude_is_vtol_view(state, v, &q),
        _ => true,
    }
}

/// The nose's angle above the horizon, rad, from a wing-frame attitude (+π/2: vertical).
#[must_use]
pub fn nose_up_rad(rpy_rad: [f32; 3]) -> f32 {
    let [r, p, y] = rpy_rad.map(f64::from);
    let nose = UnitQuaternion::from_euler_angles(r, p, y) * Vector3::x();
    (-nose.z).clamp(-1.0, 1.0).asin() as f32
}

#[cfg(test)]
mod tests {
    use super::*;

    const D: f64 = std::f64::consts::PI / 180.0;

    fn deg(x: [f32; 3]) -> [f64; 3] {
        x.map(|r| (f64::from(r) / D * 10.0).round() / 10.0)
    }

    fn wing(r: f64, p: f64, y: f64) -> UnitQuaternion<f64> {
        UnitQuaternion::from_euler_angles(r * D, p * D, y * D)
    }

    #[test]
    fn upright_on_the_tail_is_a_level_horizon_facing_where_the_belly_faces() {
        // ArduPlane's report of a tailsitter standing upright, belly to the east: pitch +90°,
        // and any split of roll and yaw whose difference is the same rotation.
        for (r, y) in [(0.0, 90.0), (30.0, 120.0), (-60.0, 30.0)] {
            let h = euler(&wing_to_hover(wing(r, 90.0, y)));
            let [hr, hp, hy] = deg(h);
            assert_eq!((hr, hp), (0.0, 0.0), "roll {r} yaw {y}: {h:?}");
            assert!((hy - 90.0).abs() < 0.1, "heading east, got {hy}");
        }
        // The UI once drew the reported `roll +129.9° pitch +89.9° yaw +128.5°` as it came:
        // upright within 0.1°, heading near north (yaw − roll).
        let [hr, hp, hy] = deg(euler(&wing_to_hover(wing(129.9, 89.9, 128.5))));
        assert!(hr.abs() < 1.0 && hp.abs() < 1.0, "{hr} {hp}");
        assert!(hy.abs() < 2.0 || (hy.abs() - 360.0).abs() < 2.0, "{hy}");
    }

    #[test]
    fn tipping_toward_the_belly_or_a_wing_reads_as_pitch_and_roll() {
        // The nose 80° up (10° short of vertical), belly to the north: tipped 10° forward,
        // toward the belly, as at the start of a forward transition.
        let [r, p, y] = deg(euler(&wing_to_hover(wing(0.0, 80.0, 0.0))));
        assert_eq!((r, p, y), (0.0, -10.0, 0.0));
        // Upright and leaning 15° toward the right wing: roll +15°.
        let q_h = UnitQuaternion::from_euler_angles(15.0 * D, 0.0, 40.0 * D);
        let back = euler(&wing_to_hover(hover_to_wing(q_h)));
        assert_eq!(deg(back), [15.0, 0.0, 40.0]);
        // Level forward flight in the hover frame is nose (thrust axis) 90° down.
        let [_, p, _] = deg(euler(&wing_to_hover(wing(0.0, 0.0, 0.0))));
        assert_eq!(p, -90.0);
    }

    #[test]
    fn rates_follow_the_axes() {
        // A roll rate of the wing is a yaw rate of the hover frame about its down axis, the
        // other way round; a wing yaw rate is a hover roll rate.
        assert_eq!(wing_rates_to_hover([0.1, 0.2, 0.3]), [0.3, 0.2, -0.1]);
    }

    #[test]
    fn the_nose_angle_is_the_wing_pitch_whatever_the_roll() {
        use std::f32::consts::{FRAC_PI_2, FRAC_PI_4};
        let up = |r: f32, p: f32| nose_up_rad([r, p, 0.3]).to_degrees();
        assert!((up(0.0, FRAC_PI_4) - 45.0).abs() < 0.01);
        assert!((up(1.2, FRAC_PI_4) - 45.0).abs() < 0.01);
        assert!((up(0.0, FRAC_PI_2) - 90.0).abs() < 0.01);
    }
}
