//! Telemetry on the globe and about the flight: GLOBAL_POSITION_INT, GPS_RAW_INT, HOME_POSITION,
//! VFR_HUD, BATTERY_STATUS and NAV_CONTROLLER_OUTPUT, built from a [`Telemetry`] snapshot, the
//! frame's [`Origin`] and home (units from common.xml: 1e-7 degree, mm, cm/s, centidegrees).
//!
//! The "GPS" is the external position sensor (motion capture) seen through the frame's origin:
//! a 3D fix with millimetre accuracy once the firmware's navigation is ready (gyro calibration
//! done), no fix before, so a script that waits for a 3D fix can arm right after. Positions and
//! velocities are the ones LOCAL_POSITION_NED reports, so the map and the local plot agree.

use mavlink::dialects::ardupilotmega as apm;
use nalgebra::Vector3;

use crate::model::frames::{fixed_wing, paper_to_ned};
use crate::model::plant::battery::{BatteryState, CELLS};
use crate::model::vehicle::{SystemState, Telemetry};
use crate::nav::globe::{Origin, bearing_deg, horizontal_distance_m};
pub use vtol_link::protocol::id::{
    BATTERY_STATUS, GLOBAL_POSITION_INT, GPS_RAW_INT, HOME_POSITION, MISSION_CURRENT,
    NAV_CONTROLLER_OUTPUT, VFR_HUD,
};

/// POSITION_TARGET_GLOBAL_INT: where the navigator flies to, sent only while it has a target.
pub const POSITION_TARGET_GLOBAL_INT: u32 =
    <apm::POSITION_TARGET_GLOBAL_INT_DATA as mavlink::MessageData>::ID;

/// Satellites a good fix reports (the motion capture has none; scripts check for "enough").
pub const GPS_SATELLITES: u8 = 16;
/// Horizontal and vertical accuracy reported with the fix, mm (a few σ of the sensor's noise).
pub const GPS_ACCURACY_MM: u32 = 5;

/// What the builders need besides the telemetry.
#[derive(Debug, Clone, Copy)]
pub struct GlobeView<'a> {
    /// The vehicle.
    pub t: &'a Telemetry,
    /// Where the motion-capture frame sits on the globe.
    pub origin: Origin,
    /// Home, local NED, m.
    pub home_ned_m: Vector3<f64>,
    /// The navigator's target (local NED), if it flies to one.
    pub target_ned_m: Option<Vector3<f64>>,
    /// `BATT_CAPACITY`, mAh.
    pub capacity_mah: f64,
}

fn clamp_i16(v: f64) -> i16 {
    v.round().clamp(f64::from(i16::MIN), f64::from(i16::MAX)) as i16
}

fn clamp_i32(v: f64) -> i32 {
    v.round().clamp(f64::from(i32::MIN), f64::from(i32::MAX)) as i32
}

fn clamp_u16(v: f64) -> u16 {
    v.round().clamp(0.0, f64::from(u16::MAX)) as u16
}

/// Heading in degrees, [0, 360): the yaw of the fixed-wing body frame, as ArduPlane reports a
/// tailsitter's (the course on the wing).
fn heading_deg(t: &Telemetry) -> f64 {
    fixed_wing::attitude(&t.euler).heading_deg()
}

/// Whether the position solution is ready (a 3D fix).
#[must_use]
pub fn has_fix(t: &Telemetry) -> bool {
    t.state != SystemState::Calibrating
}

impl GlobeView<'_> {
    fn pos_ned(&self) -> Vector3<f64> {
        paper_to_ned(&self.t.pos_m)
    }

    fn vel_ned(&self) -> Vector3<f64> {
        paper_to_ned(&self.t.vel_m_s)
    }

    /// The message with this id, if it is one of this module's (not MISSION_CURRENT, which is
    /// the mission protocol's).
    #[must_use]
    pub fn build(&self, msgid: u32) -> Option<apm::MavMessage> {
        Some(match msgid {
            GLOBAL_POSITION_INT => self.global_position_int(),
            GPS_RAW_INT => self.gps_raw_int(),
            HOME_POSITION => home_position(&self.origin, &self.home_ned_m, self.t.t_us),
            VFR_HUD => self.vfr_hud(),
            BATTERY_STATUS => battery_status(&self.t.battery, self.capacity_mah),
            NAV_CONTROLLER_OUTPUT => self.nav_controller_output(),
            POSITION_TARGET_GLOBAL_INT => self.position_target()?,
            _ => return None,
        })
    }

    fn global_position_int(&self) -> apm::MavMessage {
        let ned = self.pos_ned();
        let p = self.origin.to_global(&ned);
        let v = self.vel_ned();
        apm::MavMessage::GLOBAL_POSITION_INT(apm::GLOBAL_POSITION_INT_DATA {
            time_boot_ms: (self.t.t_us / 1000) as u32,
            lat: p.lat_e7,
            lon: p.lon_e7,
            alt: clamp_i32(p.alt_amsl_m * 1000.0),
            relative_alt: clamp_i32((self.home_ned_m.z - ned.z) * 1000.0),
            vx: clamp_i16(v.x * 100.0),
            vy: clamp_i16(v.y * 100.0),
            vz: clamp_i16(v.z * 100.0),
            hdg: clamp_u16(heading_deg(self.t) * 100.0) % 36000,
        })
    }

    fn gps_raw_int(&self) -> apm::MavMessage {
        let fix = has_fix(self.t);
        let p = self.origin.to_global(&self.pos_ned());
        let v = self.vel_ned();
        let ground_speed = v.xy().norm();
        apm::MavMessage::GPS_RAW_INT(apm::GPS_RAW_INT_DATA {
            time_usec: self.t.t_us,
            lat: p.lat_e7,
            lon: p.lon_e7,
            alt: clamp_i32(p.alt_amsl_m * 1000.0),
            // HDOP and VDOP × 100: an excellent geometry.
            eph: if fix { 60 } else { u16::MAX },
            epv: if fix { 80 } else { u16::MAX },
            vel: clamp_u16(ground_speed * 100.0),
            cog: clamp_u16(v.y.atan2(v.x).to_degrees().rem_euclid(360.0) * 100.0) % 36000,
            fix_type: if fix {
                apm::GpsFixType::GPS_FIX_TYPE_3D_FIX
            } else {
                apm::GpsFixType::GPS_FIX_TYPE_NO_FIX
            },
            satellites_visible: if fix { GPS_SATELLITES } else { 0 },
            alt_ellipsoid: 0,
            h_acc: if fix { GPS_ACCURACY_MM } else { 0 },
            v_acc: if fix { GPS_ACCURACY_MM } else { 0 },
            vel_acc: if fix { 10 } else { 0 },
            hdg_acc: 0,
            // 0 = the receiver gives no heading.
            yaw: 0,
        })
    }

    fn vfr_hud(&self) -> apm::MavMessage {
        let t = self.t;
        let v = self.vel_ned();
        let ground = v.xy().norm();
        let alt = self.origin.to_global(&self.pos_ned()).alt_amsl_m;
        // Collective as a percentage of the ESC range.
        let esc = (f64::from(t.pwm_us[0]) + f64::from(t.pwm_us[1])) / 2.0;
        apm::MavMessage::VFR_HUD(apm::VFR_HUD_DATA {
            // True airspeed: the body's speed relative to the air, wind and gusts included
            // (the aerodynamic model's, docs/model.md).
            airspeed: t.airspeed_m_s() as f32,
            groundspeed: ground as f32,
            alt: alt as f32,
            climb: (-v.z) as f32,
            heading: clamp_i16(heading_deg(t)) % 360,
            throttle: clamp_u16(((esc - 1000.0) / 10.0).clamp(0.0, 100.0)),
        })
    }

    /// The navigator's target as ArduPlane sends `next_WP_loc`: latitude, longitude and the
    /// altitude above mean sea level (MAV_FRAME_GLOBAL), everything but the position ignored;
    /// none while the navigator has no target.
    fn position_target(&self) -> Option<apm::MavMessage> {
        use apm::PositionTargetTypemask as M;
        let p = self.origin.to_global(&self.target_ned_m?);
        Some(apm::MavMessage::POSITION_TARGET_GLOBAL_INT(
            apm::POSITION_TARGET_GLOBAL_INT_DATA {
                time_boot_ms: (self.t.t_us / 1000) as u32,
                lat_int: p.lat_e7,
                lon_int: p.lon_e7,
                alt: p.alt_amsl_m as f32,
                type_mask: M::all()
                    - (M::POSITION_TARGET_TYPEMASK_X_IGNORE
                        | M::POSITION_TARGET_TYPEMASK_Y_IGNORE
                        | M::POSITION_TARGET_TYPEMASK_Z_IGNORE),
                coordinate_frame: apm::MavFrame::MAV_FRAME_GLOBAL,
                ..Default::default()
            },
        ))
    }

    fn nav_controller_output(&self) -> apm::MavMessage {
        let t = self.t;
        let est = fixed_wing::attitude(&t.euler_est);
        let (roll, pitch) = (est.roll_rad, est.pitch_rad);
        let here = self.pos_ned();
        let (bearing, dist, alt_err) = match self.target_ned_m {
            Some(tg) => (
                bearing_deg(&here, &tg),
                horizontal_distance_m(&here, &tg),
                here.z - tg.z,
            ),
            None => (heading_deg(t), 0.0, 0.0),
        };
        apm::MavMessage::NAV_CONTROLLER_OUTPUT(apm::NAV_CONTROLLER_OUTPUT_DATA {
            nav_roll: roll.to_degrees() as f32,
            nav_pitch: pitch.to_degrees() as f32,
            alt_error: alt_err as f32,
            aspd_error: 0.0,
            xtrack_error: 0.0,
            nav_bearing: clamp_i16(bearing),
            target_bearing: clamp_i16(bearing),
            wp_dist: clamp_u16(dist),
        })
    }
}

/// HOME_POSITION for a home at `home_ned_m` (local NED).
#[must_use]
pub fn home_position(origin: &Origin, home_ned_m: &Vector3<f64>, t_us: u64) -> apm::MavMessage {
    let p = origin.to_global(home_ned_m);
    apm::MavMessage::HOME_POSITION(apm::HOME_POSITION_DATA {
        latitude: p.lat_e7,
        longitude: p.lon_e7,
        altitude: clamp_i32(p.alt_amsl_m * 1000.0),
        x: home_ned_m.x as f32,
        y: home_ned_m.y as f32,
        z: home_ned_m.z as f32,
        q: [1.0, 0.0, 0.0, 0.0],
        approach_x: 0.0,
        approach_y: 0.0,
        approach_z: 0.0,
        time_usec: t_us,
    })
}

/// Remaining charge below which the battery reports LOW, and CRITICAL (fractions).
const LOW: f64 = 0.2;
const CRITICAL: f64 = 0.1;

/// BATTERY_STATUS of the flight battery.
#[must_use]
pub fn battery_status(b: &BatteryState, capacity_mah: f64) -> apm::MavMessage {
    let mut voltages = [u16::MAX; 10];
    let cell_mv = clamp_u16(b.voltage_v / f64::from(CELLS) * 1000.0);
    for v in voltages.iter_mut().take(usize::from(CELLS)) {
        *v = cell_mv;
    }
    let charge_state = if b.remaining < CRITICAL {
        apm::MavBatteryChargeState::MAV_BATTERY_CHARGE_STATE_CRITICAL
    } else if b.remaining < LOW {
        apm::MavBatteryChargeState::MAV_BATTERY_CHARGE_STATE_LOW
    } else {
        apm::MavBatteryChargeState::MAV_BATTERY_CHARGE_STATE_OK
    };
    let left_mah = (capacity_mah - b.consumed_mah).max(0.0);
    let time_remaining = if b.current_a > 0.0 {
        clamp_i32(left_mah / 1000.0 / b.current_a * 3600.0)
    } else {
        0
    };
    apm::MavMessage::BATTERY_STATUS(apm::BATTERY_STATUS_DATA {
        current_consumed: clamp_i32(b.consumed_mah),
        // hJ.
        energy_consumed: clamp_i32(b.consumed_j / 100.0),
        // Unknown.
        temperature: i16::MAX,
        voltages,
        current_battery: clamp_i16(b.current_a * 100.0),
        id: 0,
        battery_function: apm::MavBatteryFunction::MAV_BATTERY_FUNCTION_ALL,
        mavtype: apm::MavBatteryType::MAV_BATTERY_TYPE_LIPO,
        battery_remaining: (b.remaining * 100.0).round().clamp(0.0, 100.0) as i8,
        time_remaining,
        charge_state,
        voltages_ext: [0; 4],
        mode: apm::MavBatteryMode::MAV_BATTERY_MODE_UNKNOWN,
        fault_bitmask: apm::MavBatteryFault::empty(),
    })
}

/// Whether a message id is built here or by the mission protocol (the ids this file adds to
/// the stream table).
#[must_use]
pub fn builds(msgid: u32) -> bool {
    matches!(
        msgid,
        GLOBAL_POSITION_INT
            | GPS_RAW_INT
            | HOME_POSITION
            | VFR_HUD
            | BATTERY_STATUS
            | NAV_CONTROLLER_OUTPUT
            | MISSION_CURRENT
            | POSITION_TARGET_GLOBAL_INT
    )
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::model::frames::Euler;

    fn view(t: &Telemetry) -> GlobeView<'_> {
        GlobeView {
            t,
            origin: Origin::from_degrees(-35.363_261, 149.165_230, 584.0),
            home_ned_m: Vector3::zeros(),
            target_ned_m: None,
            capacity_mah: 1300.0,
        }
    }

    #[test]
    fn global_position_of_a_hover_north_east_of_home() {
        // Paper frame: x = −north, y = east, z = up.
        let t = Telemetry {
            t_us: 12_345_000,
            pos_m: Vector3::new(-5.0, 3.0, 2.0),
            vel_m_s: Vector3::new(-1.0, 0.5, 0.25),
            // On the wing, nose 5° above the horizon toward the east.
            euler: Euler::new(std::f64::consts::FRAC_PI_2, 85_f64.to_radians(), 0.0),
            state: SystemState::Active,
            ..Telemetry::default()
        };
        let v = view(&t);
        let Some(apm::MavMessage::GLOBAL_POSITION_INT(g)) = v.build(GLOBAL_POSITION_INT) else {
            panic!()
        };
        let back = v.origin.to_local_ned(&crate::nav::globe::GeoPoint {
            lat_e7: g.lat,
            lon_e7: g.lon,
            alt_amsl_m: f64::from(g.alt) / 1000.0,
        });
        assert!(
            (back - Vector3::new(5.0, 3.0, -2.0)).norm() < 0.02,
            "{back}"
        );
        assert_eq!((g.alt, g.relative_alt), (586_000, 2_000));
        assert_eq!((g.vx, g.vy, g.vz), (100, 50, -25));
        assert_eq!(g.hdg, 9000, "the nose east");
        assert_eq!(g.time_boot_ms, 12_345);
        // On the tail the heading is the belly's, which faces the hover frame's back.
        let t = Telemetry {
            euler: Euler::new(-std::f64::consts::FRAC_PI_2, 0.0, 0.0),
            ..t
        };
        let Some(apm::MavMessage::GLOBAL_POSITION_INT(g)) = view(&t).build(GLOBAL_POSITION_INT)
        else {
            panic!()
        };
        assert_eq!(g.hdg, 27000, "hover frame yaw 90° (east): the belly west");
    }

    #[test]
    fn position_target_only_with_a_target_and_above_sea_level() {
        let t = Telemetry::default();
        let mut v = view(&t);
        assert!(v.build(POSITION_TARGET_GLOBAL_INT).is_none());
        v.target_ned_m = Some(Vector3::new(20.0, -10.0, -15.0));
        let Some(apm::MavMessage::POSITION_TARGET_GLOBAL_INT(p)) =
            v.build(POSITION_TARGET_GLOBAL_INT)
        else {
            panic!()
        };
        assert_eq!(p.coordinate_frame, apm::MavFrame::MAV_FRAME_GLOBAL);
        assert!((p.alt - 599.0).abs() < 1e-3, "{}", p.alt);
        let back = v.origin.to_local_ned(&crate::nav::globe::GeoPoint {
            lat_e7: p.lat_int,
            lon_e7: p.lon_int,
            alt_amsl_m: f64::from(p.alt),
        });
        assert!(
            (back - Vector3::new(20.0, -10.0, -15.0)).norm() < 0.02,
            "{back}"
        );
        use apm::PositionTargetTypemask as M;
        assert!(!p.type_mask.intersects(
            M::POSITION_TARGET_TYPEMASK_X_IGNORE
                | M::POSITION_TARGET_TYPEMASK_Y_IGNORE
                | M::POSITION_TARGET_TYPEMASK_Z_IGNORE
        ));
        assert!(p.type_mask.contains(M::POSITION_TARGET_TYPEMASK_VX_IGNORE));
    }

    #[test]
    fn fix_only_once_calibrated() {
        let mut t = Telemetry::default();
        let Some(apm::MavMessage::GPS_RAW_INT(g)) = view(&t).build(GPS_RAW_INT) else {
            panic!()
        };
        assert_eq!(g.fix_type, apm::GpsFixType::GPS_FIX_TYPE_NO_FIX);
        t.state = SystemState::Standby;
        let Some(apm::MavMessage::GPS_RAW_INT(g)) = view(&t).build(GPS_RAW_INT) else {
            panic!()
        };
        assert_eq!(g.fix_type, apm::GpsFixType::GPS_FIX_TYPE_3D_FIX);
        assert!(g.satellites_visible >= 6);
        assert_eq!(
            (g.lat, g.lon, g.alt),
            (-353_632_610, 1_491_652_300, 584_000)
        );
    }

    #[test]
    fn battery_and_hud() {
        let b = BatteryState {
            voltage_v: 11.4,
            current_a: 5.25,
            consumed_mah: 1170.0,
            consumed_j: 50_000.0,
            remaining: 0.1 - 1e-9,
        };
        let apm::MavMessage::BATTERY_STATUS(s) = battery_status(&b, 1300.0) else {
            panic!()
        };
        assert_eq!(&s.voltages[..4], &[3800, 3800, 3800, u16::MAX]);
        assert_eq!((s.current_battery, s.current_consumed), (525, 1170));
        assert_eq!(s.battery_remaining, 10);
        assert_eq!(
            s.charge_state,
            apm::MavBatteryChargeState::MAV_BATTERY_CHARGE_STATE_CRITICAL
        );
        assert_eq!(s.time_remaining, 89, "130 mAh at 5.25 A");
        let t = Telemetry {
            pwm_us: [1500, 1700, 1500, 1500, 1500],
            vel_m_s: Vector3::new(0.0, 0.0, 1.5),
            ..Telemetry::default()
        };
        let Some(apm::MavMessage::VFR_HUD(h)) = view(&t).build(VFR_HUD) else {
            panic!()
        };
        assert_eq!((h.throttle, h.climb, h.alt), (60, 1.5, 584.0));
    }

    #[test]
    fn home_and_nav_output() {
        let home = Vector3::new(1.0, -2.0, 0.0);
        let o = Origin::from_degrees(-35.363_261, 149.165_230, 584.0);
        let apm::MavMessage::HOME_POSITION(h) = home_position(&o, &home, 7) else {
            panic!()
        };
        assert_eq!((h.x, h.y, h.z, h.altitude), (1.0, -2.0, 0.0, 584_000));
        assert_eq!(h.q, [1.0, 0.0, 0.0, 0.0]);
        let t = Telemetry::default();
        let mut v = view(&t);
        v.target_ned_m = Some(Vector3::new(0.0, 4.0, -3.0));
        let Some(apm::MavMessage::NAV_CONTROLLER_OUTPUT(n)) = v.build(NAV_CONTROLLER_OUTPUT) else {
            panic!()
        };
        assert_eq!((n.wp_dist, n.target_bearing, n.alt_error), (4, 90, 3.0));
    }
}
