//! `firmware-sim simulate`: an offline closed-loop flight in fast time, written as CSV.
//!
//! Everything is in the paper's frames (inertial z up, η = (ψ, θ, φ)) and SI units. The
//! vehicle starts armed at `--initial` in the chosen mode and flies for `--duration` seconds of
//! simulated time with the physics at 1 kHz (`--physics-rate`); one row is written every
//! 1/`--rate` s, the first at t = 0 with the controller's output at t = 0.
//!
//! The command-line types live in the binary; this module takes a [`SimulateConfig`] and checks
//! it as the vehicle would: parameters through the vehicle's own table as one set, setpoints
//! against the vehicle's limits, and flag combinations that cannot be honoured are errors.

use std::io::Write;

use nalgebra::Vector3;

use crate::model::airframe::ModelMode;
use crate::model::frames::{Euler, body_rates_to_frd};
use crate::model::mode::FlightMode;
use crate::model::signals::CRASH_TILT_RAD;
use crate::model::vehicle::{InitialState, Telemetry, Vehicle, VehicleConfig};
use crate::nav::params::{ParamError, Params};

/// The CSV header (paper frame, SI; τ̃ in rad/s², Γc in N·m, PWM in µs).
pub const CSV_HEADER: &str = "t,x,y,z,vx,vy,vz,phi,theta,psi,p,q,r,tau_phi,tau_theta,tau_psi,fz,\
pwm1,pwm2,pwm3,pwm4,pwm5,fx,gamma_x,gamma_y,gamma_z,w1,w2,phi_est,theta_est,psi_est,landed,armed";

/// The parameters an offline flight honours: the control law, the control rate and the wind.
/// The others (identity, streams, failsafes, the one-shot `SIM_PUSH_*`) have no meaning without
/// a link, and setting one is an error rather than silently ignored.
const OFFLINE_PARAMS: [&str; 28] = [
    "LAT_SAT_A",
    "LAT_SAT_B",
    "LAT_SAT_C",
    "LAT_SAT_D",
    "LON_SAT_A",
    "LON_SAT_B",
    "LON_SAT_C",
    "LON_SAT_D",
    "ALT_KD",
    "ALT_KP",
    "YAW_KD",
    "YAW_KP",
    "HOVER_ALT",
    "LAND_SPEED",
    "CTRL_RATE_HZ",
    "SIM_WIND_SPD",
    "SIM_WIND_DIR",
    "SIM_WIND_TURB",
    "HOV_POS_LAW",
    "Q_P_POSXY_P",
    "Q_P_VELXY_P",
    "Q_P_VELXY_I",
    "Q_P_VELXY_IMAX",
    "Q_WP_SPEED",
    "Q_ANGLE_MAX",
    "HOV_ATT_BW",
    "HOV_ATT_ACC",
    "HOV_YAW_ACC",
];

/// Largest horizontal setpoint, m: the motion-capture volume the position modes fly in.
pub const HORIZONTAL_SETPOINT_LIMIT_M: f64 = 50.0;

/// Why a simulation could not run.
#[derive(Debug, thiserror::Error)]
pub enum SimulateError {
    /// A parameter write the vehicle refuses (same table, ranges and constraints).
    #[error("--param {0}")]
    Param(#[from] ParamError),
    /// A flag value, or a combination of flags, that cannot be honoured.
    #[error("{0}")]
    BadValue(String),
    /// Writing the CSV failed.
    #[error("writing CSV: {0}")]
    Io(#[from] std::io::Error),
}

/// `key=value` pairs of `--initial` (φ, θ, ψ in rad; x, y, z in m; omitted keys are 0).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct InitialArg {
    /// Position, m.
    pub pos_m: Vector3<f64>,
    /// Attitude.
    pub euler: Euler,
}

/// One push of the paper's hover experiments (Figs 8–10): a torque about a body axis.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Push {
    /// 0 roll, 1 pitch, 2 yaw, about the FRD body axes a GCS shows (as `SIM_PUSH_*`).
    pub axis: usize,
    /// Torque, N·m.
    pub torque_nm: f64,
    /// Start, s of simulated time.
    pub at_s: f64,
    /// Duration, ms.
    pub duration_ms: f64,
}

/// An offline flight: what `firmware-sim simulate` asks for, independent of the command line.
#[derive(Debug, Clone, PartialEq)]
pub struct SimulateConfig {
    /// Simulated duration, s.
    pub duration_s: f64,
    /// Start state (velocities and rates zero).
    pub initial: InitialArg,
    /// Position setpoint of QLOITER, m (z up); `None` = (0, 0, `HOVER_ALT`).
    pub setpoint_m: Option<Vector3<f64>>,
    /// `paper` or `physical`.
    pub model: ModelMode,
    /// Flight mode.
    pub mode: FlightMode,
    /// Perfect sensing: no noise, bias or quantisation, and the controller reads the true state.
    pub ideal_sensors: bool,
    /// Seed of every random draw.
    pub seed: u64,
    /// Parameter writes, applied as one set through the vehicle's table.
    pub params: Vec<(String, f64)>,
    /// CSV rows per simulated second.
    pub rate_hz: f64,
    /// Physics steps per simulated second.
    pub physics_rate_hz: f64,
    /// Pushes.
    pub pushes: Vec<Push>,
}

impl Default for SimulateConfig {
    fn default() -> Self {
        Self {
            duration_s: 25.0,
            initial: InitialArg::default(),
            setpoint_m: None,
            model: ModelMode::Physical,
            mode: FlightMode::QLoiter,
            ideal_sensors: false,
            seed: 1,
            params: Vec::new(),
            rate_hz: 100.0,
            physics_rate_hz: 1000.0,
            pushes: Vec::new(),
        }
    }
}

/// What the flight ended with.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Summary {
    /// Final telemetry.
    pub last: Telemetry,
    /// Final position error from the setpoint, m.
    pub pos_error_m: f64,
    /// Rows written.
    pub rows: u64,
}

fn parse_f64(key: &str, v: &str) -> Result<f64, String> {
    let x: f64 = v.trim().parse().map_err(|_| {
        format!(
            "'{}' is not a number (for {})",
            v.escape_debug(),
            key.escape_debug()
        )
    })?;
    if x.is_finite() {
        Ok(x)
    } else {
        Err(format!("{} must be finite", key.escape_debug()))
    }
}

fn parse_pairs<'a>(s: &'a str, keys: &[&str]) -> Result<Vec<(&'a str, f64)>, String> {
    let mut out = Vec::new();
    for item in s.split(',').map(str::trim).filter(|i| !i.is_empty()) {
        let (k, v) = item
            .split_once('=')
            .ok_or_else(|| format!("'{}' is not key=value", item.escape_debug()))?;
        let k = k.trim();
        if !keys.contains(&k) {
            return Err(format!(
                "unknown key '{}' (expected one of {})",
                k.escape_debug(),
                keys.join(", ")
            ));
        }
        out.push((k, parse_f64(k, v)?));
    }
    Ok(out)
}

// Errors quote what was typed with `escape_debug`, so a value with a line break in it still
// makes a one-line error.

/// Parses `phi=..,theta=..,psi=..,x=..,y=..,z=..` (rad, m).
///
/// # Errors
/// Unknown keys, non-numbers, angles outside (−π, π], θ near ±π/2.
pub fn parse_initial(s: &str) -> Result<InitialArg, String> {
    let mut a = InitialArg::default();
    for (k, v) in parse_pairs(s, &["phi", "theta", "psi", "x", "y", "z"])? {
        match k {
            "phi" => a.euler.phi = v,
            "theta" => a.euler.theta = v,
            "psi" => a.euler.psi = v,
            "x" => a.pos_m.x = v,
            "y" => a.pos_m.y = v,
            _ => a.pos_m.z = v,
        }
    }
    for (name, v) in [("phi", a.euler.phi), ("psi", a.euler.psi)] {
        if v.abs() > std::f64::consts::PI {
            return Err(format!("{name}={v} is outside [-pi, pi]"));
        }
    }
    if a.euler.theta.abs() >= 1.5 {
        return Err("theta must stay clear of ±π/2".into());
    }
    Ok(a)
}

/// Parses `x=..,y=..,z=..` (m, z up; omitted keys are 0).
///
/// # Errors
/// Unknown keys or non-numbers.
pub fn parse_setpoint(s: &str) -> Result<Vector3<f64>, String> {
    let mut p = Vector3::zeros();
    for (k, v) in parse_pairs(s, &["x", "y", "z"])? {
        match k {
            "x" => p.x = v,
            "y" => p.y = v,
            _ => p.z = v,
        }
    }
    Ok(p)
}

/// Parses `NAME=VALUE` (the name as the parameter table spells it, any case).
///
/// # Errors
/// Not `NAME=VALUE`, or a value that is not a finite number.
pub fn parse_param(s: &str) -> Result<(String, f64), String> {
    let (name, v) = s
        .split_once('=')
        .ok_or_else(|| format!("'{}' is not NAME=VALUE", s.escape_debug()))?;
    let name = name.trim().to_ascii_uppercase();
    let value = parse_f64(&name, v)?;
    Ok((name, value))
}

/// Parses a push `AXIS=N·m@SECONDS[:MS]`, e.g. `roll=0.1@5:200` (AXIS roll, pitch or yaw about
/// the FRD body axes; MS defaults to 200, as `SIM_PUSH_MS`).
///
/// # Errors
/// Anything else.
pub fn parse_push(s: &str) -> Result<Push, String> {
    let form = "expected AXIS=N.m@SECONDS[:MS], e.g. roll=0.1@5:200";
    let (axis, rest) = s.split_once('=').ok_or_else(|| form.to_owned())?;
    let axis = match axis.trim().to_ascii_lowercase().as_str() {
        "roll" => 0,
        "pitch" => 1,
        "yaw" => 2,
        other => {
            return Err(format!(
                "unknown axis '{}' (roll, pitch or yaw)",
                other.escape_debug()
            ));
        }
    };
    let (torque, when) = rest.split_once('@').ok_or_else(|| form.to_owned())?;
    let (at, ms) = match when.split_once(':') {
        Some((at, ms)) => (at, Some(ms)),
        None => (when, None),
    };
    Ok(Push {
        axis,
        torque_nm: parse_f64("push torque", torque)?,
        at_s: parse_f64("push time", at)?,
        duration_ms: ms.map_or(Ok(200.0), |m| parse_f64("push duration", m))?,
    })
}

fn bad(msg: String) -> SimulateError {
    SimulateError::BadValue(msg)
}

/// The vehicle configuration the flight describes, after every check: the parameter set through
/// the vehicle's table, flag combinations, the start state and the setpoint against the
/// vehicle's limits.
///
/// # Errors
/// The first thing that cannot be honoured, in one line.
pub fn vehicle_config(cfg: &SimulateConfig) -> Result<(VehicleConfig, Params), SimulateError> {
    if !(cfg.duration_s > 0.0 && cfg.duration_s <= 86_400.0) {
        return Err(bad("--duration must be in (0, 86400] s".into()));
    }
    if cfg.mode.is_autonomous() {
        return Err(bad(format!(
            "--mode {} needs a ground station's targets or a mission: fly it with `serve`",
            cfg.mode
        )));
    }
    // Parameters: the vehicle's own table, one set.
    for (name, _) in &cfg.params {
        if Params::index_of(name).is_some() && !OFFLINE_PARAMS.contains(&name.as_str()) {
            return Err(bad(format!(
                "--param {name} has no effect in an offline flight (use --push for pushes)"
            )));
        }
    }
    let mut params = Params::new();
    params.set_all(&cfg.params)?;
    let rate_set = cfg.params.iter().any(|(n, _)| n == "CTRL_RATE_HZ");
    if cfg.model == ModelMode::Paper && rate_set {
        return Err(bad(
            "--param CTRL_RATE_HZ cannot apply to --model paper: its controller runs in \
continuous time"
                .into(),
        ));
    }
    let control = params.value("CTRL_RATE_HZ");
    let dt_us = check_rates(cfg, control)?;
    check_start(cfg)?;
    check_setpoint(cfg)?;
    check_pushes(cfg)?;
    let rc_us = offline_rc(cfg.mode);
    let vc = VehicleConfig {
        rc_us,
        position_setpoint_m: Some(
            cfg.setpoint_m
                .unwrap_or_else(|| Vector3::new(0.0, 0.0, params.value("HOVER_ALT"))),
        ),
        model: cfg.model,
        ideal_sensors: cfg.ideal_sensors,
        perfect_state: cfg.ideal_sensors,
        seed: cfg.seed,
        physics_dt_us: dt_us.round() as u64,
        initial: InitialState {
            pos_m: cfg.initial.pos_m,
            euler: cfg.initial.euler,
        },
        mode: cfg.mode,
        armed: true,
        gains: params.gains(),
        control_rate_hz: control,
        ..VehicleConfig::default()
    };
    Ok((vc, params))
}

/// The physics step, whole µs, after checking the physics rate, that the control rate `control`
/// divides it (physical model) and the output rate.
fn check_rates(cfg: &SimulateConfig, control: f64) -> Result<f64, SimulateError> {
    // Physics step: whole microseconds, a whole number of steps per control period.
    let physics = cfg.physics_rate_hz;
    let dt_us = 1e6 / physics;
    if !((1000.0..=10_000.0).contains(&physics) && (dt_us - dt_us.round()).abs() < 1e-9) {
        return Err(bad(format!(
            "--physics-rate {physics} must be in [1000, 10000] Hz with a whole number of µs per step"
        )));
    }
    let per_tick = physics / control;
    if cfg.model == ModelMode::Physical && (per_tick - per_tick.round()).abs() > 1e-9 {
        return Err(bad(format!(
            "CTRL_RATE_HZ {control} does not divide --physics-rate {physics}"
        )));
    }
    if !(cfg.rate_hz > 0.0 && cfg.rate_hz <= physics) {
        return Err(bad(format!(
            "--rate must be in (0, {physics}] rows/s (the physics rate)"
        )));
    }
    Ok(dt_us)
}

/// Checks the start state: z up from the ground, level on it, and not past the crash tilt.
fn check_start(cfg: &SimulateConfig) -> Result<(), SimulateError> {
    let init = &cfg.initial;
    let tilt = (init.euler.theta.cos() * init.euler.phi.cos()).acos();
    if init.pos_m.z < 0.0 {
        return Err(bad(
            "--initial z must be ≥ 0 (z up; 0 is on the ground)".into()
        ));
    }
    if init.pos_m.z == 0.0 && (init.euler.phi != 0.0 || init.euler.theta != 0.0) {
        return Err(bad(
            "--initial: a start on the ground (z = 0) is level; give z > 0 for a tilted start"
                .into(),
        ));
    }
    if tilt >= CRASH_TILT_RAD {
        return Err(bad(format!(
            "--initial tilt {tilt:.3} rad is beyond the crash tilt {CRASH_TILT_RAD:.3} rad"
        )));
    }
    Ok(())
}

/// Checks the setpoint: QLOITER's, inside the vehicle's limits.
fn check_setpoint(cfg: &SimulateConfig) -> Result<(), SimulateError> {
    if let Some(sp) = cfg.setpoint_m {
        if cfg.mode != FlightMode::QLoiter {
            return Err(bad(format!(
                "--setpoint applies to QLOITER only ({} does not hold a position)",
                cfg.mode
            )));
        }
        let alt = &crate::nav::params::TABLE[Params::index_of("HOVER_ALT").unwrap_or(0)];
        if !(sp.z > alt.min && sp.z <= alt.max) {
            return Err(bad(format!(
                "--setpoint z={} outside the vehicle's altitude range ({}, {}] m (HOVER_ALT)",
                sp.z, alt.min, alt.max
            )));
        }
        let lim = HORIZONTAL_SETPOINT_LIMIT_M;
        if sp.x.abs() > lim || sp.y.abs() > lim {
            return Err(bad(format!(
                "--setpoint x={}, y={} outside the position bound ±{lim} m",
                sp.x, sp.y
            )));
        }
    }
    Ok(())
}

/// Checks the pushes: inside the flight, within SIM_PUSH_*'s ranges.
fn check_pushes(cfg: &SimulateConfig) -> Result<(), SimulateError> {
    let torque_def = &crate::nav::params::TABLE[Params::index_of("SIM_PUSH_ROLL").unwrap_or(0)];
    let ms_def = &crate::nav::params::TABLE[Params::index_of("SIM_PUSH_MS").unwrap_or(0)];
    for p in &cfg.pushes {
        if !(torque_def.min..=torque_def.max).contains(&p.torque_nm) || p.torque_nm == 0.0 {
            return Err(bad(format!(
                "--push torque {} N.m must be non-zero within [{}, {}]",
                p.torque_nm, torque_def.min, torque_def.max
            )));
        }
        if !(ms_def.min..=ms_def.max).contains(&p.duration_ms) {
            return Err(bad(format!(
                "--push duration {} ms outside [{}, {}]",
                p.duration_ms, ms_def.min, ms_def.max
            )));
        }
        if p.at_s < 0.0 || p.at_s + p.duration_ms * 1e-3 > cfg.duration_s {
            return Err(bad(format!(
                "--push at {} s for {} ms does not fit in the {} s flight",
                p.at_s, p.duration_ms, cfg.duration_s
            )));
        }
    }
    Ok(())
}

/// The RC input of an offline flight, µs. No pilot offline: in QSTABILIZE the sticks are
/// centred and the throttle at hover, as a pilot holding the vehicle in the paper's hover
/// experiments would; in other modes no RC at all.
fn offline_rc(mode: FlightMode) -> [u16; 8] {
    let af = crate::model::airframe::Airframe::default();
    let fz_max = 2.0 * af.k_thrust_n_per_rad2_s2 * af.rotor_speed_max_rad_s.powi(2);
    let throttle_us = (1000.0 + 1000.0 * af.weight_n() / fz_max).round() as u16;
    if mode == FlightMode::QStabilize {
        [1500, 1500, throttle_us, 1500, 0, 0, 0, 0]
    } else {
        [0; 8]
    }
}

/// Writes one CSV row of `t`.
fn write_row(out: &mut dyn Write, t: &Telemetry) -> std::io::Result<()> {
    let c = &t.control;
    let e = &t.euler;
    let ee = &t.euler_est;
    writeln!(
        out,
        "{:.3},{:.6},{:.6},{:.6},{:.6},{:.6},{:.6},{:.6},{:.6},{:.6},{:.6},{:.6},{:.6},\
{:.6},{:.6},{:.6},{:.6},{},{},{},{},{},{:.6},{:.6},{:.6},{:.6},{:.3},{:.3},{:.6},{:.6},{:.6},{},{}",
        t.t_us as f64 * 1e-6,
        t.pos_m.x,
        t.pos_m.y,
        t.pos_m.z,
        t.vel_m_s.x,
        t.vel_m_s.y,
        t.vel_m_s.z,
        e.phi,
        e.theta,
        e.psi,
        t.omega_body_rad_s.x,
        t.omega_body_rad_s.y,
        t.omega_body_rad_s.z,
        c.tau_tilde[2],
        c.tau_tilde[1],
        c.tau_tilde[0],
        c.fz_n,
        t.pwm_us[0],
        t.pwm_us[1],
        t.pwm_us[2],
        t.pwm_us[3],
        t.pwm_us[4],
        c.fx_n,
        c.torque_body_nm.x,
        c.torque_body_nm.y,
        c.torque_body_nm.z,
        t.rotor_speed_rad_s[0],
        t.rotor_speed_rad_s[1],
        ee.phi,
        ee.theta,
        ee.psi,
        u8::from(t.landed),
        u8::from(t.armed),
    )
}

/// Flies the configured vehicle for `cfg.duration_s`, writing CSV rows to `out` if given.
///
/// # Errors
/// Anything [`vehicle_config`] refuses, or an I/O error while writing.
pub fn run(
    cfg: &SimulateConfig,
    mut out: Option<&mut dyn Write>,
) -> Result<Summary, SimulateError> {
    let (vc, params) = vehicle_config(cfg)?;
    let mut v = Vehicle::new(vc);
    let setpoint = v.position_setpoint();
    let (wind, gust) = params.wind_paper_m_s();
    v.set_wind(wind, gust);
    let dt = v.physics_dt_s();
    let steps = (cfg.duration_s / dt).round() as u64;
    let every = ((1.0 / (cfg.rate_hz * dt)).round() as u64).max(1);
    let mut pushes: Vec<(u64, Push)> = cfg
        .pushes
        .iter()
        .map(|p| ((p.at_s / dt).round() as u64, *p))
        .collect();
    pushes.sort_by_key(|(k, _)| *k);
    let mut next_push = 0;
    let mut rows = 0;
    if let Some(w) = out.as_deref_mut() {
        writeln!(w, "{CSV_HEADER}")?;
    }
    for k in 0..=steps {
        while let Some((at, p)) = pushes.get(next_push) {
            if *at != k {
                break;
            }
            let mut frd = Vector3::zeros();
            frd[p.axis] = p.torque_nm;
            v.push(Vector3::from(body_rates_to_frd(&frd)), p.duration_ms * 1e-3);
            next_push += 1;
        }
        if k > 0 {
            v.step();
        }
        if let Some(w) = out.as_deref_mut()
            && (k % every == 0 || k == steps)
        {
            write_row(w, v.telemetry())?;
            rows += 1;
        }
    }
    if let Some(w) = out {
        w.flush()?;
    }
    let last = *v.telemetry();
    Ok(Summary {
        last,
        pos_error_m: (last.pos_m - setpoint).norm(),
        rows,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn parses_initial_setpoint_and_push() {
        let a = parse_initial("phi=0.1, theta=0.1,psi=1,x=0.1,y=0.1,z=0.1").unwrap();
        assert_eq!(a.euler, Euler::new(1.0, 0.1, 0.1));
        assert_eq!(a.pos_m, Vector3::new(0.1, 0.1, 0.1));
        assert_eq!(parse_initial("").unwrap(), InitialArg::default());
        assert!(parse_initial("roll=1").is_err());
        assert!(parse_initial("phi=abc").is_err());
        assert!(parse_initial("phi=3.3").is_err());
        assert_eq!(parse_setpoint("z=2").unwrap(), Vector3::new(0.0, 0.0, 2.0));
        let p = parse_push("pitch=0.05@3:150").unwrap();
        assert_eq!(
            (p.axis, p.torque_nm, p.at_s, p.duration_ms),
            (1, 0.05, 3.0, 150.0)
        );
        assert_eq!(parse_push("yaw=-0.1@2").unwrap().duration_ms, 200.0);
        assert!(parse_push("up=1@2").is_err());
        assert!(parse_push("roll=1").is_err());
    }

    #[test]
    fn params_go_through_the_vehicles_table_as_a_set() {
        let cfg = |params: &[(&str, f64)]| SimulateConfig {
            params: params.iter().map(|(n, v)| ((*n).to_owned(), *v)).collect(),
            ..SimulateConfig::default()
        };
        let (vc, _) = vehicle_config(&cfg(&[("ALT_KP", 4.0), ("LAT_SAT_D", 0.1)])).unwrap();
        assert_eq!((vc.gains.alt_kp, vc.gains.lateral.d), (4.0, 0.1));
        // The vehicle's own error text.
        let e = vehicle_config(&cfg(&[("ALT_KP", 1e6)])).unwrap_err();
        assert_eq!(e.to_string(), "--param ALT_KP: 1000000 outside [0, 100]");
        let e = vehicle_config(&cfg(&[("LAT_SAT_D", 0.5)])).unwrap_err();
        assert!(e.to_string().contains("c > d"), "{e}");
        assert!(vehicle_config(&cfg(&[("NOPE", 1.0)])).is_err());
        assert!(vehicle_config(&cfg(&[("SR0_EXTRA1", 4.0)])).is_err());
    }
}
