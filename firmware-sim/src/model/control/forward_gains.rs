//! The forward-flight and transition parameters (ArduPlane's names), with their cross-checks.

use super::GainError;
use super::tecs::TecsLimits;
use crate::model::airframe::Airframe;
use crate::model::plant::aero;

/// Highest lift coefficient of the airframe's wing used for the stall speed (`docs/model.md`:
/// C_L peaks at 0.92 near 32°).
pub const WING_CL_MAX: f64 = 0.92;

/// Every tunable of forward flight and the transitions.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ForwardGains {
    /// `ARSPD_FBW_MIN`: lowest airspeed of fixed-wing flight; the forward transition ends here,
    /// m/s.
    pub airspeed_min_m_s: f64,
    /// `ARSPD_FBW_MAX`: highest airspeed demanded, m/s.
    pub airspeed_max_m_s: f64,
    /// `TRIM_ARSPD_CM` (in m/s here): the cruise airspeed.
    pub airspeed_trim_m_s: f64,
    /// `TECS_*`: the energy controller's time constant and climb/sink limits.
    pub tecs: TecsLimits,
    /// `LIM_ROLL_CD` (in rad here): largest bank, rad.
    pub roll_limit_rad: f64,
    /// `Q_TAILSIT_RAT_FW`: nose-down rate of the forward transition, rad/s.
    pub transition_rate_fw_rad_s: f64,
    /// `Q_TAILSIT_RAT_VT`: nose-up rate of the back transition, rad/s.
    pub transition_rate_vt_rad_s: f64,
    /// `Q_TAILSIT_ANGLE`: the nose must be at least this far from vertical before the forward
    /// transition may end, rad.
    pub transition_angle_fw_rad: f64,
    /// `Q_TAILSIT_ANG_VT`: the back transition ends when the nose is this far above the
    /// horizon, rad.
    pub transition_angle_vt_rad: f64,
    /// `Q_TRANSITION_MS` (in s here): a forward transition that has not reached
    /// `ARSPD_FBW_MIN` by then is aborted to hover.
    pub transition_timeout_s: f64,
    /// Bandwidth of the rotation-error attitude law, rad/s.
    pub attitude_bandwidth_rad_s: f64,
}

impl Default for ForwardGains {
    fn default() -> Self {
        Self {
            airspeed_min_m_s: 10.0,
            airspeed_max_m_s: 18.0,
            airspeed_trim_m_s: 12.0,
            tecs: TecsLimits {
                time_const_s: 3.0,
                climb_max_m_s: 3.0,
                sink_max_m_s: 3.0,
            },
            roll_limit_rad: 45f64.to_radians(),
            transition_rate_fw_rad_s: 50f64.to_radians(),
            transition_rate_vt_rad_s: 50f64.to_radians(),
            transition_angle_fw_rad: 45f64.to_radians(),
            transition_angle_vt_rad: 75f64.to_radians(),
            transition_timeout_s: 8.0,
            attitude_bandwidth_rad_s: 5.0,
        }
    }
}

/// Stall speed of the airframe in level flight, m/s: √(2 m g / (ρ S C_L,max)).
#[must_use]
pub fn stall_speed_m_s(af: &Airframe) -> f64 {
    (2.0 * af.weight_n() / (aero::AIR_DENSITY_KG_M3 * aero::WING_AREA_M2 * WING_CL_MAX)).sqrt()
}

impl ForwardGains {
    /// The cross-checks: FBW_MIN above the stall speed, FBW_MIN < TRIM < FBW_MAX, every value
    /// positive and finite, the transition angles inside (0°, 90°).
    ///
    /// # Errors
    /// [`GainError::Forward`] naming the broken rule.
    pub fn validate(&self, af: &Airframe) -> Result<(), GainError> {
        let fail = |rule: &'static str| Err(GainError::Forward { rule });
        let all = [
            self.airspeed_min_m_s,
            self.airspeed_max_m_s,
            self.airspeed_trim_m_s,
            self.tecs.time_const_s,
            self.tecs.climb_max_m_s,
            self.tecs.sink_max_m_s,
            self.roll_limit_rad,
            self.transition_rate_fw_rad_s,
            self.transition_rate_vt_rad_s,
            self.transition_angle_fw_rad,
            self.transition_angle_vt_rad,
            self.transition_timeout_s,
            self.attitude_bandwidth_rad_s,
        ];
        if !all.iter().all(|v| v.is_finite() && *v > 0.0) {
            return fail("every forward-flight parameter positive and finite");
        }
        if self.airspeed_min_m_s <= stall_speed_m_s(af) {
            return fail("ARSPD_FBW_MIN above the stall speed");
        }
        if !(self.airspeed_min_m_s < self.airspeed_trim_m_s
            && self.airspeed_trim_m_s < self.airspeed_max_m_s)
        {
            return fail("ARSPD_FBW_MIN < TRIM_ARSPD_CM < ARSPD_FBW_MAX");
        }
        let quarter = std::f64::consts::FRAC_PI_2;
        if self.transition_angle_fw_rad >= quarter || self.transition_angle_vt_rad >= quarter {
            return fail("Q_TAILSIT_ANGLE and Q_TAILSIT_ANG_VT below 90 degrees");
        }
        if self.roll_limit_rad >= 1.2 {
            return fail("LIM_ROLL_CD below 6900");
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn defaults_pass_and_the_stall_speed_is_about_5_m_s() {
        let af = Airframe::default();
        ForwardGains::default().validate(&af).unwrap();
        let vs = stall_speed_m_s(&af);
        assert!((5.0..6.0).contains(&vs), "{vs}");
    }

    #[test]
    fn a_minimum_below_stall_or_above_trim_is_refused() {
        let af = Airframe::default();
        for min in [4.0, 12.5] {
            let g = ForwardGains {
                airspeed_min_m_s: min,
                ..ForwardGains::default()
            };
            assert!(
                matches!(g.validate(&af), Err(GainError::Forward { .. })),
                "{min}"
            );
        }
    }
}
