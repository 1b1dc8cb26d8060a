//! Mission files as QGroundControl, Mission Planner and MAVProxy write them, read and written:
//!
//! - **`QGC WPL 110`** text: a first line `QGC WPL 110`, then one item a line, tab-separated
//!   (any whitespace is read): `seq current frame command p1 p2 p3 p4 x y z autocontinue`, x and
//!   y in degrees for a global frame. A mission's line `0` is home.
//! - **`.plan`** JSON (QGroundControl): `mission.items` of `"type": "SimpleItem"` with
//!   `command`, `frame`, `params` (7, `null` for NaN: p1..p4, latitude, longitude, altitude),
//!   `autoContinue`, `doJumpId`; `mission.plannedHomePosition` `[lat, lon, alt]` is the
//!   mission's item 0. `geoFence` (`polygons`, `circles`) and `rallyPoints` (`points`) are the
//!   fence and rally lists, as MAV_CMD_NAV_FENCE_* and MAV_CMD_NAV_RALLY_POINT items.
//!
//! Which format is read is decided by the content, which is written by the file's extension
//! (`.plan`, else QGC WPL).

use serde_json::{Value, json};
use vtol_link::dialect::{MavCmd, MavFrame};

use super::{Item, Kind, Located, Origin};

/// The first line of a QGC WPL file.
pub const WPL_HEADER: &str = "QGC WPL 110";

const NAV_WAYPOINT: u16 = MavCmd::MAV_CMD_NAV_WAYPOINT as u16;
const FENCE_POLY_IN: u16 = MavCmd::MAV_CMD_NAV_FENCE_POLYGON_VERTEX_INCLUSION as u16;
const FENCE_POLY_OUT: u16 = MavCmd::MAV_CMD_NAV_FENCE_POLYGON_VERTEX_EXCLUSION as u16;
const FENCE_CIRCLE_IN: u16 = MavCmd::MAV_CMD_NAV_FENCE_CIRCLE_INCLUSION as u16;
const FENCE_CIRCLE_OUT: u16 = MavCmd::MAV_CMD_NAV_FENCE_CIRCLE_EXCLUSION as u16;
const RALLY_POINT: u16 = MavCmd::MAV_CMD_NAV_RALLY_POINT as u16;
const GLOBAL: u8 = MavFrame::MAV_FRAME_GLOBAL as u8;
const RELATIVE: u8 = MavFrame::MAV_FRAME_GLOBAL_RELATIVE_ALT as u8;
const TERRAIN: u8 = MavFrame::MAV_FRAME_GLOBAL_TERRAIN_ALT as u8;

/// A file format.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Format {
    /// `QGC WPL 110` text.
    Wpl,
    /// QGroundControl `.plan` JSON.
    Plan,
}

impl Format {
    /// The format a file of this name is written in: `.plan`, else QGC WPL.
    #[must_use]
    pub fn for_path(path: &std::path::Path) -> Self {
        match path.extension().and_then(|e| e.to_str()) {
            Some(e) if e.eq_ignore_ascii_case("plan") => Format::Plan,
            _ => Format::Wpl,
        }
    }
}

/// Reads the `kind` list from a file's text, the format by its content.
///
/// # Errors
/// One line naming what is wrong and where (line, or `.plan` entry).
pub fn read(text: &str, kind: Kind) -> Result<Vec<Located>, String> {
    let start = text.trim_start_matches('\u{feff}').trim_start();
    if start.starts_with('{') {
        read_plan(start, kind)
    } else if start.starts_with("QGC WPL") {
        read_wpl(text)
    } else {
        Err(format!(
            "not a mission file: neither '{WPL_HEADER}' text nor a QGroundControl .plan"
        ))
    }
}

/// Writes a list in `format`.
#[must_use]
pub fn write(items: &[Item], kind: Kind, format: Format) -> String {
    match format {
        Format::Wpl => write_wpl(items),
        Format::Plan => write_plan(items, kind),
    }
}

fn read_wpl(text: &str) -> Result<Vec<Located>, String> {
    let mut lines = text.lines().enumerate();
    let header = lines
        .next()
        .map(|(_, l)| l.trim_start_matches('\u{feff}').trim());
    if header != Some(WPL_HEADER) {
        return Err(format!(
            "line 1: '{}' is not the '{WPL_HEADER}' header",
            header.unwrap_or("")
        ));
    }
    let mut out = Vec::new();
    for (i, line) in lines {
        let n = i + 1;
        if line.trim().is_empty() {
            continue;
        }
        let f: Vec<&str> = line.split_whitespace().collect();
        if f.len() != 12 {
            return Err(format!(
                "line {n}: {} fields, not the 12 of seq current frame command p1 p2 p3 p4 x y z autocontinue",
                f.len()
            ));
        }
        let int = |k: usize, what: &str| -> Result<u32, String> {
            f[k].parse::<u32>()
                .map_err(|_| format!("line {n}: {what} '{}' is not a whole number", f[k]))
        };
        let num = |k: usize, what: &str| -> Result<f64, String> {
            f[k].parse::<f64>()
                .map_err(|_| format!("line {n}: {what} '{}' is not a number", f[k]))
        };
        let seq = int(0, "seq")?;
        if usize::try_from(seq).ok() != Some(out.len()) {
            return Err(format!("line {n}: seq {seq}, expected {}", out.len()));
        }
        let frame = u8::try_from(int(2, "frame")?)
            .map_err(|_| format!("line {n}: frame {} is out of range", f[2]))?;
        let command = u16::try_from(int(3, "command")?)
            .map_err(|_| format!("line {n}: command {} is out of range", f[3]))?;
        let mut params = [0f32; 4];
        for (k, p) in params.iter_mut().enumerate() {
            #[allow(clippy::cast_possible_truncation)]
            {
                *p = num(4 + k, &format!("p{}", k + 1))? as f32;
            }
        }
        #[allow(clippy::cast_possible_truncation)]
        let z = num(10, "z")? as f32;
        out.push(Located {
            item: Item {
                frame,
                command,
                current: int(1, "current")? != 0,
                autocontinue: int(11, "autocontinue")? != 0,
                params,
                x: num(8, "x")?,
                y: num(9, "y")?,
                z,
            },
            origin: Origin::Line(n),
        });
    }
    Ok(out)
}

fn write_wpl(items: &[Item]) -> String {
    let mut s = format!("{WPL_HEADER}\n");
    for (seq, i) in items.iter().enumerate() {
        let [p1, p2, p3, p4] = i.params;
        s.push_str(&format!(
            "{seq}\t{}\t{}\t{}\t{p1}\t{p2}\t{p3}\t{p4}\t{:.8}\t{:.8}\t{}\t{}\n",
            u8::from(i.current),
            i.frame,
            i.command,
            i.x,
            i.y,
            i.z,
            u8::from(i.autocontinue)
        ));
    }
    s
}

/// A JSON number, or `null` for NaN.
fn number(v: &Value) -> Option<f64> {
    match v {
        Value::Null => Some(f64::NAN),
        v => v.as_f64(),
    }
}

fn read_plan(text: &str, kind: Kind) -> Result<Vec<Located>, String> {
    let v: Value = serde_json::from_str(text).map_err(|e| format!("not valid .plan JSON: {e}"))?;
    if v.get("fileType").and_then(Value::as_str) != Some("Plan") {
        return Err("not a .plan: \"fileType\" is not \"Plan\"".into());
    }
    match kind {
        Kind::Mission => plan_mission(&v),
        Kind::Fence => plan_fence(&v),
        Kind::Rally => plan_rally(&v),
    }
}

fn point(v: &Value, len: usize, at: &str) -> Result<Vec<f64>, String> {
    let a = v
        .as_array()
        .filter(|a| a.len() >= len)
        .ok_or_else(|| format!("{at}: not a list of {len} numbers"))?;
    a.iter()
        .take(len)
        .map(|x| number(x).ok_or_else(|| format!("{at}: '{x}' is not a number")))
        .collect()
}

fn plan_mission(v: &Value) -> Result<Vec<Located>, String> {
    let mission = v.get("mission").ok_or("the .plan has no \"mission\"")?;
    let home = match mission.get("plannedHomePosition") {
        Some(h) if !h.is_null() => point(h, 3, "mission.plannedHomePosition")?,
        _ => vec![0.0, 0.0, 0.0],
    };
    #[allow(clippy::cast_possible_truncation)]
    let mut out = vec![Located {
        item: Item {
            frame: GLOBAL,
            command: NAV_WAYPOINT,
            current: false,
            autocontinue: true,
            params: [0.0; 4],
            x: home[0],
            y: home[1],
            z: home[2] as f32,
        },
        origin: Origin::PlanHome,
    }];
    let items = mission
        .get("items")
        .and_then(Value::as_array)
        .ok_or("mission.items: not a list")?;
    for (i, it) in items.iter().enumerate() {
        let at = format!("mission.items[{i}]");
        let ty = it.get("type").and_then(Value::as_str).unwrap_or("");
        if ty != "SimpleItem" {
            return Err(format!(
                "{at}: a \"{ty}\" item (only SimpleItem is read; re-save the survey or pattern as waypoints)"
            ));
        }
        let whole = |key: &str| -> Result<u64, String> {
            it.get(key)
                .and_then(Value::as_u64)
                .ok_or_else(|| format!("{at}: \"{key}\" is not a whole number"))
        };
        let command =
            u16::try_from(whole("command")?).map_err(|_| format!("{at}: command out of range"))?;
        let frame =
            u8::try_from(whole("frame")?).map_err(|_| format!("{at}: frame out of range"))?;
        let p = point(
            it.get("params").unwrap_or(&Value::Null),
            7,
            &format!("{at}.params"),
        )?;
        #[allow(clippy::cast_possible_truncation)]
        out.push(Located {
            item: Item {
                frame,
                command,
                current: false,
                autocontinue: it
                    .get("autoContinue")
                    .and_then(Value::as_bool)
                    .unwrap_or(true),
                params: [p[0] as f32, p[1] as f32, p[2] as f32, p[3] as f32],
                x: p[4],
                y: p[5],
                z: p[6] as f32,
            },
            origin: Origin::PlanItem(i),
        });
    }
    Ok(out)
}

fn fence_item(command: u16, p1: f32, lat: f64, lon: f64, origin: Origin) -> Located {
    Located {
        item: Item {
            frame: GLOBAL,
            command,
            current: false,
            autocontinue: true,
            params: [p1, 0.0, 0.0, 0.0],
            x: lat,
            y: lon,
            z: 0.0,
        },
        origin,
    }
}

fn plan_fence(v: &Value) -> Result<Vec<Located>, String> {
    let mut out = Vec::new();
    let Some(fence) = v.get("geoFence") else {
        return Ok(out);
    };
    let list = |key: &str| {
        fence
            .get(key)
            .and_then(Value::as_array)
            .cloned()
            .unwrap_or_default()
    };
    for (i, poly) in list("polygons").iter().enumerate() {
        let at = format!("geoFence.polygons[{i}]");
        let inclusion = poly
            .get("inclusion")
            .and_then(Value::as_bool)
            .unwrap_or(true);
        let vertices = poly
            .get("polygon")
            .and_then(Value::as_array)
            .ok_or_else(|| format!("{at}.polygon: not a list"))?;
        if vertices.len() < 3 {
            return Err(format!(
                "{at}: {} vertices, a polygon needs 3",
                vertices.len()
            ));
        }
        let cmd = if inclusion {
            FENCE_POLY_IN
        } else {
            FENCE_POLY_OUT
        };
        #[allow(clippy::cast_precision_loss)]
        let n = vertices.len() as f32;
        for vertex in vertices {
            let p = point(vertex, 2, &format!("{at}.polygon"))?;
            out.push(fence_item(
                cmd,
                n,
                p[0],
                p[1],
                Origin::PlanEntry("geoFence.polygons", i),
            ));
        }
    }
    for (i, c) in list("circles").iter().enumerate() {
        let at = format!("geoFence.circles[{i}]");
        let inclusion = c.get("inclusion").and_then(Value::as_bool).unwrap_or(true);
        let circle = c
            .get("circle")
            .ok_or_else(|| format!("{at}: no \"circle\""))?;
        let centre = point(
            circle.get("center").unwrap_or(&Value::Null),
            2,
            &format!("{at}.circle.center"),
        )?;
        let radius = circle
            .get("radius")
            .and_then(Value::as_f64)
            .ok_or_else(|| format!("{at}.circle.radius: not a number"))?;
        let cmd = if inclusion {
            FENCE_CIRCLE_IN
        } else {
            FENCE_CIRCLE_OUT
        };
        #[allow(clippy::cast_possible_truncation)]
        out.push(fence_item(
            cmd,
            radius as f32,
            centre[0],
            centre[1],
            Origin::PlanEntry("geoFence.circles", i),
        ));
    }
    Ok(out)
}

fn plan_rally(v: &Value) -> Result<Vec<Located>, String> {
    let points = v
        .get("rallyPoints")
        .and_then(|r| r.get("points"))
        .and_then(Value::as_array)
        .cloned()
        .unwrap_or_default();
    points
        .iter()
        .enumerate()
        .map(|(i, p)| {
            let p = point(p, 3, &format!("rallyPoints.points[{i}]"))?;
            #[allow(clippy::cast_possible_truncation)]
            Ok(Located {
                item: Item {
                    frame: RELATIVE,
                    command: RALLY_POINT,
                    current: false,
                    autocontinue: true,
                    params: [0.0; 4],
                    x: p[0],
                    y: p[1],
                    z: p[2] as f32,
                },
                origin: Origin::PlanEntry("rallyPoints.points", i),
            })
        })
        .collect()
}

/// A number for JSON: `null` for NaN (what QGroundControl writes).
fn js(v: f64) -> Value {
    if v.is_finite() { json!(v) } else { Value::Null }
}

fn js32(v: f32) -> Value {
    // The shortest decimal of the float32, not its float64 widening's digits.
    if v.is_finite() {
        v.to_string()
            .parse::<f64>()
            .map_or(Value::Null, |f| json!(f))
    } else {
        Value::Null
    }
}

fn write_plan(items: &[Item], kind: Kind) -> String {
    let mut mission_items = Vec::new();
    let mut home = Value::Null;
    let mut polygons = Vec::new();
    let mut circles = Vec::new();
    let mut rally = Vec::new();
    match kind {
        Kind::Mission => {
            if let Some(h) = items.first() {
                home = json!([js(h.x), js(h.y), js32(h.z)]);
            }
            for (seq, i) in items.iter().enumerate().skip(1) {
                let [p1, p2, p3, p4] = i.params;
                let mode = match i.frame {
                    RELATIVE => 1,
                    GLOBAL => 2,
                    TERRAIN => 3,
                    _ => 0,
                };
                mission_items.push(json!({
                    "AMSLAltAboveTerrain": null,
                    "Altitude": js32(i.z),
                    "AltitudeMode": mode,
                    "autoContinue": i.autocontinue,
                    "command": i.command,
                    "doJumpId": seq,
                    "frame": i.frame,
                    "params": [js32(p1), js32(p2), js32(p3), js32(p4), js(i.x), js(i.y), js32(i.z)],
                    "type": "SimpleItem",
                }));
            }
        }
        Kind::Fence => {
            let mut k = 0;
            while k < items.len() {
                let i = &items[k];
                match i.command {
                    FENCE_POLY_IN | FENCE_POLY_OUT => {
                        #[allow(clippy::cast_possible_truncation, clippy::cast_sign_loss)]
                        let n = (i.params[0].max(1.0) as usize).min(items.len() - k);
                        let vertices: Vec<Value> = items[k..k + n]
                            .iter()
                            .map(|v| json!([js(v.x), js(v.y)]))
                            .collect();
                        polygons.push(json!({
                            "inclusion": i.command == FENCE_POLY_IN,
                            "polygon": vertices,
                            "version": 1,
                        }));
                        k += n;
                    }
                    _ => {
                        circles.push(json!({
                            "circle": {"center": [js(i.x), js(i.y)], "radius": js32(i.params[0])},
                            "inclusion": i.command == FENCE_CIRCLE_IN,
                            "version": 1,
                        }));
                        k += 1;
                    }
                }
            }
        }
        Kind::Rally => {
            rally = items
                .iter()
                .map(|i| json!([js(i.x), js(i.y), js32(i.z)]))
                .collect();
        }
    }
    let plan = json!({
        "fileType": "Plan",
        "geoFence": {"circles": circles, "polygons": polygons, "version": 2},
        "groundStation": "vtol-gcs",
        "mission": {
            "cruiseSpeed": 15,
            "firmwareType": 3,
            "hoverSpeed": 5,
            "items": mission_items,
            "plannedHomePosition": home,
            "vehicleType": 20,
            "version": 2,
        },
        "rallyPoints": {"points": rally, "version": 2},
        "version": 1,
    });
    let mut s = serde_json::to_string_pretty(&plan).unwrap_or_default();
    s.push('\n');
    s
}

#[cfg(test)]
#[path = "file_tests.rs"]
mod tests;
