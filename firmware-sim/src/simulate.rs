//! `firmware-sim simulate`: an offline closed-loop flight in fast time, written as CSV.
//!
//! Everything is in the paper's frames (inertial z up, η = (ψ, θ, φ)) and SI units. The
//! vehicle starts armed at `--initial` in the chosen mode and flies for `--duration` seconds of
//! simulated time with the physics at 1 kHz; one row is written every 1/`--rate` s.

use std::io::Write;

use nalgebra::Vector3;

use crate::airframe::ModelMode;
use crate::control::{GainError, Gains};
use crate::frames::Euler;
use crate::mode::FlightMode;
use crate::vehicle::{InitialState, PHYSICS_DT_S, Telemetry, Vehicle, VehicleConfig};

/// The CSV header (paper frame, SI; τ̃ in rad/s², Γc in N·m, PWM in µs).
pub const CSV_HEADER: &str = "t,x,y,z,vx,vy,vz,phi,theta,psi,p,q,r,tau_phi,tau_theta,tau_psi,fz,\
pwm1,pwm2,pwm3,pwm4,pwm5,fx,gamma_x,gamma_y,gamma_z,w1,w2,phi_est,theta_est,psi_est,landed,armed";

/// The tunables `--param` accepts.
pub const PARAM_NAMES: [&str; 15] = [
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
    // Kept last: not in the brief's list but harmless to expose.
    "LAND_SPEED",
    "CTRL_RATE_HZ",
];

/// Why a simulation could not run.
#[derive(Debug, thiserror::Error)]
pub enum SimulateError {
    /// The gain set breaks a constraint (e.g. the saturation conditions).
    #[error("invalid parameters")]
    Gains(#[from] GainError),
    /// A flag value is out of range.
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

/// One `--param NAME=VALUE`.
#[derive(Debug, Clone, PartialEq)]
pub struct ParamAssign {
    /// Parameter name (one of [`PARAM_NAMES`]).
    pub name: String,
    /// New value.
    pub value: f64,
}

/// Flags of `simulate`.
#[derive(Debug, Clone, clap::Args)]
pub struct SimulateArgs {
    /// Simulated duration, s.
    #[arg(long, default_value_t = 25.0, value_parser = parse_duration)]
    pub duration: f64,
    /// Initial state: phi=..,theta=..,psi=..,x=..,y=..,z=.. (rad, m; paper frame, z up).
    #[arg(long, default_value = "", value_parser = parse_initial)]
    pub initial: InitialArg,
    /// Position setpoint x=..,y=..,z=.. (m, z up).
    #[arg(long, default_value = "x=0,y=0,z=1", value_parser = parse_setpoint)]
    pub setpoint: SetpointArg,
    /// Model: paper or physical.
    #[arg(long, default_value = "physical")]
    pub model: ModelMode,
    /// Flight mode (QSTABILIZE, QHOVER, QLOITER, QLAND).
    #[arg(long, default_value = "QLOITER")]
    pub mode: FlightMode,
    /// Sensors without noise, bias or quantisation.
    #[arg(long)]
    pub ideal_sensors: bool,
    /// Seed of every random draw.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Parameter override NAME=VALUE (repeatable).
    #[arg(long = "param", value_parser = parse_param)]
    pub params: Vec<ParamAssign>,
    /// CSV output file (`-` = stdout).
    #[arg(long)]
    pub csv: Option<String>,
    /// CSV rows per simulated second.
    #[arg(long, default_value_t = 100.0, value_parser = parse_rate)]
    pub rate: f64,
}

/// A position setpoint from `--setpoint`, m.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SetpointArg(pub Vector3<f64>);

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
    let x: f64 = v
        .trim()
        .parse()
        .map_err(|_| format!("'{v}' is not a number (for {key})"))?;
    if x.is_finite() {
        Ok(x)
    } else {
        Err(format!("{key} must be finite"))
    }
}

fn parse_pairs<'a>(s: &'a str, keys: &[&str]) -> Result<Vec<(&'a str, f64)>, String> {
    let mut out = Vec::new();
    for item in s.split(',').map(str::trim).filter(|i| !i.is_empty()) {
        let (k, v) = item
            .split_once('=')
            .ok_or_else(|| format!("'{item}' is not key=value"))?;
        let k = k.trim();
        if !keys.contains(&k) {
            return Err(format!(
                "unknown key '{k}' (expected one of {})",
                keys.join(", ")
            ));
        }
        out.push((k, parse_f64(k, v)?));
    }
    Ok(out)
}

fn parse_initial(s: &str) -> Result<InitialArg, String> {
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
    if a.euler.theta.abs() >= 1.5 {
        return Err("theta must stay clear of ±π/2".into());
    }
    Ok(a)
}

fn parse_setpoint(s: &str) -> Result<SetpointArg, String> {
    let mut p = Vector3::zeros();
    for (k, v) in parse_pairs(s, &["x", "y", "z"])? {
        match k {
            "x" => p.x = v,
            "y" => p.y = v,
            _ => p.z = v,
        }
    }
    Ok(SetpointArg(p))
}

fn parse_param(s: &str) -> Result<ParamAssign, String> {
    let (name, v) = s
        .split_once('=')
        .ok_or_else(|| format!("'{s}' is not NAME=VALUE"))?;
    let name = name.trim().to_ascii_uppercase();
    if !PARAM_NAMES.contains(&name.as_str()) {
        return Err(format!("unknown parameter '{name}'"));
    }
    Ok(ParamAssign {
        value: parse_f64(&name, v)?,
        name,
    })
}

fn parse_duration(s: &str) -> Result<f64, String> {
    let d = parse_f64("duration", s)?;
    if d > 0.0 && d <= 86_400.0 {
        Ok(d)
    } else {
        Err("duration must be in (0, 86400] s".into())
    }
}

fn parse_rate(s: &str) -> Result<f64, String> {
    let r = parse_f64("rate", s)?;
    if r > 0.0 && r <= 1000.0 {
        Ok(r)
    } else {
        Err("rate must be in (0, 1000] Hz".into())
    }
}

/// Applies `--param` overrides to a gain set and a control rate, then checks the whole set.
///
/// # Errors
/// [`SimulateError::Gains`] when the set breaks a constraint (checked after all overrides, so a
/// consistent set may be changed in any order).
pub fn apply_params(
    gains: &mut Gains,
    control_rate_hz: &mut f64,
    params: &[ParamAssign],
) -> Result<(), SimulateError> {
    for p in params {
        let v = p.value;
        match p.name.as_str() {
            "LAT_SAT_A" => gains.lateral.a = v,
            "LAT_SAT_B" => gains.lateral.b = v,
            "LAT_SAT_C" => gains.lateral.c = v,
            "LAT_SAT_D" => gains.lateral.d = v,
            "LON_SAT_A" => gains.longitudinal.a = v,
            "LON_SAT_B" => gains.longitudinal.b = v,
            "LON_SAT_C" => gains.longitudinal.c = v,
            "LON_SAT_D" => gains.longitudinal.d = v,
            "ALT_KD" => gains.alt_kd = v,
            "ALT_KP" => gains.alt_kp = v,
            "YAW_KD" => gains.yaw_kd = v,
            "YAW_KP" => gains.yaw_kp = v,
            "HOVER_ALT" => gains.hover_alt_m = v,
            "LAND_SPEED" => gains.land_speed_m_s = v,
            "CTRL_RATE_HZ" => {
                if !(10.0..=1000.0).contains(&v) {
                    return Err(SimulateError::BadValue(format!(
                        "CTRL_RATE_HZ must be in [10, 1000], got {v}"
                    )));
                }
                *control_rate_hz = v;
            }
            other => {
                return Err(SimulateError::BadValue(format!(
                    "unknown parameter '{other}'"
                )));
            }
        }
    }
    gains.validate()?;
    Ok(())
}

/// The vehicle configuration the flags describe.
///
/// # Errors
/// As [`apply_params`].
pub fn vehicle_config(args: &SimulateArgs) -> Result<VehicleConfig, SimulateError> {
    let mut cfg = VehicleConfig {
        model: args.model,
        ideal_sensors: args.ideal_sensors,
        seed: args.seed,
        initial: InitialState {
            pos_m: args.initial.pos_m,
            euler: args.initial.euler,
        },
        mode: args.mode,
        armed: true,
        ..VehicleConfig::default()
    };
    apply_params(&mut cfg.gains, &mut cfg.control_rate_hz, &args.params)?;
    Ok(cfg)
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

/// Flies the configured vehicle for `args.duration` s, writing CSV rows to `out` if given.
///
/// # Errors
/// Bad parameters, or an I/O error while writing.
pub fn run(args: &SimulateArgs, mut out: Option<&mut dyn Write>) -> Result<Summary, SimulateError> {
    let cfg = vehicle_config(args)?;
    let mut v = Vehicle::new(cfg);
    v.set_position_setpoint(args.setpoint.0);
    let steps = (args.duration / PHYSICS_DT_S).round() as u64;
    let every = ((1.0 / (args.rate * PHYSICS_DT_S)).round() as u64).max(1);
    let mut rows = 0;
    if let Some(w) = out.as_deref_mut() {
        writeln!(w, "{CSV_HEADER}")?;
    }
    for k in 0..=steps {
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
        pos_error_m: (last.pos_m - args.setpoint.0).norm(),
        rows,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn parses_initial_and_setpoint() {
        let a = parse_initial("phi=0.1, theta=0.1,psi=1,x=0.1,y=0.1,z=0.1").unwrap();
        assert_eq!(a.euler, Euler::new(1.0, 0.1, 0.1));
        assert_eq!(a.pos_m, Vector3::new(0.1, 0.1, 0.1));
        assert_eq!(parse_initial("").unwrap(), InitialArg::default());
        assert!(parse_initial("roll=1").is_err());
        assert!(parse_initial("phi=abc").is_err());
        assert_eq!(
            parse_setpoint("z=2").unwrap().0,
            Vector3::new(0.0, 0.0, 2.0)
        );
    }

    #[test]
    fn params_are_checked_as_a_set() {
        let mut g = Gains::default();
        let mut rate = 100.0;
        let p = |s: &str| parse_param(s).unwrap();
        assert!(parse_param("NOPE=1").is_err());
        apply_params(&mut g, &mut rate, &[p("ALT_KP=4"), p("lat_sat_d=0.1")]).unwrap();
        assert_eq!((g.alt_kp, g.lateral.d), (4.0, 0.1));
        let err = apply_params(&mut g, &mut rate, &[p("LAT_SAT_D=0.5")]).unwrap_err();
        let chain = std::error::Error::source(&err)
            .map(ToString::to_string)
            .unwrap_or_default();
        assert!(chain.contains("c > d"), "{err}: {chain}");
    }
}
