use super::*;

/// As MAVProxy's `wp save` writes it (`%.8f` parameters and positions, `%f` altitude).
const MAVPROXY: &str = "QGC WPL 110
0\t1\t0\t16\t0.00000000\t0.00000000\t0.00000000\t0.00000000\t-35.36326200\t149.16523700\t584.090000\t1
1\t0\t3\t84\t0.00000000\t0.00000000\t0.00000000\t0.00000000\t0.00000000\t0.00000000\t30.000000\t1
2\t0\t3\t16\t0.00000000\t0.00000000\t0.00000000\t0.00000000\t-35.36100000\t149.16500000\t60.000000\t1
3\t0\t3\t85\t0.00000000\t0.00000000\t0.00000000\t0.00000000\t-35.36326200\t149.16523700\t0.000000\t1
";

/// As Mission Planner writes it: CRLF line ends, shortest numbers.
const MISSION_PLANNER: &str = "QGC WPL 110\r\n0\t1\t0\t16\t0\t0\t0\t0\t-35.363262\t149.165237\t584.09\t1\r\n1\t0\t3\t22\t15\t0\t0\t0\t0\t0\t40\t1\r\n2\t0\t3\t20\t0\t0\t0\t0\t0\t0\t0\t1\r\n";

/// As QGroundControl saves a mission (v2 plan; `null` for a NaN yaw), one polygon fence, one
/// circle and two rally points.
const QGC_PLAN: &str = r#"{
    "fileType": "Plan",
    "geoFence": {
        "circles": [
            { "circle": { "center": [-35.3632, 149.1652], "radius": 300 }, "inclusion": true, "version": 1 }
        ],
        "polygons": [
            { "inclusion": false, "polygon": [[-35.36, 149.16], [-35.36, 149.17], [-35.37, 149.17]], "version": 1 }
        ],
        "version": 2
    },
    "groundStation": "QGroundControl",
    "mission": {
        "cruiseSpeed": 15,
        "firmwareType": 3,
        "globalPlanAltitudeMode": 1,
        "hoverSpeed": 5,
        "items": [
            {
                "AMSLAltAboveTerrain": null, "Altitude": 30, "AltitudeMode": 1, "autoContinue": true,
                "command": 84, "doJumpId": 1, "frame": 3,
                "params": [0, 0, 0, null, -35.3632621, 149.1652374, 30], "type": "SimpleItem"
            },
            {
                "AMSLAltAboveTerrain": null, "Altitude": 60, "AltitudeMode": 1, "autoContinue": true,
                "command": 16, "doJumpId": 2, "frame": 3,
                "params": [0, 0, 0, null, -35.361, 149.165, 60], "type": "SimpleItem"
            },
            {
                "autoContinue": true, "command": 85, "doJumpId": 3, "frame": 3,
                "params": [0, 0, 0, null, -35.3632621, 149.1652374, 0], "type": "SimpleItem"
            }
        ],
        "plannedHomePosition": [-35.3632621, 149.1652374, 584.09],
        "vehicleType": 20,
        "version": 2
    },
    "rallyPoints": { "points": [[-35.362, 149.166, 50], [-35.364, 149.164, 60]], "version": 2 },
    "version": 1
}"#;

fn items(l: &[Located]) -> Vec<Item> {
    l.iter().map(|l| l.item).collect()
}

fn same(a: &[Item], b: &[Item]) -> bool {
    a.len() == b.len() && a.iter().zip(b).all(|(x, y)| x.same_as(y))
}

#[test]
fn mavproxy_wpl_reads_with_home_as_item_0() {
    let m = read(MAVPROXY, Kind::Mission).expect("reads");
    assert_eq!(m.len(), 4);
    assert_eq!(m[0].origin, Origin::Line(2));
    let home = m[0].item;
    assert_eq!((home.frame, home.command, home.current), (0, 16, true));
    assert_eq!(home.wire_xy(), (-353_632_620, 1_491_652_370));
    assert_eq!(m[1].item.command, 84);
    assert_eq!(m[3].origin, Origin::Line(5));
}

#[test]
fn mission_planner_wpl_with_crlf_reads() {
    let m = read(MISSION_PLANNER, Kind::Mission).expect("reads");
    assert_eq!(m.len(), 3);
    assert_eq!(m[1].item.params[0], 15.0);
    assert_eq!(m[2].item.command, 20);
}

#[test]
fn wpl_round_trips_exactly() {
    let a = items(&read(MAVPROXY, Kind::Mission).expect("reads"));
    let text = write(&a, Kind::Mission, Format::Wpl);
    assert!(text.starts_with("QGC WPL 110\n0\t1\t0\t16\t"), "{text}");
    let b = items(&read(&text, Kind::Mission).expect("reads back"));
    assert_eq!(a, b);
}

#[test]
fn a_nan_parameter_survives_wpl() {
    let mut a = items(&read(MAVPROXY, Kind::Mission).expect("reads"));
    a[2].params[3] = f32::NAN;
    let b = items(&read(&write(&a, Kind::Mission, Format::Wpl), Kind::Mission).expect("reads"));
    assert!(b[2].params[3].is_nan());
    assert!(same(&a, &b));
}

#[test]
fn qgc_plan_reads_home_as_item_0() {
    let m = read(QGC_PLAN, Kind::Mission).expect("reads");
    assert_eq!(m.len(), 4);
    assert_eq!(m[0].origin, Origin::PlanHome);
    assert_eq!(m[0].item.wire_xy(), (-353_632_621, 1_491_652_374));
    assert!((m[0].item.z - 584.09).abs() < 1e-4);
    assert_eq!(m[1].origin, Origin::PlanItem(0));
    assert!(m[1].item.params[3].is_nan(), "null is NaN");
    assert_eq!((m[3].item.command, m[3].item.frame), (85, 3));
}

#[test]
fn plan_and_wpl_convert_both_ways() {
    let a = items(&read(QGC_PLAN, Kind::Mission).expect("reads"));
    let plan = write(&a, Kind::Mission, Format::Plan);
    let b = items(&read(&plan, Kind::Mission).expect("plan reads back"));
    assert!(same(&a, &b), "{a:?}\n{b:?}");
    let wpl = write(&b, Kind::Mission, Format::Wpl);
    let c = items(&read(&wpl, Kind::Mission).expect("wpl reads back"));
    assert!(same(&a, &c));
    let v: serde_json::Value = serde_json::from_str(&plan).expect("json");
    assert_eq!(
        v["mission"]["items"][0]["params"][3],
        serde_json::Value::Null
    );
    assert_eq!(v["mission"]["items"][2]["doJumpId"], 3);
}

#[test]
fn fence_and_rally_lists_round_trip_through_plan() {
    let fence = items(&read(QGC_PLAN, Kind::Fence).expect("fence"));
    assert_eq!(fence.len(), 4);
    assert!(
        fence[..3]
            .iter()
            .all(|i| i.command == 5002 && i.params[0] == 3.0)
    );
    assert_eq!((fence[3].command, fence[3].params[0]), (5003, 300.0));
    let back = items(&read(&write(&fence, Kind::Fence, Format::Plan), Kind::Fence).expect("reads"));
    assert!(same(&fence, &back));
    let rally = items(&read(QGC_PLAN, Kind::Rally).expect("rally"));
    assert_eq!(rally.len(), 2);
    assert_eq!(
        (rally[1].command, rally[1].frame, rally[1].z),
        (5100, 3, 60.0)
    );
    let back = items(&read(&write(&rally, Kind::Rally, Format::Plan), Kind::Rally).expect("reads"));
    assert!(same(&rally, &back));
}

#[test]
fn bad_files_name_the_line_or_entry() {
    let err = |t: &str| read(t, Kind::Mission).expect_err("refused");
    assert!(err("hello").contains("not a mission file"));
    assert!(err("QGC WPL 100\n").starts_with("line 1:"));
    let short = "QGC WPL 110\n0\t1\t0\t16\t0\t0\t0\t0\t1\t2\t3\t1\n1\t0\t3\t16\t0\t0\n";
    assert!(err(short).starts_with("line 3: 6 fields"), "{}", err(short));
    let word = "QGC WPL 110\n0\t1\t0\t16\tx\t0\t0\t0\t1\t2\t3\t1\n";
    assert_eq!(err(word), "line 2: p1 'x' is not a number");
    let seq =
        "QGC WPL 110\n0\t1\t0\t16\t0\t0\t0\t0\t1\t2\t3\t1\n2\t0\t3\t16\t0\t0\t0\t0\t1\t2\t3\t1\n";
    assert_eq!(err(seq), "line 3: seq 2, expected 1");
    let complex = QGC_PLAN.replacen("\"SimpleItem\"", "\"ComplexItem\"", 1);
    assert!(err(&complex).starts_with("mission.items[0]: a \"ComplexItem\""));
    let params = QGC_PLAN.replacen("[0, 0, 0, null, -35.361, 149.165, 60]", "[0, 0]", 1);
    assert!(
        err(&params).starts_with("mission.items[1].params"),
        "{}",
        err(&params)
    );
}

#[test]
fn format_follows_the_extension() {
    use std::path::Path;
    assert_eq!(Format::for_path(Path::new("a.plan")), Format::Plan);
    assert_eq!(Format::for_path(Path::new("a.PLAN")), Format::Plan);
    assert_eq!(Format::for_path(Path::new("a.waypoints")), Format::Wpl);
    assert_eq!(Format::for_path(Path::new("a.txt")), Format::Wpl);
}
