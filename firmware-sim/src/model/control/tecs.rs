//! Total energy control (Lambregts 1983, ArduPlane's TECS) for forward flight: thrust holds the
//! rate of the total specific energy E = g h + ½ V², pitch holds its split between height and
//! speed (the balance g h − ½ V²). Both loops feed forward what the demanded rates need and
//! integrate the error, so the drag and lift models only have to be roughly right.
//!
//! Rates per unit mass (m²/s³): Ė = g ḣ + V V̇, Ḃ = g ḣ − V V̇. At constant thrust a change Δγ of
//! the flight-path angle moves Ḃ by about 2 g V Δγ and leaves Ė alone; at constant path angle
//! thrust moves Ė by ΔT V / m.

/// The controller's fixed tuning: what no parameter sets (the `TECS_*` parameters are
/// [`TecsLimits`]), kept together as ArduPlane keeps TECS's tuning in one parameter group.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TecsTuning {
    /// Largest speed-rate demand, m/s².
    pub speed_rate_max_m_s2: f64,
    /// Proportional gain of the thrust loop on the total-energy-rate error (fraction per s).
    pub thr_kp: f64,
    /// Integral gain of the thrust loop, 1/s.
    pub thr_ki: f64,
    /// Proportional gain of the pitch loop on the balance-rate error.
    pub pitch_kp: f64,
    /// Integral gain of the pitch loop, 1/s.
    pub pitch_ki: f64,
    /// Bound on the pitch integrator, rad.
    pub pitch_integ_max_rad: f64,
    /// Lowest speed the loops divide by, m/s.
    pub speed_floor_m_s: f64,
    /// Time constant of the speed-derivative filter, s.
    pub speed_rate_filter_s: f64,
}

impl Default for TecsTuning {
    fn default() -> Self {
        Self {
            speed_rate_max_m_s2: 2.0,
            thr_kp: 0.5,
            thr_ki: 0.3,
            pitch_kp: 0.5,
            pitch_ki: 0.3,
            pitch_integ_max_rad: 0.3,
            speed_floor_m_s: 3.0,
            speed_rate_filter_s: 0.2,
        }
    }
}

/// Limits and time constant (the `TECS_*` parameters).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TecsLimits {
    /// `TECS_TIME_CONST`: time constant of the height and speed demands, s.
    pub time_const_s: f64,
    /// `TECS_CLMB_MAX`: largest climb rate demanded, m/s.
    pub climb_max_m_s: f64,
    /// `TECS_SINK_MAX`: largest sink rate demanded, m/s.
    pub sink_max_m_s: f64,
}

/// One tick's measurements and demands.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TecsInput {
    /// Tick, s.
    pub dt_s: f64,
    /// Height and its rate, m, m/s (z up).
    pub h_m: f64,
    /// Climb rate, m/s.
    pub h_dot_m_s: f64,
    /// True airspeed, m/s.
    pub airspeed_m_s: f64,
    /// Demanded height, m.
    pub h_demand_m: f64,
    /// Demanded airspeed, m/s.
    pub airspeed_demand_m_s: f64,
    /// Modelled drag along the path at the present state, N (the thrust's feed-forward).
    pub drag_n: f64,
    /// Mass, kg; gravity, m/s².
    pub mass_kg: f64,
    /// Gravity, m/s².
    pub gravity_m_s2: f64,
    /// Largest thrust, N.
    pub thrust_max_n: f64,
}

/// What TECS asks for.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct TecsOutput {
    /// Thrust, N.
    pub thrust_n: f64,
    /// Flight-path angle demand, rad (the attitude law adds the angle of attack).
    pub path_angle_rad: f64,
}

/// The energy controller: its tuning, two integrators and the speed-rate filter.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Tecs {
    tuning: TecsTuning,
    thrust_integ_n: f64,
    pitch_integ_rad: f64,
    last_speed_m_s: Option<f64>,
    speed_rate_m_s2: f64,
}

impl Tecs {
    /// Clears the integrators (on entering forward flight).
    pub fn reset(&mut self) {
        *self = Self::default();
    }

    /// One tick.
    pub fn update(&mut self, lim: &TecsLimits, i: &TecsInput) -> TecsOutput {
        let t = self.tuning;
        let g = i.gravity_m_s2;
        let v = i.airspeed_m_s.max(t.speed_floor_m_s);
        let dt = i.dt_s.max(1e-6);
        if let Some(last) = self.last_speed_m_s {
            let raw = (i.airspeed_m_s - last) / dt;
            self.speed_rate_m_s2 +=
                (raw - self.speed_rate_m_s2) * (dt / t.speed_rate_filter_s).min(1.0);
        }
        self.last_speed_m_s = Some(i.airspeed_m_s);
        let tau = lim.time_const_s.max(0.5);
        let h_dot_d = ((i.h_demand_m - i.h_m) / tau).clamp(-lim.sink_max_m_s, lim.climb_max_m_s);
        let v_dot_d = ((i.airspeed_demand_m_s - i.airspeed_m_s) / tau)
            .clamp(-t.speed_rate_max_m_s2, t.speed_rate_max_m_s2);
        let ste_d = g * h_dot_d + v * v_dot_d;
        let ste = g * i.h_dot_m_s + v * self.speed_rate_m_s2;
        let seb_d = g * h_dot_d - v * v_dot_d;
        let seb = g * i.h_dot_m_s - v * self.speed_rate_m_s2;

        let m_over_v = i.mass_kg / v;
        let ste_err = ste_d - ste;
        let unsat = i.drag_n + m_over_v * (ste_d + t.thr_kp * ste_err) + self.thrust_integ_n;
        // Integrate only while the thrust is not pinned in the error's direction.
        let pinned = (unsat >= i.thrust_max_n && ste_err > 0.0) || (unsat <= 0.0 && ste_err < 0.0);
        if !pinned {
            self.thrust_integ_n = (self.thrust_integ_n + t.thr_ki * m_over_v * ste_err * dt)
                .clamp(-i.thrust_max_n, i.thrust_max_n);
        }
        let thrust_n = unsat.clamp(0.0, i.thrust_max_n);

        let seb_err = (seb_d - seb) / (g * v);
        self.pitch_integ_rad = (self.pitch_integ_rad + t.pitch_ki * seb_err * dt)
            .clamp(-t.pitch_integ_max_rad, t.pitch_integ_max_rad);
        let path_angle_rad =
            (h_dot_d / v).clamp(-0.5, 0.5) + t.pitch_kp * seb_err + self.pitch_integ_rad;
        TecsOutput {
            thrust_n,
            path_angle_rad,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const LIM: TecsLimits = TecsLimits {
        time_const_s: 3.0,
        climb_max_m_s: 3.0,
        sink_max_m_s: 3.0,
    };

    fn input(h: f64, v: f64) -> TecsInput {
        TecsInput {
            dt_s: 0.01,
            h_m: h,
            h_dot_m_s: 0.0,
            airspeed_m_s: v,
            h_demand_m: 20.0,
            airspeed_demand_m_s: 12.0,
            drag_n: 1.0,
            mass_kg: 0.5,
            gravity_m_s2: 9.8,
            thrust_max_n: 10.0,
        }
    }

    #[test]
    fn on_target_it_asks_for_the_drag_and_level_flight() {
        let out = Tecs::default().update(&LIM, &input(20.0, 12.0));
        assert!((out.thrust_n - 1.0).abs() < 1e-9, "{out:?}");
        assert!(out.path_angle_rad.abs() < 1e-9, "{out:?}");
    }

    #[test]
    fn low_it_adds_thrust_and_climbs_slow_it_adds_thrust_and_dives() {
        let low = Tecs::default().update(&LIM, &input(15.0, 12.0));
        assert!(low.thrust_n > 1.0 && low.path_angle_rad > 0.0, "{low:?}");
        let slow = Tecs::default().update(&LIM, &input(20.0, 9.0));
        assert!(slow.thrust_n > 1.0 && slow.path_angle_rad < 0.0, "{slow:?}");
    }
}
