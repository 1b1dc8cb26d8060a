//! What the Flight view and its charts both show of where the vehicle is meant to be and how
//! it is oriented: the setpoint and its source, and the attitude as shown.

use super::Snapshot;
use crate::tracker::state::VehicleView;
use crate::tui::app::App;

/// Where a setpoint shown comes from.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(super) enum SetpointSource {
    /// The vehicle's own live target (POSITION_TARGET_*).
    Vehicle,
    /// Where QLOITER was entered, moved by the arrows.
    Loiter,
    /// `HOVER_ALT` in QHOVER (altitude only).
    HoverAlt,
}

impl SetpointSource {
    pub(super) fn words(self) -> &'static str {
        match self {
            SetpointSource::Vehicle => "setpoint: the vehicle's live target",
            SetpointSource::Loiter => "setpoint: where QLOITER was entered",
            SetpointSource::HoverAlt => "setpoint: HOVER_ALT",
        }
    }
}

/// Modes that fly to no point: the stick modes, fixed-wing and hover, QLOITER (its hold point
/// is not in ArduPlane's target) and QLAND (straight down).
const NO_POINT_MODES: [&str; 14] = [
    "MANUAL",
    "STABILIZE",
    "TRAINING",
    "ACRO",
    "FBWA",
    "FBWB",
    "CRUISE",
    "AUTOTUNE",
    "QSTABILIZE",
    "QHOVER",
    "QLOITER",
    "QLAND",
    "QACRO",
    "QAUTOTUNE",
];

/// The setpoint (north, east, down; NaN where none) the view shows: the vehicle's live target
/// in any mode that sends one (GUIDED, AUTO, QRTL, RTL …), else the QLOITER point when it was
/// entered from a hover, else `HOVER_ALT` in QHOVER.
pub(super) fn setpoint_ned(
    app: &App,
    snap: &Snapshot<'_>,
    v: &VehicleView,
) -> Option<([f32; 3], SetpointSource)> {
    // ArduPlane sends its next waypoint as POSITION_TARGET_GLOBAL_INT in every mode but
    // MANUAL, also where it flies to no point (a stick mode, a hover): there it is stale.
    let mode = v.mode_name();
    if !NO_POINT_MODES.contains(&mode.as_str())
        && let Some(t) = crate::tui::air::live_target(snap.state, v, snap.now)
    {
        return Some((t, SetpointSource::Vehicle));
    }
    let hover = app.params.value("HOVER_ALT");
    match mode.as_str() {
        // Where QLOITER was entered from a hover; none after a back transition (the vehicle
        // holds where it stopped, and says nothing of it).
        "QLOITER" => app.target_ned.map(|t| (t, SetpointSource::Loiter)),
        "QHOVER" => hover.map(|h| ([f32::NAN, f32::NAN, -h], SetpointSource::HoverAlt)),
        _ => None,
    }
}

/// The attitude of `v` as the operator reads it: a tailsitter in hover in its hover frame.
pub(super) fn shown_attitude(
    app: &App,
    snap: &Snapshot<'_>,
    v: &VehicleView,
) -> Option<crate::tui::attitude::Shown> {
    crate::tui::attitude::shown(snap.state, v, super::q_tailsit_enable(app))
}
