//! Position on the globe: the motion-capture frame anchored at a geographic origin, and the
//! conversions between local NED offsets and latitude, longitude and altitude.
//!
//! The twin flies in the motion-capture frame (`frames`: the paper's z-up inertial frame, NED at
//! the wire). Ground stations and scripts speak latitude and longitude, so the frame's origin is
//! pinned to a point on the globe ([`Origin`], from the `SIM_HOME_LAT`/`LON`/`ALT` parameters,
//! north-aligned, the ground at z = 0 being `SIM_HOME_ALT` above mean sea level).
//!
//! The map is ArduPilot's flat-earth approximation (`Location::offset`, `get_distance_NE`):
//! 1e-7 degree of latitude is [`METERS_PER_E7_DEG`], a degree of longitude shrinks by the cosine
//! of the mean latitude of the two points. Over the few hundred metres the twin flies, this
//! agrees with the ellipsoid to well below the motion capture's noise, and a GCS that does the
//! same arithmetic (MAVProxy, QGroundControl) places the vehicle on its map where the twin says.
//!
//! Latitudes and longitudes travel as `i32` in 1e-7 degree (`*_e7`), altitudes in metres above
//! mean sea level (AMSL) unless the name says otherwise.

use nalgebra::Vector3;

/// Metres per 1e-7 degree of latitude (ArduPilot's `LOCATION_SCALING_FACTOR`: a sphere of
/// radius 6 378 100 m).
pub const METERS_PER_E7_DEG: f64 = 0.011_131_884_502_145_034;

/// Smallest cosine used to scale longitudes, so that the poles stay finite (ArduPilot clamps the
/// same way).
const MIN_LON_SCALE: f64 = 0.01;

/// A point on the globe.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct GeoPoint {
    /// Latitude, 1e-7 degree.
    pub lat_e7: i32,
    /// Longitude, 1e-7 degree.
    pub lon_e7: i32,
    /// Altitude above mean sea level, m.
    pub alt_amsl_m: f64,
}

impl GeoPoint {
    /// A point from degrees (rounded to 1e-7 degree).
    #[must_use]
    pub fn from_degrees(lat_deg: f64, lon_deg: f64, alt_amsl_m: f64) -> Self {
        Self {
            lat_e7: deg_to_e7(lat_deg),
            lon_e7: deg_to_e7(lon_deg),
            alt_amsl_m,
        }
    }
}

/// Degrees to 1e-7 degree, rounded and clamped to the `i32` range.
#[must_use]
pub fn deg_to_e7(deg: f64) -> i32 {
    (deg * 1e7)
        .round()
        .clamp(f64::from(i32::MIN), f64::from(i32::MAX)) as i32
}

/// Whether a latitude and longitude (1e-7 degree) name a real place.
#[must_use]
pub fn valid_lat_lon(lat_e7: i32, lon_e7: i32) -> bool {
    (-900_000_000..=900_000_000).contains(&lat_e7)
        && (-1_800_000_000..=1_800_000_000).contains(&lon_e7)
}

/// cos(latitude) of the mean latitude of two points, floored at [`MIN_LON_SCALE`].
fn lon_scale(lat_a_e7: i32, lat_b_e7: i32) -> f64 {
    let mean_deg = (f64::from(lat_a_e7) + f64::from(lat_b_e7)) * 0.5e-7;
    mean_deg.to_radians().cos().max(MIN_LON_SCALE)
}

/// Longitude difference b − a in 1e-7 degree, wrapped across the antimeridian.
fn lon_diff_e7(a: i32, b: i32) -> f64 {
    let mut d = f64::from(b) - f64::from(a);
    if d > 1.8e9 {
        d -= 3.6e9;
    } else if d < -1.8e9 {
        d += 3.6e9;
    }
    d
}

/// The motion-capture frame's origin on the globe (north-aligned; the ground is at z = 0).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Origin(pub GeoPoint);

impl Origin {
    /// The origin `SIM_HOME_*` describe (degrees, metres AMSL).
    #[must_use]
    pub fn from_degrees(lat_deg: f64, lon_deg: f64, alt_amsl_m: f64) -> Self {
        Self(GeoPoint::from_degrees(lat_deg, lon_deg, alt_amsl_m))
    }

    /// The point at a local NED offset (m) from the origin.
    #[must_use]
    pub fn to_global(&self, ned_m: &Vector3<f64>) -> GeoPoint {
        let o = self.0;
        let dlat = ned_m.x / METERS_PER_E7_DEG;
        let lat = f64::from(o.lat_e7) + dlat;
        let lat_e7 = lat.round().clamp(-9e8, 9e8) as i32;
        let dlon = ned_m.y / (METERS_PER_E7_DEG * lon_scale(o.lat_e7, lat_e7));
        let mut lon = f64::from(o.lon_e7) + dlon;
        if lon > 1.8e9 {
            lon -= 3.6e9;
        } else if lon < -1.8e9 {
            lon += 3.6e9;
        }
        GeoPoint {
            lat_e7,
            lon_e7: lon.round() as i32,
            alt_amsl_m: o.alt_amsl_m - ned_m.z,
        }
    }

    /// The local NED offset (m) of a point from the origin.
    #[must_use]
    pub fn to_local_ned(&self, p: &GeoPoint) -> Vector3<f64> {
        let o = self.0;
        Vector3::new(
            (f64::from(p.lat_e7) - f64::from(o.lat_e7)) * METERS_PER_E7_DEG,
            lon_diff_e7(o.lon_e7, p.lon_e7) * METERS_PER_E7_DEG * lon_scale(o.lat_e7, p.lat_e7),
            o.alt_amsl_m - p.alt_amsl_m,
        )
    }

    /// Altitude AMSL of the ground (z = 0), m.
    #[must_use]
    pub fn ground_amsl_m(&self) -> f64 {
        self.0.alt_amsl_m
    }
}

/// Horizontal distance between two local NED points, m.
#[must_use]
pub fn horizontal_distance_m(a: &Vector3<f64>, b: &Vector3<f64>) -> f64 {
    (a.xy() - b.xy()).norm()
}

/// Bearing from `a` to `b` (local NED), degrees in [0, 360).
#[must_use]
pub fn bearing_deg(a: &Vector3<f64>, b: &Vector3<f64>) -> f64 {
    let d = b - a;
    d.y.atan2(d.x).to_degrees().rem_euclid(360.0)
}

#[cfg(test)]
mod tests {
    use super::*;

    const CMAC: (f64, f64, f64) = (-35.363_261, 149.165_230, 584.0);

    fn origin() -> Origin {
        Origin::from_degrees(CMAC.0, CMAC.1, CMAC.2)
    }

    #[test]
    fn origin_maps_to_itself() {
        let o = origin();
        let p = o.to_global(&Vector3::zeros());
        assert_eq!((p.lat_e7, p.lon_e7), (-353_632_610, 1_491_652_300));
        assert_eq!(p.alt_amsl_m, 584.0);
        assert_eq!(o.to_local_ned(&p), Vector3::zeros());
    }

    #[test]
    fn offsets_round_trip_to_a_centimetre() {
        let o = origin();
        for ned in [
            Vector3::new(5.0, 0.0, -2.0),
            Vector3::new(-123.4, 87.6, -30.0),
            Vector3::new(0.3, -0.7, 0.0),
            Vector3::new(2500.0, -1800.0, -100.0),
        ] {
            let back = o.to_local_ned(&o.to_global(&ned));
            assert!((back - ned).norm() < 0.012, "{ned} -> {back}");
        }
    }

    #[test]
    fn distances_match_ardupilot_scaling() {
        // 1e-5 degree of latitude is 1.1132 m; of longitude, that times cos(latitude).
        let o = origin();
        let north = GeoPoint {
            lat_e7: o.0.lat_e7 + 100,
            ..o.0
        };
        assert!((o.to_local_ned(&north).x - 1.113_188).abs() < 1e-5);
        let east = GeoPoint {
            lon_e7: o.0.lon_e7 + 100,
            ..o.0
        };
        let expect = 1.113_188 * CMAC.0.to_radians().cos();
        assert!((o.to_local_ned(&east).y - expect).abs() < 1e-5);
        let up = GeoPoint {
            alt_amsl_m: 590.0,
            ..o.0
        };
        assert_eq!(o.to_local_ned(&up).z, -6.0);
    }

    #[test]
    fn antimeridian_and_bad_coordinates() {
        let o = Origin::from_degrees(0.0, 179.999_99, 0.0);
        let p = o.to_global(&Vector3::new(0.0, 10.0, 0.0));
        assert!(p.lon_e7 < 0, "wrapped east across 180: {}", p.lon_e7);
        let back = o.to_local_ned(&p);
        assert!((back.y - 10.0).abs() < 0.02, "{back}");
        assert!(valid_lat_lon(900_000_000, -1_800_000_000));
        assert!(!valid_lat_lon(900_000_001, 0));
        assert_eq!(deg_to_e7(f64::NAN), 0);
        assert_eq!(deg_to_e7(1e30), i32::MAX);
    }

    #[test]
    fn bearings() {
        let a = Vector3::zeros();
        assert!((bearing_deg(&a, &Vector3::new(1.0, 0.0, 0.0)) - 0.0).abs() < 1e-12);
        assert!((bearing_deg(&a, &Vector3::new(0.0, 1.0, 0.0)) - 90.0).abs() < 1e-12);
        assert!((bearing_deg(&a, &Vector3::new(0.0, -1.0, 0.0)) - 270.0).abs() < 1e-12);
        assert!((horizontal_distance_m(&a, &Vector3::new(3.0, 4.0, 9.0)) - 5.0).abs() < 1e-12);
    }
}
