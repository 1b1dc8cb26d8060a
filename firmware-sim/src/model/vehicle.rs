//! `Vehicle::step(dt)`: one physics step of the whole twin — sensors → estimator → controller →
//! actuators → plant — synchronous, deterministic (seeded RNG, no wall clock) and free of
//! allocation. The MAVLink endpoint and the offline `simulate` command both drive it.
//!
//! Frames are the paper's (inertial z up, body thrust along +z_B). The plant is integrated with
//! RK4 at [`PHYSICS_DT_S`] (by default; [`VehicleConfig::physics_dt_us`]).
//!
//! * `physical`: sensors, estimator and controller run every control period (100 Hz by
//!   default) and their outputs are held in between, as the firmware's PWM is; the controller
//!   sees the estimator and the position sensor (or the true state with
//!   [`VehicleConfig::perfect_state`]) and drives PWM through the actuator models.
//! * `paper`: the paper's simulation is continuous-time, so the controller is part of the
//!   vector field: it is evaluated on the true state at every RK4 stage of every physics step
//!   and drives the plant directly ([I17], [I18]). A sampled controller would hold f_x of (43)
//!   over the control period, and because (43) cancels g·sin θ that leaves an error of order
//!   g·θ̇·Δt in ẍ, as large as the x loop's own acceleration.
//!
//! The control tick runs at the END of a step whose end time is a tick time (and once at
//! construction), so the telemetry of time t always carries the controller's output at t.

use nalgebra::Vector3;

use crate::model::airframe::{Airframe, ModelMode};
use crate::model::control::{ControlInput, ControlOutput, Controller, GainError, Gains};
use crate::model::estimator::Estimator;
use crate::model::frames::Euler;
use crate::model::integrator::rk4_step;
use crate::model::mode::{FlightMode, Guidance};
use crate::model::plant::actuators::{ActuatorModel, DISARMED_PWM_US};
use crate::model::plant::battery::{Battery, BatteryConfig};
use crate::model::plant::rigid_body::{EulerTrig, RigidBody};
use crate::model::plant::{self, PlantInput, PlantState, aero, ground, surface_airflow};
use crate::model::sensors::{self, Sensors};
use crate::model::signals::{ActuatorCommand, CRASH_TILT_RAD, PilotInput};

mod arming;
mod forward_flight;
mod power;
mod telemetry;
mod wind;

pub use forward_flight::ForwardFlight;
pub use telemetry::{ArmError, SystemState, Telemetry};
pub use wind::GUST_TIME_CONSTANT_S;
use wind::Wind;

/// The default physics step: the plant is integrated at 1 kHz.
pub const PHYSICS_DT_S: f64 = 0.001;
/// The default physics step in µs (the simulation clock counts whole steps).
pub const PHYSICS_DT_US: u64 = 1000;
/// cos([`CRASH_TILT_RAD`]), compared with cos θ cos φ every step.
const CRASH_COS_TILT: f64 = 0.5;
/// Sink rate at touchdown above which the landing is a crash, m/s.
pub const CRASH_SINK_RATE_M_S: f64 = 3.0;
/// The aerodynamic loads are evaluated every this many physics steps and held in between (4 ms
/// at 1 kHz): the fastest aerodynamic time constant, the slipstream's crossflow damping, is
/// about 0.9 s near hover (`docs/model.md`), so the hold costs nothing in accuracy and keeps the
/// flight benchmark's real-time factor.
pub const AERO_EVERY_STEPS: u64 = 4;
/// Time on the ground after which QLAND disarms, s.
pub const LAND_DISARM_DELAY_S: f64 = 0.5;
/// Largest estimated tilt at which arming is allowed, rad.
pub const ARM_MAX_TILT_RAD: f64 = 0.2;
/// QLOITER on the ground idles while its point is at most this far above the vehicle, m.
const LOITER_GROUND_HOLD_M: f64 = 0.05;
/// Period of the battery model, s: it drains slowly, so 10 Hz is plenty and costs the control
/// loop nothing.
const BATTERY_PERIOD_S: f64 = 0.1;

/// Rigid-body state in the paper's frames (z up). See `plant` for the equations.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct InitialState {
    /// Position ξ = (x, y, z), m.
    pub pos_m: Vector3<f64>,
    /// Attitude η = (ψ, θ, φ).
    pub euler: Euler,
}

/// How to build a vehicle.
#[derive(Debug, Clone, PartialEq)]
pub struct VehicleConfig {
    /// Physical constants.
    pub airframe: Airframe,
    /// `paper` or `physical` (`PHYSICS.md` §0).
    pub model: ModelMode,
    /// Noise, bias and quantisation off when true (the firmware still flies on its estimator).
    pub ideal_sensors: bool,
    /// The controller reads the true state instead of the estimator and the position sensor
    /// (perfect sensing; `paper` mode always does).
    pub perfect_state: bool,
    /// The motion-capture heading is fused in the modes that fly on the motion capture
    /// (QHOVER, QLOITER, QLAND). Off: yaw from the gyros only, as in QSTABILIZE.
    pub heading_sensor: bool,
    /// Physics step, µs (1000 by default; the control period is rounded to whole steps).
    pub physics_dt_us: u64,
    /// Seed of every random draw.
    pub seed: u64,
    /// Control loop rate, Hz (100 by default).
    pub control_rate_hz: f64,
    /// Start state (velocities and rates are zero).
    pub initial: InitialState,
    /// Controller gains and levels.
    pub gains: Gains,
    /// Flight mode at start.
    pub mode: FlightMode,
    /// Start armed (the offline `simulate` command flies from t = 0).
    pub armed: bool,
    /// The gyros were calibrated at rest before sim time 0, so the vehicle is ready to arm at
    /// once (`firmware-sim serve` starts so). False: the firmware calibrates for
    /// [`crate::model::estimator::CALIBRATION_TIME_S`] at rest after power-up, as the hardware does
    /// (and as a reboot does); arming is refused until then.
    pub calibrated: bool,
    /// QLOITER's position setpoint at start (paper frame, z up), m; `None` = (0, 0,
    /// `HOVER_ALT`). Given here rather than set after construction because the controller's
    /// output at t = 0 is computed at construction.
    pub position_setpoint_m: Option<Vector3<f64>>,
    /// RC receiver pulse widths at start, µs (0 = no signal), as [`Vehicle::set_rc_input`].
    pub rc_us: [u16; 8],
    /// The flight battery (full at start); by default a bench supply that never runs flat.
    pub battery: BatteryConfig,
}

impl Default for VehicleConfig {
    fn default() -> Self {
        Self {
            airframe: Airframe::default(),
            model: ModelMode::Physical,
            ideal_sensors: false,
            perfect_state: false,
            heading_sensor: true,
            physics_dt_us: PHYSICS_DT_US,
            seed: 1,
            control_rate_hz: 100.0,
            initial: InitialState::default(),
            gains: Gains::default(),
            mode: FlightMode::QStabilize,
            armed: false,
            calibrated: false,
            position_setpoint_m: None,
            rc_us: [0; 8],
            battery: BatteryConfig::bench_supply(),
        }
    }
}

/// The twin.
#[derive(Debug, Clone)]
pub struct Vehicle {
    config: VehicleConfig,
    plant: PlantState,
    /// Sines and cosines of `plant.euler`, kept with the state (computed once per step).
    plant_trig: EulerTrig,
    /// The airframe's mass properties as the equations of motion use them.
    body: RigidBody,
    actuators: ActuatorModel,
    /// What the plant is driven with during the current step.
    input: PlantInput,
    sensors: Sensors,
    estimator: Estimator,
    controller: Controller,
    setpoint_m: Vector3<f64>,
    on_ground: bool,
    landed_time_s: f64,
    steps: u64,
    control_every_steps: u64,
    control_dt_s: f64,
    dt_s: f64,
    dt_us: u64,
    /// Fault injection: a constant error added to the heading the controller flies on.
    chain_heading_error_rad: f64,
    /// The controller's input of the last tick (`paper` mode evaluates the controller at the
    /// RK4 stages with the same mode, setpoint and pilot input).
    last_control_input: ControlInput,
    push_torque_body_nm: Vector3<f64>,
    push_steps_left: u64,
    wind: Wind,
    /// What GUIDED, AUTO and QRTL fly (set by the navigator).
    guidance: Guidance,
    battery: Battery,
    /// Time not yet drawn from the battery, s.
    battery_pending_s: f64,
    /// Forward flight and the transitions (`forward_flight`).
    forward: ForwardFlight,
    telemetry: Telemetry,
}

impl Vehicle {
    /// A vehicle at rest at `config.initial`. With `initial.pos_m.z ≤ 0` it stands on the
    /// ground (level, at z = 0). A vehicle configured `armed` starts calibrated and, if it
    /// starts in the air, with its rotors at hover speed (it was launched from a hover).
    // Long: most of it is the one struct literal of the vehicle's state; the rest picks its start
    // (on the ground or in the air, calibrated or not, armed or not).
    #[must_use]
    pub fn new(config: VehicleConfig) -> Self {
        let af = &config.airframe;
        let dt_us = config.physics_dt_us.max(1);
        let dt_s = dt_us as f64 * 1e-6;
        let control_every_steps = match config.model {
            // Continuous-time: the controller runs at every step (and inside it).
            ModelMode::Paper => 1,
            ModelMode::Physical => {
                ((1.0 / (config.control_rate_hz.max(1.0) * dt_s)).round() as u64).max(1)
            }
        };
        let control_dt_s = control_every_steps as f64 * dt_s;
        let mut plant = PlantState::at_rest(config.initial.pos_m, config.initial.euler);
        let on_ground = plant.pos_m.z <= 0.0;
        if on_ground {
            plant = ground::resting(&plant);
        }
        let mut sensors = Sensors::new(config.ideal_sensors, config.seed, control_dt_s);
        let mut estimator = Estimator::new(plant.euler, control_dt_s, af.gravity_m_s2);
        let mut actuators = ActuatorModel::new(af, dt_s);
        let mut state = SystemState::Calibrating;
        if config.model == ModelMode::Paper || config.ideal_sensors || config.perfect_state {
            estimator.skip_calibration();
            state = SystemState::Standby;
        } else if config.armed || config.calibrated {
            // Launched armed or ready: the gyros were calibrated at rest before, with the same
            // sensors.
            let rest = Vector3::new(0.0, 0.0, af.gravity_m_s2);
            while !estimator.calibrate(&sensors.sample_imu(&Vector3::zeros(), &rest)) {}
            state = SystemState::Standby;
        }
        if config.armed {
            state = SystemState::Active;
            if !on_ground {
                let w = af.hover_rotor_speed_rad_s();
                actuators.state.rotor_speed_rad_s = [w, w];
            }
        }
        let mut v = Self {
            plant,
            plant_trig: EulerTrig::new(&plant.euler),
            body: RigidBody::new(af),
            actuators,
            input: PlantInput::default(),
            sensors,
            estimator,
            controller: Controller::new(config.airframe.clone(), config.model),
            setpoint_m: config
                .position_setpoint_m
                .unwrap_or_else(|| Vector3::new(0.0, 0.0, config.gains.hover_alt_m)),
            on_ground,
            landed_time_s: 0.0,
            steps: 0,
            control_every_steps,
            control_dt_s,
            dt_s,
            dt_us,
            last_control_input: ControlInput::default(),
            chain_heading_error_rad: 0.0,
            push_torque_body_nm: Vector3::zeros(),
            push_steps_left: 0,
            wind: Wind::new(config.seed, dt_s),
            guidance: Guidance::Idle,
            battery: Battery::new(config.battery),
            battery_pending_s: 0.0,
            forward: ForwardFlight::default(),
            telemetry: Telemetry {
                mode: config.mode,
                armed: config.armed,
                rc_us: config.rc_us,
                state,
                euler_est: plant.euler,
                pwm_us: DISARMED_PWM_US,
                control: ControlOutput {
                    pwm_us: DISARMED_PWM_US,
                    ..ControlOutput::default()
                },
                battery: *Battery::new(config.battery).state(),
                ..Telemetry::default()
            },
            config,
        };
        v.input.actuators = v.actuators.state;
        v.refresh_truth();
        // The controller's output at t = 0 (the first row of a flight log carries it).
        v.control_tick();
        v
    }

    /// Advances the twin by one physics step ([`PHYSICS_DT_S`] by default).
    pub fn step(&mut self) {
        self.hold_inputs();
        let af = &self.config.airframe;
        let model = self.config.model;
        let dt = self.dt_s;

        if self.on_ground {
            let trig = EulerTrig::new(&self.plant.euler);
            let loads = plant::loads(af, model, &trig, &self.plant, &self.input);
            let vertical = (trig.rotation_body_to_inertial() * loads.force_body_n).z;
            if ground::lifts_off(vertical, af.weight_n()) {
                self.on_ground = false;
            }
        }
        if !self.on_ground {
            self.fly(dt);
        }
        self.landed_bookkeeping(dt);

        self.steps += 1;
        self.telemetry.t_us += self.dt_us;
        self.refresh_truth();
        if self.steps.is_multiple_of(self.control_every_steps) {
            self.control_tick();
        }
    }

    /// The plant's inputs for this step. Actuators: hold the controller's outputs between
    /// control ticks; the paper's thrust, a push's torque, the wind's step and (physical model)
    /// the airframe's aerodynamics.
    fn hold_inputs(&mut self) {
        let af = &self.config.airframe;
        let model = self.config.model;
        match model {
            ModelMode::Physical => self.actuators.step(af, &self.telemetry.pwm_us),
            ModelMode::Paper => {
                self.actuators.state = if self.telemetry.armed {
                    self.telemetry.control.actuators
                } else {
                    ActuatorCommand::default()
                };
            }
        }
        self.input.actuators = self.actuators.state;
        self.input.fx_paper_n = match model {
            ModelMode::Paper if self.telemetry.armed => self.telemetry.control.fx_n,
            _ => 0.0,
        };
        self.input.disturbance_torque_body_nm = if self.push_steps_left > 0 {
            self.push_steps_left -= 1;
            self.push_torque_body_nm
        } else {
            Vector3::zeros()
        };
        self.input.wind_m_s = self.wind.step();
        if model == ModelMode::Physical && self.steps.is_multiple_of(AERO_EVERY_STEPS) {
            // The airframe's aerodynamics, held over [`AERO_EVERY_STEPS`] steps like the
            // actuators over a control period: its time constants are hundreds of steps long.
            let v_air = self.air_velocity_body_m_s();
            let mut loads = aero::loads(af, &v_air, &self.input.actuators.rotor_speed_rad_s);
            let stream = surface_airflow::free_stream_loads(af, &v_air, &self.input.actuators);
            loads.force_body_n += stream.force_body_n;
            loads.torque_body_nm += stream.torque_body_nm;
            self.input.aero = loads;
        }
    }

    /// One step in the air: the plant integrated over `dt`, then touchdown (a crash if too hard
    /// or tilted) or a crash by tilt.
    fn fly(&mut self, dt: f64) {
        let af = &self.config.airframe;
        let model = self.config.model;
        let input = self.input;
        let start = self.plant.euler;
        let start_trig = self.plant_trig;
        // `paper`: the controller is part of the vector field. The first stage is the
        // step's start, where the last tick already evaluated it on the same state. The
        // sampled path keeps its own closure: copying the input per stage costs ~10 %.
        if model == ModelMode::Paper && self.telemetry.armed {
            let (controller, gains) = (&self.controller, &self.config.gains);
            let template = self.last_control_input;
            let mut first_stage = true;
            self.plant = rk4_step(&self.plant, dt, |s| {
                let trig = start_trig.shifted(&start, &s.euler);
                let mut u = input;
                if !first_stage {
                    let ci = ControlInput {
                        euler: s.euler,
                        omega_body_rad_s: s.omega_body_rad_s,
                        pos_m: s.pos_m,
                        vel_m_s: trig.rotate_body_to_inertial(&s.vel_body_m_s),
                        ..template
                    };
                    // A copy: the stages are trial points, only the tick updates the state.
                    let out = controller.clone().update(&ci, gains);
                    u.actuators = out.actuators;
                    u.fx_paper_n = out.fx_n;
                }
                first_stage = false;
                plant::derivative_with_trig(af, model, s, &u, &trig)
            });
        } else {
            // The input is held over the step: its loads are computed once.
            let held = plant::HeldLoads::new(af, model, &input);
            let body = &self.body;
            let mut first_stage = true;
            self.plant = rk4_step(&self.plant, dt, |s| {
                // The first stage is the step's start, whose trig is known.
                let trig = if first_stage {
                    first_stage = false;
                    start_trig
                } else {
                    start_trig.shifted(&start, &s.euler)
                };
                plant::derivative_held(af, body, s, &held, &trig)
            });
        }
        let touchdown = ground::touchdown(&mut self.plant);
        // The step moves the angles by a few mrad, so the next step's trig comes from this
        // one by angle addition; it is recomputed exactly once per control period so
        // rounding never accumulates, and after a touchdown (which may reset the attitude).
        self.plant_trig =
            if touchdown.is_some() || self.steps.is_multiple_of(self.control_every_steps) {
                EulerTrig::new(&self.plant.euler)
            } else {
                start_trig.shifted(&start, &self.plant.euler)
            };
        if let Some(td) = touchdown {
            self.on_ground = true;
            if td.sink_rate_m_s > CRASH_SINK_RATE_M_S || td.tilt_rad > CRASH_TILT_RAD {
                self.crash();
            }
        } else if self.plant_trig.cos_tilt() < CRASH_COS_TILT && !self.forward.state().is_forward()
        {
            // The tilt check is the hover's: forward flight flies the nose level.
            self.crash();
        }
    }

    /// Landed bookkeeping and the automatic disarm of QLAND's law.
    fn landed_bookkeeping(&mut self, dt: f64) {
        if self.on_ground {
            self.landed_time_s += dt;
            if self.telemetry.armed
                && self.law() == Some(FlightMode::QLand)
                && self.landed_time_s >= LAND_DISARM_DELAY_S
            {
                self.set_disarmed();
            }
        } else {
            self.landed_time_s = 0.0;
        }
    }

    /// Sensors → estimator → controller, once per control period.
    fn control_tick(&mut self) {
        let af = &self.config.airframe;
        let model = self.config.model;
        // What the accelerometer feels: on the ground the gear cancels gravity's pull.
        let specific_force = if self.on_ground {
            self.plant
                .euler
                .rotation_body_to_inertial()
                .tr_mul(&Vector3::new(0.0, 0.0, af.gravity_m_s2))
        } else {
            // `plant_trig` is exact here: it is recomputed at every control tick.
            plant::specific_force_body_m_s2(af, model, &self.plant_trig, &self.plant, &self.input)
        };
        let imu = self
            .sensors
            .sample_imu(&self.plant.omega_body_rad_s, &specific_force);
        let fix = self
            .sensors
            .sample_position(&self.plant.pos_m, self.plant.euler.psi);
        let rc = self.telemetry.rc_us;
        let pilot: PilotInput = sensors::rc_to_pilot(&rc);

        if self.telemetry.state == SystemState::Calibrating {
            if self.estimator.calibrate(&imu) {
                self.telemetry.state = SystemState::Standby;
            }
        } else if model == ModelMode::Physical {
            // The heading fix is fused where the firmware flies on the motion capture; the
            // paper's own experiment (QSTABILIZE) has gyros and accelerometer only.
            let heading = (self.config.heading_sensor
                && self.telemetry.mode != FlightMode::QStabilize)
                .then_some(fix.heading_rad);
            // Forward flight has its own filter (`forward_flight::forward_estimate`).
            if !self.forward_estimate(&imu, &fix, heading) {
                // The thrust the firmware commanded last tick stands in for the missing z axis
                // of the accelerometer (the motors lag it by their 40 ms time constant).
                let thrust = (self.telemetry.armed && !self.on_ground)
                    .then(|| self.telemetry.control.fz_n / self.config.airframe.mass_kg);
                self.estimator.set_thrust_accel(thrust);
                self.estimator.update(&imu, Some(&fix.pos_m), heading);
            }
        }

        // The law flown this tick: the mode's own, or the autonomous modes' guidance (None:
        // armed and idle on the ground).
        let law = self.law();
        let input = self.control_input(law.unwrap_or(FlightMode::QStabilize), pilot, &fix);
        self.last_control_input = input;

        let out = if self.telemetry.armed && law.is_some() {
            match self.forward_tick(&input) {
                Some(out) => out,
                None => self.controller.update(&input, &self.config.gains),
            }
        } else {
            ControlOutput {
                pwm_us: DISARMED_PWM_US,
                ..ControlOutput::default()
            }
        };
        self.telemetry.control = out;
        self.telemetry.pwm_us = out.pwm_us;
        self.telemetry.gyro_rad_s = imu.gyro_rad_s.into();
        self.telemetry.accel_m_s2 = imu.accel_m_s2;
        self.telemetry.adc_counts = imu.adc_counts;
        self.telemetry.euler_est = input.euler;
        self.telemetry.omega_est_rad_s = input.omega_body_rad_s;
        self.step_battery();
        if self.telemetry.armed && self.telemetry.state != SystemState::Emergency {
            // Failsafe: flying on pilot throttle with no receiver signal.
            let rc_lost = !sensors::rc_has_signal(&rc);
            self.telemetry.state = if rc_lost && self.telemetry.mode == FlightMode::QStabilize {
                SystemState::Critical
            } else {
                SystemState::Active
            };
        }
    }

    /// What the controller flies `mode` on this tick: the true state (paper model, or perfect
    /// state), or the estimator's attitude and rates with the position fix.
    fn control_input(
        &self,
        mode: FlightMode,
        pilot: PilotInput,
        fix: &sensors::PositionFix,
    ) -> ControlInput {
        let truth_vel = self.telemetry.vel_m_s;
        let truth = self.config.model == ModelMode::Paper || self.config.perfect_state;
        if truth {
            ControlInput {
                dt_s: self.control_dt_s,
                mode,
                euler: self.plant.euler,
                omega_body_rad_s: self.plant.omega_body_rad_s,
                pos_m: self.plant.pos_m,
                vel_m_s: truth_vel,
                setpoint_m: self.setpoint_m,
                yaw_setpoint_rad: self.forward.hover_heading_rad(),
                rotor_speed_rad_s: self.actuators.state.rotor_speed_rad_s,
                pilot,
            }
        } else {
            // The hover estimator's attitude, or the forward-flight filter's on the wing.
            let (est_euler, est_omega) = self.estimated_attitude();
            ControlInput {
                dt_s: self.control_dt_s,
                mode,
                euler: Euler {
                    psi: crate::model::frames::wrap_pi(
                        est_euler.psi + self.chain_heading_error_rad,
                    ),
                    ..est_euler
                },
                omega_body_rad_s: est_omega,
                pos_m: fix.pos_m,
                vel_m_s: fix.vel_m_s,
                setpoint_m: self.setpoint_m,
                yaw_setpoint_rad: self.forward.hover_heading_rad(),
                rotor_speed_rad_s: self.actuators.state.rotor_speed_rad_s,
                pilot,
            }
        }
    }

    /// The battery's integration over the control ticks since its last step, once per
    /// [`BATTERY_PERIOD_S`]; the motors' supply follows its voltage.
    fn step_battery(&mut self) {
        let af = &self.config.airframe;
        self.battery_pending_s += self.control_dt_s;
        if self.battery_pending_s >= BATTERY_PERIOD_S - 1e-9 {
            let w = self.actuators.state.rotor_speed_rad_s;
            // The thrust's work on the inflow (forward flight, climbs): `physical` mode only.
            let work = match self.config.model {
                ModelMode::Physical => {
                    af.k_thrust_n_per_rad2_s2
                        * (w[0] * w[0] + w[1] * w[1])
                        * self.telemetry.air_velocity_body_m_s.z.max(0.0)
                }
                ModelMode::Paper => 0.0,
            };
            self.battery.step_with_work(
                self.battery_pending_s,
                w,
                af.rotor_arm_m,
                af.k_drag_n_per_rad2_s2,
                work,
            );
            self.battery_pending_s = 0.0;
            self.telemetry.battery = *self.battery.state();
            self.actuators.set_supply(self.battery.supply_ratio());
        }
    }

    /// The body's velocity relative to the air (wind and gust included), in B, m/s.
    fn air_velocity_body_m_s(&self) -> Vector3<f64> {
        let wind_body = self.input.wind_m_s.map_or_else(Vector3::zeros, |w| {
            self.plant_trig.rotation_body_to_inertial().tr_mul(&w)
        });
        aero::air_velocity_body(&self.plant.vel_body_m_s, &wind_body)
    }

    /// Copies the true state into the telemetry.
    fn refresh_truth(&mut self) {
        self.telemetry.air_velocity_body_m_s = self.air_velocity_body_m_s();
        let t = &mut self.telemetry;
        t.pos_m = self.plant.pos_m;
        t.vel_m_s = self
            .plant_trig
            .rotate_body_to_inertial(&self.plant.vel_body_m_s);
        t.euler = self.plant.euler;
        t.omega_body_rad_s = self.plant.omega_body_rad_s;
        t.rotor_speed_rad_s = self.actuators.state.rotor_speed_rad_s;
        t.landed = self.on_ground;
    }

    /// The control law flown now: the mode's own, or for GUIDED, AUTO and QRTL the one their
    /// guidance asks for (QLOITER's to a point, QLAND's), or `None` when idle on the ground
    /// (also QLOITER landed with its point on the ground).
    #[must_use]
    pub fn law(&self) -> Option<FlightMode> {
        let mode = self.telemetry.mode;
        if mode == FlightMode::QLoiter
            && self.on_ground
            && self.setpoint_m.z <= self.plant.pos_m.z + LOITER_GROUND_HOLD_M
        {
            // A point on the ground: landed, motors at idle (ArduPlane's QLOITER with the
            // throttle stick at or below mid).
            return None;
        }
        if !mode.is_autonomous() {
            return Some(mode);
        }
        match self.guidance {
            Guidance::Idle => None,
            Guidance::Position(_) => Some(FlightMode::QLoiter),
            Guidance::Land => Some(FlightMode::QLand),
            // Until the transition starts, hold the point where the leg was asked for.
            Guidance::Forward(_) => Some(FlightMode::QLoiter),
        }
    }

    /// What GUIDED, AUTO and QRTL fly from the next control tick on. A position also becomes
    /// the setpoint QLOITER holds.
    pub fn set_guidance(&mut self, guidance: Guidance) {
        if let Guidance::Position(p) = guidance {
            self.setpoint_m = p;
        }
        self.guidance = guidance;
    }

    /// The current guidance.
    #[must_use]
    pub fn guidance(&self) -> Guidance {
        self.guidance
    }

    fn crash(&mut self) {
        self.set_disarmed();
        self.telemetry.state = SystemState::Emergency;
    }

    fn set_disarmed(&mut self) {
        self.forward_reset();
        self.telemetry.armed = false;
        self.telemetry.pwm_us = DISARMED_PWM_US;
        self.telemetry.control = ControlOutput {
            pwm_us: DISARMED_PWM_US,
            ..ControlOutput::default()
        };
        if self.telemetry.state != SystemState::Emergency {
            self.telemetry.state = if self.estimator.is_calibrated() {
                SystemState::Standby
            } else {
                SystemState::Calibrating
            };
        }
    }

    /// Current snapshot.
    #[must_use]
    pub fn telemetry(&self) -> &Telemetry {
        &self.telemetry
    }

    /// The true rigid-body state (paper frames).
    #[must_use]
    pub fn plant_state(&self) -> &PlantState {
        &self.plant
    }

    /// The configuration the vehicle was built with (gains as currently set).
    #[must_use]
    pub fn config(&self) -> &VehicleConfig {
        &self.config
    }

    /// The physics step, s.
    #[must_use]
    pub fn physics_dt_s(&self) -> f64 {
        self.dt_s
    }

    /// Simulation time, s.
    #[must_use]
    pub fn time_s(&self) -> f64 {
        self.telemetry.t_us as f64 * 1e-6
    }

    /// The position setpoint in use (paper frame, z up), m.
    #[must_use]
    pub fn position_setpoint(&self) -> Vector3<f64> {
        self.setpoint_m
    }

    /// Current gains.
    #[must_use]
    pub fn gains(&self) -> &Gains {
        &self.config.gains
    }

    /// Replaces the gains after checking them.
    ///
    /// # Errors
    /// The first constraint the set breaks; the old gains stay in force.
    pub fn set_gains(&mut self, gains: Gains) -> Result<(), GainError> {
        gains.validate()?;
        self.config.gains = gains;
        Ok(())
    }

    /// Changes the flight mode.
    pub fn set_mode(&mut self, mode: FlightMode) {
        if mode != self.telemetry.mode {
            self.controller.reset();
        }
        self.telemetry.mode = mode;
        self.vtol_mode_changed(mode);
    }

    /// RC receiver input: pulse widths in µs for channels 1–8 (1 roll, 2 pitch, 3 throttle,
    /// 4 yaw); 0 = no signal on that channel.
    pub fn set_rc_input(&mut self, channels_us: [u16; 8]) {
        self.telemetry.rc_us = channels_us;
    }

    /// Moves the hover point (paper frame, z up) used by QLOITER.
    pub fn set_position_setpoint(&mut self, pos_m: Vector3<f64>) {
        self.setpoint_m = pos_m;
    }

    /// Applies a body torque (N·m) for `duration_s`: the paper's push on an axis.
    pub fn push(&mut self, torque_body_nm: Vector3<f64>, duration_s: f64) {
        self.push_torque_body_nm = torque_body_nm;
        self.push_steps_left = (duration_s.max(0.0) / self.dt_s).round() as u64;
    }

    /// Fault injection: the motion-capture rig reports the heading `offset_rad` off (a rig
    /// whose frame is misaligned with the vehicle's reference). With heading fusion on, the
    /// estimate converges to the wrong heading and the position chains fly on it.
    pub fn set_heading_sensor_offset(&mut self, offset_rad: f64) {
        self.sensors.position.heading_offset_rad = offset_rad;
    }

    /// Fault injection: the controller flies on a heading `error_rad` off the estimate (a
    /// constant heading error in the position chains' heading frame and the yaw law; the
    /// estimator itself is untouched). `physical` mode with the estimator only.
    pub fn set_controller_heading_error(&mut self, error_rad: f64) {
        self.chain_heading_error_rad = error_rad;
    }

    /// The heading estimate's error, ψ̂ − ψ wrapped to (−π, π], rad.
    #[must_use]
    pub fn heading_error_rad(&self) -> f64 {
        crate::model::frames::wrap_pi(self.telemetry.euler_est.psi - self.plant.euler.psi)
    }

    /// Sets a steady wind (inertial, m/s) and a gust intensity (m/s, standard deviation).
    pub fn set_wind(&mut self, wind_m_s: Vector3<f64>, gust_m_s: f64) {
        self.wind.mean_m_s = wind_m_s;
        self.wind.gust_sigma_m_s = gust_m_s.max(0.0);
        if self.wind.gust_sigma_m_s == 0.0 {
            self.wind.gust_m_s = Vector3::zeros();
        }
    }
}

/// Angle between z_B and the vertical, rad.
fn tilt_rad(e: &Euler) -> f64 {
    (e.theta.cos() * e.phi.cos()).clamp(-1.0, 1.0).acos()
}

#[cfg(test)]
mod forward_tests;
#[cfg(test)]
mod tests;
