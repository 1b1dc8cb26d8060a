//! Pilot input over MAVLink (`PROTOCOL.md` A.7) and position targets.
//!
//! MANUAL_CONTROL and RC_CHANNELS_OVERRIDE are accepted only from the GCS system id
//! (`SYSID_MYGCS`), as ArduPilot does, and both become RC receiver pulse widths fed to
//! [`Vehicle::set_rc_input`]: channel 1 roll, 2 pitch, 3 throttle, 4 yaw. An override lapses
//! [`OVERRIDE_TIMEOUT_US`] after its last refresh (ArduPilot `RC_OVERRIDE_TIME`), and the
//! receiver then reports no signal (0) on those channels.

use mavlink::dialects::ardupilotmega as apm;
use nalgebra::Vector3;

use super::{Endpoint, Frame};
use crate::model::frames::ned_to_paper;
use crate::model::vehicle::Vehicle;

/// Override lifetime without refresh, µs.
pub const OVERRIDE_TIMEOUT_US: u64 = 3_000_000;

/// Overridden channels and when they were last refreshed.
#[derive(Debug, Clone, Copy, Default)]
pub struct ManualState {
    channels_us: [Option<u16>; 8],
    last_us: Option<u64>,
}

impl ManualState {
    fn apply(&self, vehicle: &mut Vehicle) {
        vehicle.set_rc_input(self.channels_us.map(|c| c.unwrap_or(0)));
    }

    /// Releases every override once it is stale.
    pub fn expire(&mut self, now_us: u64, vehicle: &mut Vehicle) {
        if self
            .last_us
            .is_some_and(|last| now_us.saturating_sub(last) > OVERRIDE_TIMEOUT_US)
        {
            *self = Self::default();
            self.apply(vehicle);
        }
    }
}

impl Endpoint {
    fn is_from_gcs(&self, frame: &Frame) -> bool {
        f64::from(frame.system_id()) == self.params.value("SYSID_MYGCS")
    }

    pub(super) fn on_rc_override(&mut self, frame: &Frame, o: &apm::RC_CHANNELS_OVERRIDE_DATA) {
        if !self.is_from_gcs(frame) {
            return;
        }
        let values = [
            o.chan1_raw,
            o.chan2_raw,
            o.chan3_raw,
            o.chan4_raw,
            o.chan5_raw,
            o.chan6_raw,
            o.chan7_raw,
            o.chan8_raw,
        ];
        for (slot, v) in self.manual.channels_us.iter_mut().zip(values) {
            match v {
                // 0 releases the channel, UINT16_MAX leaves it as it is (common.xml).
                0 => *slot = None,
                u16::MAX => {}
                v => *slot = Some(v),
            }
        }
        // Channels 9–18 do not exist on the twin's receiver and are ignored.
        self.manual.last_us = Some(self.now_us);
        self.manual.apply(&mut self.vehicle);
    }

    pub(super) fn on_manual_control(&mut self, frame: &Frame, m: &apm::MANUAL_CONTROL_DATA) {
        if m.target != self.sysid.0 || !self.is_from_gcs(frame) {
            return;
        }
        // ArduPlane's mapping: y → roll, x → pitch (forward stick = nose down, so reversed),
        // z → throttle 0..1000, r → yaw; 32767 marks an axis as unused.
        let axis = |v: i16, f: fn(f64) -> f64| {
            (v != i16::MAX).then(|| f(f64::from(v.clamp(-1000, 1000))).round() as u16)
        };
        let updates = [
            (0, axis(m.y, |v| 1500.0 + v / 2.0)),
            (1, axis(m.x, |v| 1500.0 - v / 2.0)),
            (2, axis(m.z, |v| 1000.0 + v.clamp(0.0, 1000.0))),
            (3, axis(m.r, |v| 1500.0 + v / 2.0)),
        ];
        for (ch, value) in updates {
            if let Some(v) = value {
                self.manual.channels_us[ch] = Some(v);
            }
        }
        self.manual.last_us = Some(self.now_us);
        self.manual.apply(&mut self.vehicle);
    }

    /// SET_POSITION_TARGET_LOCAL_NED in LOCAL_NED (1) with the position not masked out moves
    /// the hover point (QLOITER), converted from NED to the twin's z-up frame; in GUIDED it is
    /// a guided target (checked against the flight envelope).
    pub(super) fn on_position_target(
        &mut self,
        link: super::LinkKey,
        t: &apm::SET_POSITION_TARGET_LOCAL_NED_DATA,
    ) {
        use apm::PositionTargetTypemask as Mask;
        if t.coordinate_frame != apm::MavFrame::MAV_FRAME_LOCAL_NED {
            return;
        }
        let ignore = Mask::POSITION_TARGET_TYPEMASK_X_IGNORE
            | Mask::POSITION_TARGET_TYPEMASK_Y_IGNORE
            | Mask::POSITION_TARGET_TYPEMASK_Z_IGNORE;
        if t.type_mask.intersects(ignore) {
            return;
        }
        let ned = Vector3::new(f64::from(t.x), f64::from(t.y), f64::from(t.z));
        if self.vehicle.telemetry().mode == crate::model::mode::FlightMode::Guided {
            self.guided_target(link, ned);
        } else if ned.iter().all(|v| v.is_finite()) {
            self.vehicle.set_position_setpoint(ned_to_paper(&ned));
        }
    }
}
