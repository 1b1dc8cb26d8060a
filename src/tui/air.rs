//! What the vehicle flies through and to, read from the last message of each kind the tracker
//! kept for it: airspeed (VFR_HUD), angle of attack and sideslip (AOA_SSA, ardupilotmega 11020),
//! the VTOL state (EXTENDED_SYS_STATE) with the progress of a transition, and the live position
//! target (POSITION_TARGET_GLOBAL_INT as ArduPilot sends it, or POSITION_TARGET_LOCAL_NED) in
//! the local NED frame. Pure, like [`crate::vitals`]: the header and the Flight view read it.

use std::time::{Duration, Instant};

use vtol_link::dialect::{MavFrame, MavMessage, MavVtolState};
use vtol_link::protocol::id::{
    AOA_SSA, EXTENDED_SYS_STATE, GLOBAL_POSITION_INT, HOME_POSITION, POSITION_TARGET_GLOBAL_INT,
    POSITION_TARGET_LOCAL_NED, VFR_HUD,
};

use crate::tracker::state::{VehicleState, VehicleView};

/// `ARSPD_FBW_MIN` when the vehicle does not publish it (ArduPlane's default), m/s.
pub const ARSPD_FBW_MIN_DEFAULT: f32 = 10.0;
/// A target older than this is no longer the vehicle's: ArduPilot streams it with its
/// extended status (1 to 4 Hz), and stops when the mode has none.
pub const TARGET_FRESH: Duration = Duration::from_secs(3);

/// Below this airspeed the air's angles mean nothing (the relative wind's direction is noise,
/// and a hovering tailsitter reads about 90° of AoA): AoA and sideslip show as "-".
pub const AIR_ANGLES_MIN_M_S: f32 = 2.0;

/// Metres per 1e-7 degree of latitude (ArduPilot's `LOCATION_SCALING_FACTOR`).
const METERS_PER_E7_DEG: f64 = 0.011_131_884_502_145_034;

/// Hover or forward flight, as EXTENDED_SYS_STATE's `vtol_state` says.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Vtol {
    /// Hover (multicopter).
    Mc,
    /// Forward transition under way.
    ToFw,
    /// Forward (fixed-wing) flight.
    Fw,
    /// Back transition under way.
    ToMc,
}

impl Vtol {
    /// The short name shown: `MC`, `→FW`, `FW`, `→MC`.
    #[must_use]
    pub fn label(self) -> &'static str {
        match self {
            Vtol::Mc => "MC",
            Vtol::ToFw => "→FW",
            Vtol::Fw => "FW",
            Vtol::ToMc => "→MC",
        }
    }
}

/// Air data and the VTOL state of one vehicle; `None` for what it does not report (and the
/// air's angles below [`AIR_ANGLES_MIN_M_S`]).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Air {
    /// True airspeed, m/s (VFR_HUD).
    pub airspeed_m_s: Option<f32>,
    /// Angle of attack, degrees (AOA_SSA).
    pub aoa_deg: Option<f32>,
    /// Sideslip, degrees (AOA_SSA).
    pub ssa_deg: Option<f32>,
    /// Hover, forward flight or a transition.
    pub vtol: Option<Vtol>,
    /// How far a transition has come, 0 to 1: a forward one by airspeed against
    /// `ARSPD_FBW_MIN`, a tailsitter's back one by the nose's way from level to vertical.
    pub progress: Option<f32>,
}

fn last(state: &VehicleState, v: &VehicleView, id: u32) -> Option<(MavMessage, Instant)> {
    let s = state.messages.get(&(v.system_id, v.component_id, id))?;
    Some((s.last.decode_lenient().ok().map(|l| l.msg)?, s.last_at))
}

/// The air data of `v`; `arspd_fbw_min` is the vehicle's `ARSPD_FBW_MIN` if known,
/// `tailsitter` whether it pitches up to hover ([`crate::tui::attitude::is_tailsitter`]).
#[must_use]
pub fn air(
    state: &VehicleState,
    v: &VehicleView,
    arspd_fbw_min: Option<f32>,
    tailsitter: bool,
) -> Air {
    let mut out = Air::default();
    if let Some((MavMessage::VFR_HUD(h), _)) = last(state, v, VFR_HUD)
        && h.airspeed.is_finite()
    {
        out.airspeed_m_s = Some(h.airspeed);
    }
    let too_slow = out.airspeed_m_s.is_some_and(|a| a < AIR_ANGLES_MIN_M_S);
    if let Some((MavMessage::AOA_SSA(a), _)) = last(state, v, AOA_SSA)
        && !too_slow
    {
        out.aoa_deg = Some(a.AOA).filter(|x| x.is_finite());
        out.ssa_deg = Some(a.SSA).filter(|x| x.is_finite());
    }
    if let Some((MavMessage::EXTENDED_SYS_STATE(e), _)) = last(state, v, EXTENDED_SYS_STATE) {
        out.vtol = match e.vtol_state {
            MavVtolState::MAV_VTOL_STATE_MC => Some(Vtol::Mc),
            MavVtolState::MAV_VTOL_STATE_TRANSITION_TO_FW => Some(Vtol::ToFw),
            MavVtolState::MAV_VTOL_STATE_FW => Some(Vtol::Fw),
            MavVtolState::MAV_VTOL_STATE_TRANSITION_TO_MC => Some(Vtol::ToMc),
            MavVtolState::MAV_VTOL_STATE_UNDEFINED => None,
        };
    }
    out.progress = match out.vtol {
        Some(Vtol::ToFw) => out.airspeed_m_s.map(|a| {
            let min = arspd_fbw_min
                .filter(|m| *m > 0.0)
                .unwrap_or(ARSPD_FBW_MIN_DEFAULT);
            (a / min).clamp(0.0, 1.0)
        }),
        // ArduPlane (and the twin) report a tailsitter's attitude in the wing frame: the
        // nose's angle above the horizon, 0 in level flight and 90° upright, is the way made.
        Some(Vtol::ToMc) if tailsitter => v.attitude.map(|a| {
            let up = crate::tui::attitude::nose_up_rad(a.rpy_rad);
            (up / std::f32::consts::FRAC_PI_2).clamp(0.0, 1.0)
        }),
        _ => None,
    };
    out
}

/// The point the vehicle flies to, local NED (m), from its own word at `now`: the last
/// POSITION_TARGET_LOCAL_NED or POSITION_TARGET_GLOBAL_INT not older than [`TARGET_FRESH`]
/// (the global one placed through HOME_POSITION, else through the vehicle's own global and
/// local position). Axes the target ignores are NaN.
#[must_use]
pub fn live_target(state: &VehicleState, v: &VehicleView, now: Instant) -> Option<[f32; 3]> {
    let fresh = |at: Instant| now.saturating_duration_since(at) <= TARGET_FRESH;
    let local = last(state, v, POSITION_TARGET_LOCAL_NED).filter(|(_, at)| fresh(*at));
    let global = last(state, v, POSITION_TARGET_GLOBAL_INT).filter(|(_, at)| fresh(*at));
    // The newer of the two when a vehicle sends both.
    let newer_local = match (&local, &global) {
        (Some((_, l)), Some((_, g))) => l >= g,
        (Some(_), None) => true,
        _ => false,
    };
    if newer_local && let Some((MavMessage::POSITION_TARGET_LOCAL_NED(t), _)) = local {
        // Offsets from the vehicle or in its body axes are no point in the local frame.
        if t.coordinate_frame != MavFrame::MAV_FRAME_LOCAL_NED {
            return None;
        }
        let ignore = t.type_mask.bits();
        let axis = |bit: u16, x: f32| if ignore & bit == 0 { x } else { f32::NAN };
        return Some([axis(1, t.x), axis(2, t.y), axis(4, t.z)]);
    }
    let Some((MavMessage::POSITION_TARGET_GLOBAL_INT(t), _)) = global else {
        return None;
    };
    let ignore = t.type_mask.bits();
    if ignore & 0b11 == 0b11 && ignore & 4 != 0 {
        return None;
    }
    // A reference point known both on the globe and in the local frame, and where home is
    // in the local frame (for altitudes relative to home).
    let (lat, lon, alt_amsl, ned, home_down) = match last(state, v, HOME_POSITION) {
        Some((MavMessage::HOME_POSITION(h), _)) => (
            h.latitude,
            h.longitude,
            f64::from(h.altitude) / 1000.0,
            [h.x, h.y, h.z],
            f64::from(h.z),
        ),
        _ => match (last(state, v, GLOBAL_POSITION_INT), v.position) {
            (Some((MavMessage::GLOBAL_POSITION_INT(g), _)), Some(p)) => (
                g.lat,
                g.lon,
                f64::from(g.alt) / 1000.0,
                p.pos_ned_m,
                f64::from(p.pos_ned_m[2]) + f64::from(g.relative_alt) / 1000.0,
            ),
            _ => return None,
        },
    };
    let dn = f64::from(t.lat_int - lat) * METERS_PER_E7_DEG;
    let mean_lat = (f64::from(t.lat_int) + f64::from(lat)) * 0.5e-7;
    let de = f64::from(t.lon_int.wrapping_sub(lon))
        * METERS_PER_E7_DEG
        * mean_lat.to_radians().cos().max(0.01);
    let down = match t.coordinate_frame {
        // Above mean sea level, as ArduPlane sends it.
        MavFrame::MAV_FRAME_GLOBAL => f64::from(ned[2]) - (f64::from(t.alt) - alt_amsl),
        // Above home (MAV_FRAME_GLOBAL_RELATIVE_ALT and its kin); the deprecated
        // MAV_FRAME_GLOBAL_INT means AMSL as well.
        f if f as u32 == 5 => f64::from(ned[2]) - (f64::from(t.alt) - alt_amsl),
        _ => home_down - f64::from(t.alt),
    };
    let axis = |bit: u16, x: f64| {
        if ignore & bit == 0 {
            x as f32
        } else {
            f32::NAN
        }
    };
    Some([
        axis(1, f64::from(ned[0]) + dn),
        axis(2, f64::from(ned[1]) + de),
        axis(4, down),
    ])
}
