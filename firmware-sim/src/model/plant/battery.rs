//! The flight battery: a lithium-polymer pack that drains with the power the motors draw.
//!
//! The prototype's battery is not in the paper; this is an assumption sized for a 0.5 kg
//! two-rotor vehicle (like `PHYSICS.md` §5's actuator constants). The shaft power of each rotor
//! is its drag torque times its speed, l_r·k_D·ω³ (the reaction torque of the model, about 16 W
//! per rotor at hover); the motors, gearboxes and ESCs turn [`DRIVE_EFFICIENCY`] of the electric
//! power into it, and the avionics draw [`AVIONICS_CURRENT_A`]. The pack's open-circuit voltage
//! falls with the charge drawn along a typical LiPo discharge curve, less the sag across its
//! internal resistance; hover draws about 5 A from a 3-cell 1300 mAh pack, so a full pack hovers
//! for about a quarter of an hour.
//!
//! The motors weaken with the pack: a brushed motor's speed follows its voltage. The autopilot
//! compensates for sag down to [`COMPENSATION_CELL_V`] a cell under load (ArduPilot's
//! `MOT_BAT_VOLT_MIN`), so a healthy pack flies as a full one; below it the rotors reach only
//! [`Battery::supply_ratio`] of the speed commanded. Past empty the cells collapse (the open-circuit
//! voltage falls to zero over the next [`OVER_DISCHARGE`] of the capacity): a flat pack does not fly.

/// Fraction of the electric power that reaches the propeller shafts (brushed motor, 1:6
/// gearbox, ESC).
pub const DRIVE_EFFICIENCY: f64 = 0.6;
/// Current drawn by the avionics (autopilot, receiver, radio), A.
pub const AVIONICS_CURRENT_A: f64 = 0.3;
/// Internal resistance of the pack, Ω.
pub const INTERNAL_RESISTANCE_OHM: f64 = 0.06;
/// Number of cells in series.
pub const CELLS: u16 = 3;
/// Loaded cell voltage down to which the autopilot keeps the full thrust, V (scaled with the
/// pack's full voltage for other packs).
pub const COMPENSATION_CELL_V: f64 = 3.3;
/// Charge drawn past empty, as a fraction of the capacity, at which a cell reads 0 V.
pub const OVER_DISCHARGE: f64 = 0.05;

/// Open-circuit cell voltage against state of charge (0 = empty, 1 = full), V: a typical LiPo
/// curve, steep at both ends and flat around 3.8 V.
const CELL_OCV: [(f64, f64); 7] = [
    (0.0, 3.30),
    (0.05, 3.50),
    (0.15, 3.68),
    (0.5, 3.82),
    (0.8, 3.98),
    (0.95, 4.12),
    (1.0, 4.20),
];

/// The pack's size, from the `BATT_CAPACITY` and `SIM_BATT_VOLTAGE` parameters.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct BatteryConfig {
    /// Capacity, mAh.
    pub capacity_mah: f64,
    /// Voltage of the full pack at rest, V (scales the cell curve; 12.6 V = 3 × 4.2 V).
    pub full_voltage_v: f64,
}

impl BatteryConfig {
    /// A bench supply: the full voltage less the sag, for ever (infinite capacity). What the
    /// pure model flies by default, so that its long-endurance runs measure the controller and
    /// not the pack; the served twin's pack comes from `BATT_CAPACITY`.
    #[must_use]
    pub fn bench_supply() -> Self {
        Self {
            capacity_mah: f64::INFINITY,
            ..Self::default()
        }
    }
}

impl Default for BatteryConfig {
    fn default() -> Self {
        Self {
            capacity_mah: 1300.0,
            full_voltage_v: 12.6,
        }
    }
}

/// What the battery reports.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct BatteryState {
    /// Terminal voltage, V.
    pub voltage_v: f64,
    /// Current drawn, A.
    pub current_a: f64,
    /// Charge drawn since power-up, mAh.
    pub consumed_mah: f64,
    /// Energy drawn since power-up, J.
    pub consumed_j: f64,
    /// Remaining charge, 0..1.
    pub remaining: f64,
}

/// The battery model.
#[derive(Debug, Clone, PartialEq)]
pub struct Battery {
    config: BatteryConfig,
    state: BatteryState,
}

impl Battery {
    /// A full pack.
    #[must_use]
    pub fn new(config: BatteryConfig) -> Self {
        let mut b = Self {
            config,
            state: BatteryState {
                remaining: 1.0,
                ..BatteryState::default()
            },
        };
        b.state.voltage_v = b.open_circuit_v(1.0);
        b
    }

    /// The same pack after a restart of the firmware: the charge drawn stays drawn (a reboot
    /// does not refill a pack), no current flows yet, and the size is `config` (the parameters
    /// as they stand at the restart).
    #[must_use]
    pub fn restarted(&self, config: BatteryConfig) -> Self {
        let mut b = Self {
            config,
            state: BatteryState {
                consumed_mah: self.state.consumed_mah,
                consumed_j: self.state.consumed_j,
                ..BatteryState::default()
            },
        };
        let soc = 1.0 - b.state.consumed_mah / b.config.capacity_mah.max(1.0);
        b.state.remaining = soc.clamp(0.0, 1.0);
        b.state.voltage_v = b.open_circuit_v(soc);
        b
    }

    /// Open-circuit voltage of the pack at a state of charge, V; below 0 (drawn past empty) the
    /// cells collapse linearly to 0 V at −[`OVER_DISCHARGE`].
    fn open_circuit_v(&self, soc: f64) -> f64 {
        if soc < 0.0 {
            let at_empty = self.open_circuit_v(0.0);
            return (at_empty * (1.0 + soc / OVER_DISCHARGE)).max(0.0);
        }
        let soc = soc.min(1.0);
        let cell = CELL_OCV.windows(2).find(|w| soc <= w[1].0).map_or(
            CELL_OCV[CELL_OCV.len() - 1].1,
            |w| {
                let (s0, v0) = w[0];
                let (s1, v1) = w[1];
                v0 + (v1 - v0) * (soc - s0) / (s1 - s0)
            },
        );
        cell / CELL_OCV[CELL_OCV.len() - 1].1 * self.config.full_voltage_v
    }

    /// Draws the current for `dt_s` with the rotors at these speeds (rad/s): `rotor_arm_m ×
    /// k_drag × ω³` is each shaft's power.
    pub fn step(&mut self, dt_s: f64, rotor_speed_rad_s: [f64; 2], rotor_arm_m: f64, k_drag: f64) {
        self.step_with_work(dt_s, rotor_speed_rad_s, rotor_arm_m, k_drag, 0.0);
    }

    /// [`Battery::step`] with the work the thrust does on the air flowing through the rotors,
    /// T·V with V the inflow along the thrust axis, W: the power a propeller needs on top of its
    /// static power when the air meets it at speed (forward flight, a climb). Zero in hover.
    pub fn step_with_work(
        &mut self,
        dt_s: f64,
        rotor_speed_rad_s: [f64; 2],
        rotor_arm_m: f64,
        k_drag: f64,
        thrust_work_w: f64,
    ) {
        let shaft_w: f64 = rotor_speed_rad_s
            .iter()
            .map(|w| rotor_arm_m * k_drag * w.abs().powi(3))
            .sum::<f64>()
            + thrust_work_w.max(0.0);
        let soc = 1.0 - self.state.consumed_mah / self.config.capacity_mah.max(1.0);
        let ocv = self.open_circuit_v(soc);
        // P = V·I with V = ocv − R·I: the smaller root of R·I² − ocv·I + P = 0.
        let p = shaft_w / DRIVE_EFFICIENCY;
        let disc = (ocv * ocv - 4.0 * INTERNAL_RESISTANCE_OHM * p).max(0.0);
        let motor_a = (ocv - disc.sqrt()) / (2.0 * INTERNAL_RESISTANCE_OHM);
        let current = motor_a + AVIONICS_CURRENT_A;
        let voltage = (ocv - INTERNAL_RESISTANCE_OHM * current).max(0.0);
        let s = &mut self.state;
        s.current_a = current;
        s.voltage_v = voltage;
        s.consumed_mah += current * dt_s / 3.6;
        s.consumed_j += voltage * current * dt_s;
        s.remaining = (1.0 - s.consumed_mah / self.config.capacity_mah.max(1.0)).clamp(0.0, 1.0);
    }

    /// Fraction of the commanded rotor speed the pack can drive now: 1 while the loaded voltage
    /// stays above the compensation floor, then in proportion to the voltage.
    #[must_use]
    pub fn supply_ratio(&self) -> f64 {
        let floor =
            COMPENSATION_CELL_V / CELL_OCV[CELL_OCV.len() - 1].1 * self.config.full_voltage_v;
        (self.state.voltage_v / floor).clamp(0.0, 1.0)
    }

    /// What the battery reports now.
    #[must_use]
    pub fn state(&self) -> &BatteryState {
        &self.state
    }

    /// The pack's size.
    #[must_use]
    pub fn config(&self) -> &BatteryConfig {
        &self.config
    }

    /// Voltage of one cell, V (BATTERY_STATUS lists the cells).
    #[must_use]
    pub fn cell_voltage_v(&self) -> f64 {
        self.state.voltage_v / f64::from(CELLS)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::model::airframe::Airframe;

    #[test]
    fn full_at_rest() {
        let b = Battery::new(BatteryConfig::default());
        assert!((b.state().voltage_v - 12.6).abs() < 1e-12);
        assert_eq!(b.state().remaining, 1.0);
    }

    #[test]
    fn hover_draws_about_five_amps_and_drains() {
        let af = Airframe::default();
        let w = af.hover_rotor_speed_rad_s();
        let mut b = Battery::new(BatteryConfig::default());
        // One minute of hover at 100 Hz.
        for _ in 0..6000 {
            b.step(0.01, [w, w], af.rotor_arm_m, af.k_drag_n_per_rad2_s2);
        }
        let s = *b.state();
        assert_eq!(
            b.supply_ratio(),
            1.0,
            "a healthy pack drives the motors fully"
        );
        assert!((4.0..6.5).contains(&s.current_a), "{s:?}");
        assert!(s.voltage_v < 12.6 && s.voltage_v > 11.0, "{s:?}");
        // ≈ 5 A for 60 s is ≈ 83 mAh of 1300.
        assert!((70.0..110.0).contains(&s.consumed_mah), "{s:?}");
        assert!((s.remaining - (1.0 - s.consumed_mah / 1300.0)).abs() < 1e-12);
        // Idle rotors draw only the avionics.
        let mut idle = Battery::new(BatteryConfig::default());
        idle.step(1.0, [0.0, 0.0], af.rotor_arm_m, af.k_drag_n_per_rad2_s2);
        assert!((idle.state().current_a - AVIONICS_CURRENT_A).abs() < 1e-12);
    }

    #[test]
    fn voltage_falls_with_charge_and_stays_finite_when_flat() {
        let mut b = Battery::new(BatteryConfig {
            capacity_mah: 10.0,
            full_voltage_v: 12.6,
        });
        let mut last = f64::INFINITY;
        for _ in 0..200 {
            b.step(1.0, [300.0, 300.0], 0.15, 1.25e-6);
            let v = b.state().voltage_v;
            assert!(v.is_finite() && v <= last + 1e-12, "{v} after {last}");
            last = v;
        }
        assert_eq!(b.state().remaining, 0.0);
        assert!(b.state().voltage_v < 10.5);
        // Drawn past empty the cells collapse: the motors can no longer be driven.
        assert!(b.supply_ratio() < 0.05, "{}", b.supply_ratio());
        // Absurd power never gives a NaN: the sag is capped at the open-circuit voltage.
        b.step(1.0, [1e6, 1e6], 0.15, 1.25e-6);
        assert!(b.state().current_a.is_finite() && b.state().voltage_v >= 0.0);
    }

    #[test]
    fn a_restart_keeps_the_charge_drawn() {
        let mut b = Battery::new(BatteryConfig::default());
        for _ in 0..60 {
            b.step(1.0, [400.0, 400.0], 0.15, 1.25e-6);
        }
        let drawn = *b.state();
        assert!(drawn.consumed_mah > 50.0, "{drawn:?}");
        let r = b.restarted(BatteryConfig::default());
        let s = *r.state();
        assert_eq!(
            (s.consumed_mah, s.consumed_j),
            (drawn.consumed_mah, drawn.consumed_j)
        );
        assert_eq!(s.remaining, drawn.remaining);
        assert_eq!(s.current_a, 0.0);
        // At rest: the open-circuit voltage of the charge left, above the loaded one, below full.
        assert!(s.voltage_v > drawn.voltage_v && s.voltage_v < 12.6, "{s:?}");
        // A larger pack set before the restart leaves more in proportion.
        let big = b.restarted(BatteryConfig {
            capacity_mah: 2600.0,
            ..BatteryConfig::default()
        });
        assert!((big.state().remaining - (1.0 - s.consumed_mah / 2600.0)).abs() < 1e-12);
    }
}
