//! The tailsitter's phases (`docs/forward-flight.md`): what the vehicle flies in each, when a
//! transition starts, ends or is aborted. ArduPlane's QuadPlane tailsitter is the model: a
//! fixed-wing mode picked in the air starts a forward transition (nose down at
//! `Q_TAILSIT_RAT_FW`, thrust holding the height, done at `ARSPD_FBW_MIN` once the nose is
//! `Q_TAILSIT_ANGLE` from vertical, aborted to QLOITER after `Q_TRANSITION_MS`), a Q mode picked
//! in forward flight a back transition (nose up at `Q_TAILSIT_RAT_VT`, done when the nose is
//! `Q_TAILSIT_ANG_VT` above the horizon; the hover then holds where it ended).

use super::Vehicle;
use crate::model::airframe::ModelMode;
use crate::model::control::forward::{ForwardCommand, ForwardInput, ForwardLaw, Longitudinal};
use crate::model::control::{ControlInput, ControlOutput, forward_gains};
use crate::model::signals::PilotInput;
use nalgebra::{Vector2, Vector3};

use crate::model::estimator_forward::ForwardAttitude;
use crate::model::frames::{Euler, wrap_pi};
use crate::model::mode::{FlightMode, Guidance, VtolState};
use crate::model::plant::aero;
use crate::model::sensors::{ImuSample, PositionFix};

/// The phases' fixed tuning: what no parameter sets, kept together as ArduPilot keeps a
/// feature's tuning in one parameter group.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PhaseTuning {
    /// The forward transition ends this far above `ARSPD_FBW_MIN`, m/s: the energy controller
    /// takes over with the thrust of level flight, and the airspeed dips a little as it does;
    /// with 0.5 m/s a gust just after the hand-over took it to 9.6 m/s, below `ARSPD_FBW_MIN`.
    pub fw_entry_margin_m_s: f64,
    /// Time constant of CRUISE's heading hold, s.
    pub heading_time_const_s: f64,
    /// Full-stick nose angle change in FBWA, rad.
    pub fbwa_pitch_range_rad: f64,
    /// The back transition's pull-up starts at this multiple of the stall speed: slow enough
    /// that the climb it trades the speed for stays small (½ V² / g ≈ 2 m at 7 m/s), fast
    /// enough that the wing still turns the path up with the nose, so the plate never meets
    /// the air broadside at speed.
    pub pull_up_stall_ratio: f64,
    /// Nose angle above which the pull-up's thrust floor applies, rad.
    pub pull_up_floor_nose_rad: f64,
    /// Lag of the nose behind its command above which the pull-up's thrust floor applies, rad.
    pub pull_up_lag_rad: f64,
    /// Least thrust of the pull-up, in weights.
    pub pull_up_thrust_weights: f64,
    /// Margin above the pull-up speed at which the slowing stage ends, m/s.
    pub pull_up_speed_margin_m_s: f64,
    /// Longest slowing stage, s.
    pub slowing_max_s: f64,
    /// Time constant of the wind estimate on the wing (ground velocity less air velocity), s.
    pub wind_estimate_time_const_s: f64,
    /// Least wind, as estimated on the wing, for which the hover after a back transition turns
    /// its span into the wind, m/s.
    pub weathervane_min_wind_m_s: f64,
    /// Rate at which the hover turns its span into the wind, rad/s (ArduPilot's weathervaning,
    /// rate-limited): the plate passes slowly through the angles where its yaw and pitch
    /// moments are largest; 0.5 rad/s brought it down in most runs.
    pub weathervane_rate_rad_s: f64,
}

impl Default for PhaseTuning {
    fn default() -> Self {
        Self {
            fw_entry_margin_m_s: 1.5,
            heading_time_const_s: 2.0,
            fbwa_pitch_range_rad: 0.35,
            pull_up_stall_ratio: 1.1,
            pull_up_floor_nose_rad: 0.45,
            pull_up_lag_rad: 0.15,
            pull_up_thrust_weights: 0.5,
            pull_up_speed_margin_m_s: 0.3,
            slowing_max_s: 6.0,
            wind_estimate_time_const_s: 5.0,
            weathervane_min_wind_m_s: 1.0,
            weathervane_rate_rad_s: 0.1,
        }
    }
}

/// The forward-flight side of the vehicle: the phase, its clock and targets, and the law.
#[derive(Debug, Clone, Default)]
pub struct ForwardFlight {
    tuning: PhaseTuning,
    state: VtolState,
    law: ForwardLaw,
    phase_time_s: f64,
    nose_cmd_rad: f64,
    heading_rad: f64,
    height_m: f64,
    /// What the last forward transition ended in (for the record: aborted or not).
    aborted: bool,
    /// The back transition's first stage: slowing down on the wing at constant height.
    slowing: bool,
    /// The attitude filter of forward flight (estimator mode only; from the first tick of a
    /// forward transition to the end of the back transition).
    attitude: Option<ForwardAttitude>,
    /// The heading the hover holds after a back transition (the one it ended with, as
    /// ArduPlane keeps it), rad; 0 until the first one, and again from each arming.
    hover_heading_rad: f64,
    /// The wind estimated on the wing (ground velocity less air velocity, low-passed),
    /// inertial x, y, m/s.
    wind_m_s: Vector2<f64>,
    /// Whether the hover turns its span into [`Self::wind_m_s`] (after a back transition).
    weathervane: bool,
}

impl ForwardFlight {
    /// The heading the hover's position modes hold, rad.
    #[must_use]
    pub fn hover_heading_rad(&self) -> f64 {
        self.hover_heading_rad
    }

    /// Forgets the heading of the last back transition (on arming).
    pub fn clear_hover_heading(&mut self) {
        self.hover_heading_rad = 0.0;
        self.weathervane = false;
    }

    /// The wind estimated on the wing, inertial x, y, m/s.
    #[must_use]
    pub fn wind_estimate_m_s(&self) -> Vector2<f64> {
        self.wind_m_s
    }

    /// Turns the hover's heading toward the nearer of the two that put the span (y_B) into
    /// the wind estimated on the wing, at [`PhaseTuning::weathervane_rate_rad_s`]: a 3 m/s wind on the
    /// plate's face needs more lean than `Q_ANGLE_MAX`, along its span 9° (`docs/model.md`).
    fn weathervane_step(&mut self, dt_s: f64) {
        let w = self.wind_m_s;
        if !self.weathervane || w.norm() < self.tuning.weathervane_min_wind_m_s {
            return;
        }
        let toward = w.y.atan2(w.x);
        let h = self.hover_heading_rad;
        let a = wrap_pi(toward + std::f64::consts::FRAC_PI_2 - h);
        let b = wrap_pi(toward - std::f64::consts::FRAC_PI_2 - h);
        let err = if a.abs() <= b.abs() { a } else { b };
        let step = self.tuning.weathervane_rate_rad_s * dt_s;
        self.hover_heading_rad = wrap_pi(h + err.clamp(-step, step));
    }

    /// The phase.
    #[must_use]
    pub fn state(&self) -> VtolState {
        self.state
    }

    /// Whether the last forward transition was aborted by `Q_TRANSITION_MS`.
    #[must_use]
    pub fn last_transition_aborted(&self) -> bool {
        self.aborted
    }
}

/// The nose's angle above the horizon for this rotation body → inertial: asin of z_B's
/// vertical component.
fn nose_angle_rad(r: &nalgebra::Matrix3<f64>) -> f64 {
    r[(2, 2)].clamp(-1.0, 1.0).asin()
}

impl Vehicle {
    /// The phase between hover and forward flight.
    #[must_use]
    pub fn vtol_state(&self) -> VtolState {
        self.forward.state
    }

    /// The forward-flight side (phase, abort record).
    #[must_use]
    pub fn forward_flight(&self) -> &ForwardFlight {
        &self.forward
    }

    /// Starts a forward transition if the vehicle hovers in the air (or is coming back to a
    /// hover). Returns whether it started.
    pub fn start_forward_transition(&mut self) -> bool {
        // `paper` mode is the paper's hover model: it has no forward flight.
        if !self.telemetry.armed || self.on_ground || self.config.model == ModelMode::Paper {
            return false;
        }
        if !matches!(
            self.forward.state,
            VtolState::Mc | VtolState::TransitionToMc
        ) {
            return false;
        }
        let r = self.plant_trig.rotation_body_to_inertial();
        let f = &mut self.forward;
        if f.state == VtolState::Mc {
            f.law.reset();
            f.height_m = self.plant.pos_m.z;
            f.heading_rad = self.telemetry.euler_est.psi;
        }
        f.state = VtolState::TransitionToFw;
        f.phase_time_s = 0.0;
        f.nose_cmd_rad = nose_angle_rad(&r);
        f.aborted = false;
        self.telemetry.vtol_state = f.state;
        true
    }

    /// Starts a back transition if the vehicle flies forward (or is transitioning to). Returns
    /// whether it started.
    pub fn start_back_transition(&mut self) -> bool {
        if !self.forward.state.is_forward() || self.forward.state == VtolState::TransitionToMc {
            return false;
        }
        let r = self.plant_trig.rotation_body_to_inertial();
        let air = r * self.telemetry.air_velocity_body_m_s;
        let f = &mut self.forward;
        f.state = VtolState::TransitionToMc;
        f.phase_time_s = 0.0;
        f.slowing = true;
        f.nose_cmd_rad = nose_angle_rad(&r);
        f.height_m = self.plant.pos_m.z;
        f.heading_rad = if air.xy().norm() > 1.0 {
            air.y.atan2(air.x)
        } else {
            self.telemetry.euler_est.psi
        };
        self.telemetry.vtol_state = f.state;
        true
    }

    /// A mode change's effect on the phase: a fixed-wing mode in the air starts a forward
    /// transition, a Q mode in forward flight a back transition.
    pub(super) fn vtol_mode_changed(&mut self, mode: FlightMode) {
        if mode.is_fixed_wing() {
            self.start_forward_transition();
        } else if mode.is_q_mode() {
            self.start_back_transition();
        }
    }

    /// Drops back to hover at once (disarm, crash, landing).
    pub(super) fn forward_reset(&mut self) {
        self.forward.attitude = None;
        self.forward.state = VtolState::Mc;
        self.forward.law.reset();
        self.telemetry.vtol_state = VtolState::Mc;
    }

    /// The forward-flight law's output this tick, or `None` in hover (the paper's law flies).
    /// One function for the three phases: each ends or aborts on the state the others read,
    /// and splitting them would pass the same half-dozen values back and forth.
    pub(super) fn forward_tick(&mut self, input: &ControlInput) -> Option<ControlOutput> {
        if self.forward.state == VtolState::Mc && self.telemetry.armed && !self.on_ground {
            self.forward.weathervane_step(input.dt_s);
        }
        if !self.forward.state.is_forward() || !self.telemetry.armed {
            return None;
        }
        let gains = self.config.gains.forward;
        let tuning = self.forward.tuning;
        let dt = input.dt_s;
        let r = input.euler.rotation_body_to_inertial();
        let airspeed = self.telemetry.air_velocity_body_m_s.norm();
        if self.forward.state == VtolState::Fw {
            let air = r * self.telemetry.air_velocity_body_m_s;
            let w = input.vel_m_s.xy() - air.xy();
            let k = (dt / tuning.wind_estimate_time_const_s).min(1.0);
            self.forward.wind_m_s += k * (w - self.forward.wind_m_s);
        }
        self.forward.phase_time_s += dt;
        let cmd = match self.forward.state {
            VtolState::TransitionToFw => {
                let f = &mut self.forward;
                // The nose goes down to the angle of level flight at the trim airspeed.
                let v_end = gains.airspeed_trim_m_s.max(airspeed);
                let q = 0.5 * aero::AIR_DENSITY_KG_M3 * v_end.powi(2);
                let level = f
                    .law
                    .tuning()
                    .alpha_for_lift(self.config.airframe.weight_n() / (q * aero::WING_AREA_M2));
                f.nose_cmd_rad = (f.nose_cmd_rad - gains.transition_rate_fw_rad_s * dt).max(level);
                let from_vertical = std::f64::consts::FRAC_PI_2 - nose_angle_rad(&r);
                if airspeed >= gains.airspeed_min_m_s + tuning.fw_entry_margin_m_s
                    && from_vertical >= gains.transition_angle_fw_rad
                {
                    f.state = VtolState::Fw;
                    f.phase_time_s = 0.0;
                } else if f.phase_time_s > gains.transition_timeout_s {
                    // Abort: back to a hover where the transition began its height.
                    f.aborted = true;
                    self.telemetry.mode = FlightMode::QLoiter;
                    self.controller.reset();
                    self.start_back_transition();
                }
                self.transition_command()
            }
            VtolState::TransitionToMc if self.forward.slowing => {
                // Slow down on the wing first: the stalled plate's moment at speed is more
                // than the elevator can hold, so the nose comes up only near the pull-up speed.
                let f = &mut self.forward;
                let slow = tuning.pull_up_stall_ratio
                    * forward_gains::stall_speed_m_s(&self.config.airframe);
                if airspeed <= slow + tuning.pull_up_speed_margin_m_s
                    || f.phase_time_s > tuning.slowing_max_s
                {
                    f.slowing = false;
                    f.nose_cmd_rad = nose_angle_rad(&r);
                }
                ForwardCommand {
                    longitudinal: Longitudinal::Energy {
                        height_m: f.height_m,
                        airspeed_m_s: slow,
                    },
                    bank_rad: 0.0,
                    heading_rad: f.heading_rad,
                }
            }
            VtolState::TransitionToMc => {
                let f = &mut self.forward;
                f.nose_cmd_rad = (f.nose_cmd_rad + gains.transition_rate_vt_rad_s * dt)
                    .min(std::f64::consts::FRAC_PI_2);
                if nose_angle_rad(&r) >= gains.transition_angle_vt_rad
                    || f.phase_time_s > gains.transition_timeout_s
                {
                    // The hover holds where the transition ended, as ArduPlane's does.
                    let hold = input.pos_m;
                    self.forward.hover_heading_rad = input.euler.psi;
                    self.forward.weathervane = true;
                    if let Some(att) = self.forward.attitude.take() {
                        self.estimator
                            .realign(att.euler(), &input.pos_m, &input.vel_m_s);
                    }
                    self.forward_reset();
                    self.controller.reset();
                    if !self.telemetry.mode.is_autonomous() {
                        self.setpoint_m = hold;
                    }
                    return None;
                }
                self.transition_command()
            }
            VtolState::Fw => self.fixed_wing_command(input, airspeed),
            VtolState::Mc => return None,
        };
        self.telemetry.vtol_state = self.forward.state;
        let fin = ForwardInput {
            dt_s: dt,
            euler: input.euler,
            omega_body_rad_s: input.omega_body_rad_s,
            pos_m: input.pos_m,
            vel_m_s: input.vel_m_s,
            air_velocity_body_m_s: self.telemetry.air_velocity_body_m_s,
            rotor_speed_rad_s: input.rotor_speed_rad_s,
        };
        Some(
            self.forward
                .law
                .update(&self.config.airframe, &gains, &fin, &cmd),
        )
    }

    /// Updates the forward-flight attitude filter in the forward phases (`estimator_forward`);
    /// returns false in hover, where the hover estimator runs.
    pub(super) fn forward_estimate(
        &mut self,
        imu: &ImuSample,
        fix: &PositionFix,
        heading_rad: Option<f64>,
    ) -> bool {
        if !self.forward.state.is_forward() || !self.telemetry.armed {
            self.forward.attitude = None;
            return false;
        }
        let af = &self.config.airframe;
        let estimator = &self.estimator;
        let att = self.forward.attitude.get_or_insert_with(|| {
            ForwardAttitude::new(estimator.euler(), estimator.gyro_bias_rad_s())
        });
        // The accelerometer's missing z axis: the commanded thrust and the modelled
        // aerodynamic force along the nose, from the airspeed sensor's air velocity.
        let aero_z = aero::loads(
            af,
            &self.telemetry.air_velocity_body_m_s,
            &self.actuators.state.rotor_speed_rad_s,
        )
        .force_body_n
        .z;
        let bias = estimator.accel_bias_m_s2();
        let force = Vector3::new(
            imu.accel_m_s2[0] - bias[0],
            imu.accel_m_s2[1] - bias[1],
            (self.telemetry.control.fz_n + aero_z) / af.mass_kg,
        );
        att.update(
            self.control_dt_s,
            af.gravity_m_s2,
            &imu.gyro_rad_s,
            &force,
            &fix.vel_m_s,
            heading_rad,
        );
        true
    }

    /// The attitude and body rates the controller flies on in estimator mode: the forward
    /// filter's in the forward phases, the hover estimator's otherwise.
    pub(super) fn estimated_attitude(&self) -> (Euler, Vector3<f64>) {
        match &self.forward.attitude {
            Some(att) if self.forward.state.is_forward() => (att.euler(), att.omega_rad_s()),
            _ => (self.estimator.euler(), self.estimator.omega_rad_s()),
        }
    }

    fn transition_command(&self) -> ForwardCommand {
        let f = &self.forward;
        let nose = nose_angle_rad(&self.plant_trig.rotation_body_to_inertial());
        ForwardCommand {
            longitudinal: Longitudinal::NoseAngle {
                nose_rad: f.nose_cmd_rad,
                height_m: f.height_m,
                // Once the nose is up and lags its command (the elevator saturated against the
                // wing's moment near the stall), the pull-up raises the thrust toward the
                // hover's for that angle: its wash gives the elevator the authority it lacks.
                thrust_min_n: if f.state == VtolState::TransitionToMc
                    && nose >= f.tuning.pull_up_floor_nose_rad
                    && f.nose_cmd_rad - nose > f.tuning.pull_up_lag_rad
                {
                    f.tuning.pull_up_thrust_weights * self.config.airframe.weight_n()
                        / nose.sin().max(0.5)
                } else {
                    0.0
                },
            },
            bank_rad: 0.0,
            heading_rad: f.heading_rad,
        }
    }

    /// What the fixed-wing modes fly: CRUISE holds the height, the trim airspeed and the
    /// heading it was entered with; FBWA flies the sticks; AUTO and GUIDED their guidance.
    fn fixed_wing_command(&mut self, input: &ControlInput, airspeed: f64) -> ForwardCommand {
        let gains = self.config.gains.forward;
        let f = &self.forward;
        let g = self.config.airframe.gravity_m_s2;
        let course = input.vel_m_s.y.atan2(input.vel_m_s.x);
        let heading_hold = |target: f64| {
            let lateral = airspeed * wrap_pi(target - course) / f.tuning.heading_time_const_s;
            -(lateral / g).atan()
        };
        let energy = |height_m: f64, airspeed_m_s: f64| Longitudinal::Energy {
            height_m,
            airspeed_m_s,
        };
        match (self.telemetry.mode, self.guidance) {
            (FlightMode::Fbwa, _) => {
                let p: PilotInput = input.pilot;
                let fz_max = 2.0
                    * self.config.airframe.k_thrust_n_per_rad2_s2
                    * self.config.airframe.rotor_speed_max_rad_s.powi(2);
                ForwardCommand {
                    longitudinal: Longitudinal::Manual {
                        nose_rad: 0.1 + f.tuning.fbwa_pitch_range_rad * p.pitch,
                        thrust_n: p.throttle * fz_max,
                    },
                    bank_rad: gains.roll_limit_rad * p.roll,
                    heading_rad: f.heading_rad,
                }
            }
            (_, Guidance::Forward(fw)) if self.telemetry.mode.is_autonomous() => ForwardCommand {
                longitudinal: energy(
                    fw.height_m,
                    fw.airspeed_m_s
                        .clamp(gains.airspeed_min_m_s, gains.airspeed_max_m_s),
                ),
                bank_rad: fw.bank_rad,
                heading_rad: f.heading_rad,
            },
            _ => ForwardCommand {
                longitudinal: energy(f.height_m, gains.airspeed_trim_m_s),
                bank_rad: heading_hold(f.heading_rad),
                heading_rad: f.heading_rad,
            },
        }
    }
}
