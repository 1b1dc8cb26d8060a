//! Flight modes. The numbers are ArduPlane's, so pymavlink and MAVProxy name them for free.
//!
//! The pilot and hover modes (QSTABILIZE, QHOVER, QLOITER, QLAND) are control laws. The
//! autonomous modes (GUIDED, AUTO, QRTL) fly those laws towards targets the navigator chooses
//! (`navigation`): each control tick they fly one [`Guidance`]. The fixed-wing modes (FBWA,
//! CRUISE) fly the forward-flight law (`control::forward`) after a tailsitter transition.

use mavlink::dialects::ardupilotmega::PlaneMode;

/// A flight mode of the twin (ArduPlane custom_mode numbers).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default)]
pub enum FlightMode {
    /// Attitude hold with pilot throttle: the paper's experiment.
    #[default]
    QStabilize,
    /// Attitude hold plus altitude hold at `HOVER_ALT`.
    QHover,
    /// Full position hold: the controller of the paper's simulation.
    QLoiter,
    /// Descend, touch down and disarm.
    QLand,
    /// Fly to the ground station's targets (take-off, reposition, position targets).
    Guided,
    /// Fly the stored mission.
    Auto,
    /// Fly home and land (ArduPlane's QRTL; RTL requests land here too).
    QRtl,
    /// Fly home on the wing (picked in forward flight; in a hover RTL is flown as QRTL), then
    /// land vertically or circle home (`Q_RTL_MODE`).
    Rtl,
    /// Fixed-wing fly-by-wire: the sticks command bank and pitch, the throttle thrust
    /// (`forward-flight.md`). Picked in the air it starts a forward transition.
    Fbwa,
    /// Fixed-wing cruise: heading, altitude and airspeed (`TRIM_ARSPD_CM`) held, the sticks
    /// move them. Picked in the air it starts a forward transition.
    Cruise,
}

/// What an autonomous mode flies during one control tick.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub enum Guidance {
    /// Armed on the ground, waiting for a take-off: the motors stay at idle.
    #[default]
    Idle,
    /// QLOITER's law to this point (paper frame, z up), m.
    Position(nalgebra::Vector3<f64>),
    /// QLAND's law: descend where the vehicle is, touch down, disarm.
    Land,
    /// Fixed-wing flight (after a forward transition): what the energy controller and the
    /// lateral guidance ask for.
    Forward(ForwardGuidance),
}

/// A fixed-wing leg's demands for one control tick.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct ForwardGuidance {
    /// Height, m (z up).
    pub height_m: f64,
    /// Airspeed, m/s.
    pub airspeed_m_s: f64,
    /// Bank, rad (positive: a turn to the right).
    pub bank_rad: f64,
}

impl FlightMode {
    /// Every mode, in number order.
    pub const ALL: [Self; 10] = [
        Self::Fbwa,
        Self::Cruise,
        Self::Auto,
        Self::Rtl,
        Self::Guided,
        Self::QStabilize,
        Self::QHover,
        Self::QLoiter,
        Self::QLand,
        Self::QRtl,
    ];

    /// The ArduPlane mode, as the dialect's `PLANE_MODE` names it.
    #[must_use]
    pub const fn plane_mode(self) -> PlaneMode {
        match self {
            Self::QStabilize => PlaneMode::PLANE_MODE_QSTABILIZE,
            Self::QHover => PlaneMode::PLANE_MODE_QHOVER,
            Self::QLoiter => PlaneMode::PLANE_MODE_QLOITER,
            Self::QLand => PlaneMode::PLANE_MODE_QLAND,
            Self::Guided => PlaneMode::PLANE_MODE_GUIDED,
            Self::Auto => PlaneMode::PLANE_MODE_AUTO,
            Self::QRtl => PlaneMode::PLANE_MODE_QRTL,
            Self::Rtl => PlaneMode::PLANE_MODE_RTL,
            Self::Fbwa => PlaneMode::PLANE_MODE_FLY_BY_WIRE_A,
            Self::Cruise => PlaneMode::PLANE_MODE_CRUISE,
        }
    }

    /// The ArduPlane `custom_mode` number.
    #[must_use]
    pub const fn custom_mode(self) -> u32 {
        self.plane_mode() as u32
    }

    /// The mode for an ArduPlane `custom_mode` number, if the twin has it.
    #[must_use]
    pub fn from_custom_mode(n: u32) -> Option<Self> {
        Self::ALL.into_iter().find(|m| m.custom_mode() == n)
    }

    /// The name pymavlink and MAVProxy show.
    #[must_use]
    pub const fn name(self) -> &'static str {
        match self {
            Self::QStabilize => "QSTABILIZE",
            Self::QHover => "QHOVER",
            Self::QLoiter => "QLOITER",
            Self::QLand => "QLAND",
            Self::Guided => "GUIDED",
            Self::Auto => "AUTO",
            Self::QRtl => "QRTL",
            Self::Rtl => "RTL",
            Self::Fbwa => "FBWA",
            Self::Cruise => "CRUISE",
        }
    }

    /// Whether the navigator chooses the targets (GUIDED, AUTO, QRTL).
    #[must_use]
    pub const fn is_autonomous(self) -> bool {
        matches!(self, Self::Guided | Self::Auto | Self::QRtl | Self::Rtl)
    }

    /// Whether the vehicle may be armed in this mode: not in the modes that can only come down
    /// (ArduPilot refuses to arm in a mode that cannot take off).
    #[must_use]
    pub const fn allows_arming(self) -> bool {
        !matches!(
            self,
            Self::QLand | Self::QRtl | Self::Rtl | Self::Fbwa | Self::Cruise
        )
    }

    /// Whether the mode flies as an aeroplane (picked in the air, it starts a forward
    /// transition). AUTO flies fixed-wing legs by its mission items instead.
    #[must_use]
    pub const fn is_fixed_wing(self) -> bool {
        matches!(self, Self::Fbwa | Self::Cruise)
    }

    /// Whether the mode is a hover (Q) mode: picked in forward flight, it starts a back
    /// transition.
    #[must_use]
    pub const fn is_q_mode(self) -> bool {
        matches!(
            self,
            Self::QStabilize | Self::QHover | Self::QLoiter | Self::QLand | Self::QRtl
        )
    }

    /// Whether the sticks fly the attitude and the heading rate (QSTABILIZE, QHOVER); every
    /// other mode flies the position law to a setpoint (its own, the navigator's or the
    /// fixed-wing modes' in a hover).
    #[must_use]
    pub const fn pilot_flies_attitude(self) -> bool {
        matches!(self, Self::QStabilize | Self::QHover)
    }

    /// Whether the mode holds altitude (and so needs the external position sensor).
    #[must_use]
    pub const fn holds_altitude(self) -> bool {
        !matches!(self, Self::QStabilize)
    }
}

impl std::str::FromStr for FlightMode {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        let up = s.to_ascii_uppercase();
        Self::ALL
            .into_iter()
            .find(|m| m.name() == up)
            .ok_or_else(|| format!("unknown mode '{s}'"))
    }
}

impl std::fmt::Display for FlightMode {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

/// Where the convertible is between hover and forward flight (MAVLink's `MAV_VTOL_STATE`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default)]
pub enum VtolState {
    /// Hovering (or on the ground): the paper's controller flies.
    #[default]
    Mc,
    /// Pitching over and accelerating to `ARSPD_FBW_MIN`.
    TransitionToFw,
    /// Flying on the wing: the forward-flight law flies.
    Fw,
    /// Pitching up and slowing to a hover.
    TransitionToMc,
}

impl VtolState {
    /// Whether the forward-flight law flies (every phase but the hover).
    #[must_use]
    pub const fn is_forward(self) -> bool {
        !matches!(self, Self::Mc)
    }
}
