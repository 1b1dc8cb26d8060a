//! The Map view's model: mission items as the map draws them, the camera, the scene of one
//! vehicle read from the tracker's state, and the flat-earth projection around the camera's
//! centre (ArduPilot's, [`firmware_sim::nav::globe`]: metres north and east of a reference
//! point). The app moves the camera and keeps the mission; the view draws a scene through the
//! camera ([`crate::tui::view::map`]).

use firmware_sim::nav::globe::{GeoPoint, Origin};
use nalgebra::Vector3;
use vtol_link::dialect::MavMessage;
use vtol_link::protocol::id;

use crate::tracker::state::{VehicleState, VehicleView};

/// A latitude and longitude, 1e-7 degree (as MAVLink carries them).
pub type LatLon = (i32, i32);

/// Metres per terminal cell (its width; a cell is twice as tall), zoom level by level.
pub const ZOOMS_M: [f64; 13] = [
    0.5, 1.0, 2.0, 5.0, 10.0, 20.0, 50.0, 100.0, 200.0, 500.0, 1000.0, 2000.0, 5000.0,
];
/// The zoom level a camera starts at (10 m per cell).
pub const DEFAULT_ZOOM: usize = 4;
/// Cells a pan moves the centre by (rows count twice: a cell is twice as tall as wide).
pub const PAN_CELLS: f64 = 8.0;

/// What a mission item is, as the map draws it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum ItemKind {
    /// A take-off.
    Takeoff,
    /// A waypoint.
    Waypoint,
    /// A loiter, drawn as a circle of this radius, m.
    Loiter {
        /// Radius, m.
        radius_m: f32,
    },
    /// A landing (VTOL or fixed-wing).
    Land,
    /// Anything else (not a leg of the route).
    Other,
}

/// One mission item on the map.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MapItem {
    /// Sequence number.
    pub seq: u16,
    /// Where, 1e-7 degree; (0, 0) for an item without a place (a take-off where it stands).
    pub at: LatLon,
    /// What.
    pub kind: ItemKind,
}

impl MapItem {
    /// A mission item as MISSION_ITEM_INT carries it: its MAV_CMD, params 1 to 4 and place.
    /// A loiter's radius is its param 3 (param 2 for LOITER_TO_ALT), `default_radius_m`
    /// (`WP_LOITER_RAD`) when that is 0, as on ArduPlane; the sign (the turn's direction)
    /// is dropped.
    #[must_use]
    pub fn from_mission(
        seq: u16,
        command: u16,
        params: [f32; 4],
        at: LatLon,
        default_radius_m: f32,
    ) -> Self {
        let loiter = |r: f32| ItemKind::Loiter {
            radius_m: if r == 0.0 { default_radius_m } else { r.abs() },
        };
        use vtol_link::dialect::MavCmd as C;
        let is = |c: C| command == c as u16;
        let kind = if is(C::MAV_CMD_NAV_WAYPOINT) || is(C::MAV_CMD_NAV_SPLINE_WAYPOINT) {
            ItemKind::Waypoint
        } else if is(C::MAV_CMD_NAV_LOITER_UNLIM)
            || is(C::MAV_CMD_NAV_LOITER_TURNS)
            || is(C::MAV_CMD_NAV_LOITER_TIME)
        {
            loiter(params[2])
        } else if is(C::MAV_CMD_NAV_LOITER_TO_ALT) {
            loiter(params[1])
        } else if is(C::MAV_CMD_NAV_TAKEOFF) || is(C::MAV_CMD_NAV_VTOL_TAKEOFF) {
            ItemKind::Takeoff
        } else if is(C::MAV_CMD_NAV_LAND) || is(C::MAV_CMD_NAV_VTOL_LAND) {
            ItemKind::Land
        } else {
            ItemKind::Other
        };
        Self { seq, at, kind }
    }
}

/// The navigation items of a downloaded mission that have a place, as the map draws them:
/// item 0 (home) and items without a position (DO_*) are left out; a take-off at 0, 0 is drawn
/// at home.
#[must_use]
// The `_INT` frames are deprecated in the dialect, but vehicles still send them.
#[allow(deprecated)]
pub fn items_from_mission(items: &[crate::mission::Item], default_radius_m: f32) -> Vec<MapItem> {
    // A take-off without a place (the usual 0, 0) climbs where the vehicle is: drawn at home,
    // item 0, so its leg to the first waypoint shows.
    let home = items.first().map(|h| (h.x, h.y));
    let placed = |it: &crate::mission::Item| {
        use vtol_link::dialect::MavCmd as C;
        let takeoff = [C::MAV_CMD_NAV_TAKEOFF, C::MAV_CMD_NAV_VTOL_TAKEOFF]
            .iter()
            .any(|c| *c as u16 == it.command);
        match home {
            Some(h) if takeoff && it.x == 0.0 && it.y == 0.0 => crate::mission::Item {
                x: h.0,
                y: h.1,
                ..*it
            },
            _ => *it,
        }
    };
    items
        .iter()
        .map(placed)
        .enumerate()
        .skip(1)
        .filter(|(_, it)| it.x != 0.0 || it.y != 0.0)
        .filter(|(_, it)| {
            use vtol_link::dialect::MavFrame as F;
            [
                F::MAV_FRAME_GLOBAL,
                F::MAV_FRAME_GLOBAL_RELATIVE_ALT,
                F::MAV_FRAME_GLOBAL_INT,
                F::MAV_FRAME_GLOBAL_RELATIVE_ALT_INT,
                F::MAV_FRAME_GLOBAL_TERRAIN_ALT,
                F::MAV_FRAME_GLOBAL_TERRAIN_ALT_INT,
            ]
            .iter()
            .any(|f| *f as u8 == it.frame)
        })
        .map(|(seq, it)| {
            let at = ((it.x * 1e7).round() as i32, (it.y * 1e7).round() as i32);
            MapItem::from_mission(seq as u16, it.command, it.params, at, default_radius_m)
        })
        .collect()
}

/// The vehicle on the map.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MapVehicle {
    /// Where, 1e-7 degree.
    pub at: LatLon,
    /// Heading, degrees clockwise from north, when known.
    pub heading_deg: Option<f32>,
}

/// Everything the map draws.
#[derive(Debug, Clone, Copy, Default)]
pub struct MapScene<'a> {
    /// Home.
    pub home: Option<LatLon>,
    /// The vehicle.
    pub vehicle: Option<MapVehicle>,
    /// The vehicle's live position target.
    pub target: Option<LatLon>,
    /// The mission, in order.
    pub items: &'a [MapItem],
    /// The item the vehicle flies to.
    pub current_seq: Option<u16>,
    /// The track flown, oldest first.
    pub track: &'a [LatLon],
}

/// Where the map looks and how far it sees.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MapCamera {
    /// The centre while not following.
    pub center: Option<LatLon>,
    /// Index into [`ZOOMS_M`].
    pub zoom: usize,
    /// Whether the centre follows the vehicle.
    pub follow: bool,
    /// The centre the last frame showed (where a pan starts).
    pub shown: Option<LatLon>,
}

impl Default for MapCamera {
    fn default() -> Self {
        Self {
            center: None,
            zoom: DEFAULT_ZOOM,
            follow: true,
            shown: None,
        }
    }
}

impl MapCamera {
    /// Metres per cell width.
    #[must_use]
    pub fn metres_per_cell(&self) -> f64 {
        ZOOMS_M[self.zoom.min(ZOOMS_M.len() - 1)]
    }

    /// Closer in (fewer metres per cell).
    pub fn zoom_in(&mut self) {
        self.zoom = self.zoom.saturating_sub(1);
    }

    /// Further out.
    pub fn zoom_out(&mut self) {
        self.zoom = (self.zoom + 1).min(ZOOMS_M.len() - 1);
    }

    /// Moves the centre by `cells_east` cell widths and `cells_north` cell widths from where
    /// the last frame was centred; the camera stops following the vehicle.
    pub fn pan(&mut self, cells_north: f64, cells_east: f64) {
        let Some(from) = self.center.filter(|_| !self.follow).or(self.shown) else {
            return;
        };
        let m = self.metres_per_cell();
        let p = origin(from).to_global(&Vector3::new(cells_north * m, cells_east * m, 0.0));
        self.center = Some((p.lat_e7, p.lon_e7));
        self.follow = false;
    }

    /// Follows the vehicle again.
    pub fn follow(&mut self) {
        self.follow = true;
        self.center = None;
    }

    /// The centre for `scene`: the vehicle while following, else the chosen centre, else
    /// whatever the scene has (vehicle, home, first placed item).
    #[must_use]
    pub fn center_for(&self, scene: &MapScene<'_>) -> Option<LatLon> {
        let vehicle = scene.vehicle.map(|v| v.at);
        let fallback = || {
            vehicle
                .or(scene.home)
                .or_else(|| scene.items.iter().map(|i| i.at).find(|a| *a != (0, 0)))
        };
        if self.follow {
            vehicle.or(self.center).or_else(fallback)
        } else {
            self.center.or_else(fallback)
        }
    }
}

/// The Map view's state in the app: camera and the mission shown.
#[derive(Debug, Clone, Default)]
pub struct MapState {
    /// Camera.
    pub camera: MapCamera,
    /// The mission drawn (downloaded when the view is first entered; `r` again).
    pub items: Vec<MapItem>,
    /// The mission as downloaded (item 0 home), for the Flight view's progress line.
    pub mission: Option<Vec<crate::mission::Item>>,
    /// Whether the mission was asked for.
    pub requested: bool,
}

/// The flat-earth projection around `at`.
pub(crate) fn origin(at: LatLon) -> Origin {
    Origin(GeoPoint {
        lat_e7: at.0,
        lon_e7: at.1,
        alt_amsl_m: 0.0,
    })
}

/// Metres (east, north) of `p` from `reference` (x east, y north, as the canvas draws).
#[must_use]
pub fn east_north_m(reference: LatLon, p: LatLon) -> (f64, f64) {
    let ned = origin(reference).to_local_ned(&GeoPoint {
        lat_e7: p.0,
        lon_e7: p.1,
        alt_amsl_m: 0.0,
    });
    (ned.y, ned.x)
}

/// Vehicle, home, live target and current mission item of `v` from the tracker's last
/// GLOBAL_POSITION_INT, HOME_POSITION, POSITION_TARGET_GLOBAL_INT and MISSION_CURRENT.
#[must_use]
pub fn scene_parts(
    state: &VehicleState,
    v: &VehicleView,
) -> (
    Option<MapVehicle>,
    Option<LatLon>,
    Option<LatLon>,
    Option<u16>,
) {
    let last = |id: u32| {
        state
            .messages
            .get(&(v.system_id, v.component_id, id))
            .and_then(|m| m.last.decode_lenient().ok().map(|l| l.msg))
    };
    let vehicle = match last(id::GLOBAL_POSITION_INT) {
        Some(MavMessage::GLOBAL_POSITION_INT(g)) if (g.lat, g.lon) != (0, 0) => {
            let heading_deg = if g.hdg == u16::MAX {
                v.attitude.map(|a| a.rpy_rad[2].to_degrees())
            } else {
                Some(f32::from(g.hdg) / 100.0)
            };
            Some(MapVehicle {
                at: (g.lat, g.lon),
                heading_deg,
            })
        }
        _ => None,
    };
    let home = match last(id::HOME_POSITION) {
        Some(MavMessage::HOME_POSITION(h)) => Some((h.latitude, h.longitude)),
        _ => None,
    };
    let target = match last(id::POSITION_TARGET_GLOBAL_INT) {
        Some(MavMessage::POSITION_TARGET_GLOBAL_INT(t)) if (t.lat_int, t.lon_int) != (0, 0) => {
            Some((t.lat_int, t.lon_int))
        }
        _ => None,
    };
    let current = match last(id::MISSION_CURRENT) {
        Some(MavMessage::MISSION_CURRENT(m)) => Some(m.seq),
        _ => None,
    };
    (vehicle, home, target, current)
}
