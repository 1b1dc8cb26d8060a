//! ArduPilot's battery failsafe (`AP_BattMonitor::check_failsafes` and Plane's
//! `handle_battery_failsafe`): a pack is *low* when its voltage stays below `BATT_LOW_VOLT` for
//! `BATT_LOW_TIMER` seconds or its remaining capacity falls below `BATT_LOW_MAH`, and *critical*
//! likewise with `BATT_CRT_VOLT`/`BATT_CRT_MAH` (a zero threshold is off). Each level is
//! reported once per boot, in ArduPilot's words ("Battery 1 is low 10.45V used 1100 mAh"), and
//! takes its action (`BATT_FS_LOW_ACT`, `BATT_FS_CRT_ACT`) while armed; the level only rises.

use crate::model::plant::battery::BatteryState;
use crate::nav::params::Params;

/// How low the pack is.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord)]
pub enum Level {
    /// Below the low thresholds.
    Low,
    /// Below the critical thresholds.
    Critical,
}

/// What the vehicle does about it (ArduPlane's `BATT_FS_*_ACT` values).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Action {
    /// 0: report only.
    None,
    /// 1: RTL (QRTL with `Q_RTL_MODE` 3).
    Rtl,
    /// 2 (Land), 4 (QLand), 6 (Loiter to QLand): QLAND.
    QLand,
    /// 3: terminate, the motors stop.
    Terminate,
}

impl Action {
    fn from_param(v: f64) -> Self {
        match v.round() as i32 {
            1 => Action::Rtl,
            3 => Action::Terminate,
            2 | 4..=6 => Action::QLand,
            _ => Action::None,
        }
    }
}

/// A level reached: its action and the text the vehicle sends.
#[derive(Debug, Clone, PartialEq)]
pub struct Event {
    /// The level.
    pub level: Level,
    /// What to do (only while armed).
    pub action: Action,
    /// The STATUSTEXT, ArduPilot's words.
    pub text: String,
}

/// The thresholds, from the parameters.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Limits {
    low_volt: f64,
    crt_volt: f64,
    low_mah: f64,
    crt_mah: f64,
    timer_us: u64,
    low_act: Action,
    crt_act: Action,
    capacity_mah: f64,
}

impl Limits {
    /// From the `BATT_*` parameters.
    #[must_use]
    pub fn from_params(p: &Params) -> Self {
        Self {
            low_volt: p.value("BATT_LOW_VOLT"),
            crt_volt: p.value("BATT_CRT_VOLT"),
            low_mah: p.value("BATT_LOW_MAH"),
            crt_mah: p.value("BATT_CRT_MAH"),
            timer_us: (p.value("BATT_LOW_TIMER").max(0.0) * 1e6) as u64,
            low_act: Action::from_param(p.value("BATT_FS_LOW_ACT")),
            crt_act: Action::from_param(p.value("BATT_FS_CRT_ACT")),
            capacity_mah: p.value("BATT_CAPACITY"),
        }
    }
}

/// The failsafe's memory over a boot.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct BatteryFailsafe {
    level: Option<Level>,
    /// Since when the voltage has been below the low / the critical threshold, µs.
    below_since_us: [Option<u64>; 2],
}

impl BatteryFailsafe {
    /// The level reached so far this boot.
    #[must_use]
    pub fn level(&self) -> Option<Level> {
        self.level
    }

    /// Checks the pack at sim time `now_us`; a level reached for the first time is returned.
    pub fn check(&mut self, lim: &Limits, b: &BatteryState, now_us: u64) -> Option<Event> {
        let left_mah = lim.capacity_mah - b.consumed_mah;
        let mut volt_low = |i: usize, threshold: f64| {
            if threshold > 0.0 && b.voltage_v < threshold {
                let since = *self.below_since_us[i].get_or_insert(now_us);
                now_us.saturating_sub(since) >= lim.timer_us
            } else {
                self.below_since_us[i] = None;
                false
            }
        };
        let crt = volt_low(1, lim.crt_volt) || (lim.crt_mah > 0.0 && left_mah < lim.crt_mah);
        let low = volt_low(0, lim.low_volt) || (lim.low_mah > 0.0 && left_mah < lim.low_mah);
        let reached = if crt {
            Level::Critical
        } else if low {
            Level::Low
        } else {
            return None;
        };
        if self.level.is_some_and(|l| l >= reached) {
            return None;
        }
        self.level = Some(reached);
        let (word, action) = match reached {
            Level::Low => ("low", lim.low_act),
            Level::Critical => ("critical", lim.crt_act),
        };
        Some(Event {
            level: reached,
            action,
            text: format!(
                "Battery 1 is {word} {:.2}V used {:.0} mAh",
                b.voltage_v, b.consumed_mah
            ),
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn limits() -> Limits {
        Limits {
            low_volt: 10.5,
            crt_volt: 0.0,
            low_mah: 300.0,
            crt_mah: 100.0,
            timer_us: 10_000_000,
            low_act: Action::Rtl,
            crt_act: Action::QLand,
            capacity_mah: 1300.0,
        }
    }

    fn pack(voltage_v: f64, consumed_mah: f64) -> BatteryState {
        BatteryState {
            voltage_v,
            consumed_mah,
            ..BatteryState::default()
        }
    }

    #[test]
    fn low_voltage_must_last_the_timer_and_capacity_acts_at_once() {
        let mut fs = BatteryFailsafe::default();
        let lim = limits();
        assert_eq!(fs.check(&lim, &pack(10.4, 0.0), 0), None);
        // A dip shorter than the timer is forgotten.
        assert_eq!(fs.check(&lim, &pack(11.0, 0.0), 5_000_000), None);
        assert_eq!(fs.check(&lim, &pack(10.4, 0.0), 6_000_000), None);
        let e = fs.check(&lim, &pack(10.4, 10.0), 16_000_000).expect("low");
        assert_eq!(e.level, Level::Low);
        assert_eq!(e.action, Action::Rtl);
        assert_eq!(e.text, "Battery 1 is low 10.40V used 10 mAh");
        // Reported once.
        assert_eq!(fs.check(&lim, &pack(10.4, 20.0), 17_000_000), None);
        // Capacity: 1210 mAh used leaves 90 < BATT_CRT_MAH.
        let e = fs
            .check(&lim, &pack(10.4, 1210.0), 17_000_001)
            .expect("critical");
        assert_eq!((e.level, e.action), (Level::Critical, Action::QLand));
        assert_eq!(fs.check(&lim, &pack(10.4, 1250.0), 18_000_000), None);
        assert_eq!(fs.level(), Some(Level::Critical));
    }

    #[test]
    fn zero_thresholds_are_off() {
        let mut fs = BatteryFailsafe::default();
        let lim = Limits {
            low_volt: 0.0,
            low_mah: 0.0,
            crt_mah: 0.0,
            ..limits()
        };
        assert_eq!(fs.check(&lim, &pack(1.0, 5000.0), 100_000_000), None);
    }
}
