//! Flight modes. The numbers are ArduPlane's, so pymavlink and MAVProxy name them for free.

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
}

impl FlightMode {
    /// Every mode, in number order.
    pub const ALL: [Self; 4] = [Self::QStabilize, Self::QHover, Self::QLoiter, Self::QLand];

    /// The ArduPlane `custom_mode` number.
    #[must_use]
    pub const fn custom_mode(self) -> u32 {
        match self {
            Self::QStabilize => 17,
            Self::QHover => 18,
            Self::QLoiter => 19,
            Self::QLand => 20,
        }
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
        }
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
