//! GUIDED's requests to the navigator: the take-off, a new point to fly to, the point held.

use nalgebra::Vector3;

use super::{Leg, NavEvent, NavInput, Navigator, Refused};
use crate::model::mode::{FlightMode, VtolState};

impl Navigator {
    /// NAV_TAKEOFF in GUIDED: climb `alt_m` above where the vehicle stands.
    ///
    /// # Errors
    /// Why not: [`Refused::NotNow`] (not GUIDED, not armed, already flying) or
    /// [`Refused::Invalid`] (altitude not positive or above the envelope).
    pub fn takeoff(
        &mut self,
        alt_m: f64,
        inp: &NavInput<'_>,
        events: &mut Vec<NavEvent>,
    ) -> Result<(), Refused> {
        self.sync(inp, events);
        if inp.mode != FlightMode::Guided {
            return Err(Refused::NotNow("Takeoff: only in GUIDED mode".into()));
        }
        if !inp.armed {
            return Err(Refused::NotNow("Takeoff: must be armed".into()));
        }
        if !inp.landed || !matches!(self.leg, Leg::Idle) {
            return Err(Refused::NotNow("Takeoff: already flying".into()));
        }
        if !(alt_m.is_finite() && alt_m > 0.0) {
            return Err(Refused::Invalid(format!("Takeoff: bad altitude {alt_m} m")));
        }
        let here = inp.pos_ned_m;
        let target = Vector3::new(here.x, here.y, here.z - alt_m);
        inp.limits
            .check("Takeoff target", &target)
            .map_err(|r| Refused::Invalid(r.reason))?;
        self.z_cmd = here.z;
        self.leg = Leg::Takeoff {
            xy: here.xy(),
            z: target.z,
        };
        Ok(())
    }

    /// A new point to hold in GUIDED (DO_REPOSITION, SET_POSITION_TARGET_*), local NED.
    ///
    /// # Errors
    /// Why not: [`Refused::NotNow`] (not GUIDED, not flying) or [`Refused::Invalid`] (outside
    /// the envelope).
    pub fn reposition(
        &mut self,
        target_ned_m: Vector3<f64>,
        inp: &NavInput<'_>,
        events: &mut Vec<NavEvent>,
    ) -> Result<(), Refused> {
        self.sync(inp, events);
        if inp.mode != FlightMode::Guided {
            return Err(Refused::NotNow("Reposition: only in GUIDED mode".into()));
        }
        if !inp.armed || matches!(self.leg, Leg::Idle) {
            return Err(Refused::NotNow(
                "Reposition: not flying, take off first".into(),
            ));
        }
        if !target_ned_m.iter().all(|v| v.is_finite()) {
            return Err(Refused::Invalid(
                "Reposition: target is not a number".into(),
            ));
        }
        inp.limits
            .check("Reposition target", &target_ned_m)
            .map_err(|r| {
                Refused::Invalid(format!("Reposition refused: {}", strip_what(&r.reason)))
            })?;
        if inp.fixed_wing.guided_on_the_wing && inp.fixed_wing.vtol == VtolState::Mc {
            // Q_GUIDED_MODE 0: ArduPlane flies a GUIDED target as a plane, circling it.
            events.push(NavEvent::Transition(true));
        }
        self.leg = Leg::Goto {
            xy: target_ned_m.xy(),
            z: target_ned_m.z,
        };
        Ok(())
    }

    /// The point a GUIDED reposition without a position keeps (the current target, or here).
    #[must_use]
    pub fn hold_point(&self, here: &Vector3<f64>) -> Vector3<f64> {
        self.target_ned_m().unwrap_or(*here)
    }
}

/// "Reposition target is 150.0 m from home…" → "150.0 m from home…": the refusal sentence
/// names the target once.
fn strip_what(reason: &str) -> &str {
    reason
        .strip_prefix("Reposition target is ")
        .or_else(|| reason.strip_prefix("Reposition target "))
        .unwrap_or(reason)
}
