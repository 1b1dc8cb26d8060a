//! Tests of the parameter table.

use super::*;

#[test]
fn table_invariants() {
    let mut names = std::collections::HashSet::new();
    for d in TABLE {
        assert!(d.name.len() <= MAX_NAME_LEN, "{} too long", d.name);
        assert_eq!(d.name, d.name.to_ascii_uppercase());
        assert!(names.insert(d.name), "{} twice", d.name);
        assert!(
            d.min <= d.default && d.default <= d.max,
            "{} default out of range",
            d.name
        );
        if d.ty.is_integer() {
            assert_eq!(d.default.fract(), 0.0, "{}", d.name);
        }
    }
    let p = Params::new();
    assert_eq!(p.count(), TABLE.len());
    assert_eq!(
        p.gains(),
        Gains::default(),
        "defaults must match PHYSICS.md §0"
    );
    p.gains().validate().unwrap();
}

#[test]
fn refused_writes_leave_the_value() {
    let mut p = Params::new();
    assert!(matches!(
        p.set("LAT_SAT_A", f64::NAN),
        Err(ParamError::NotFinite { .. })
    ));
    assert!(matches!(
        p.set("ALT_KP", 1e6),
        Err(ParamError::OutOfRange { .. })
    ));
    assert!(matches!(
        p.set("SERVO1_FUNCTION", 33.0),
        Err(ParamError::ReadOnly(_))
    ));
    assert!(matches!(p.set("NOPE", 1.0), Err(ParamError::Unknown(_))));
    // a = 0.9 breaks a > b + c + d = 1.0.
    let e = p.set("LAT_SAT_A", 0.9).unwrap_err();
    assert!(e.to_string().contains("a > b + c + d"), "{e}");
    assert_eq!(e.mav_error(), 2);
    // c = 0.1 breaks c > d = 0.18.
    assert!(matches!(
        p.set("LON_SAT_C", 0.1),
        Err(ParamError::Gains { .. })
    ));
    assert_eq!(p, Params::new());
    let ok = p.set("LAT_SAT_A", 1.5).unwrap();
    assert_eq!((ok.old, ok.new), (1.2, 1.5));
    // C cast: an integer parameter rounds.
    assert_eq!(p.set("SR0_EXTRA1", 4.6).unwrap().new, 5.0);
}

#[test]
fn a_set_is_validated_as_a_whole() {
    let mut p = Params::new();
    let w = |n: &str, v: f64| (n.to_owned(), v);
    // d = 0.3 alone breaks c > d; with c = 0.35, b = 0.7 and a = 1.5 the set holds.
    p.set_all(&[
        w("LAT_SAT_D", 0.3),
        w("LAT_SAT_C", 0.35),
        w("LAT_SAT_B", 0.7),
        w("LAT_SAT_A", 1.5),
    ])
    .unwrap();
    assert_eq!(p.gains().lateral.d, 0.3);
    let before = p.clone();
    let e = p.set_all(&[w("ALT_KP", 1e6)]).unwrap_err();
    assert_eq!(e.to_string(), "ALT_KP: 1000000 outside [0, 100]");
    assert!(p.set_all(&[w("LAT_SAT_D", 0.5)]).is_err());
    assert!(p.set_all(&[w("SERVO1_FUNCTION", 1.0)]).is_err());
    assert_eq!(p, before, "a refused set changes nothing");
}

/// Values are saved at full precision: a float32 from PARAM_SET as its shortest decimal, a
/// finer value given in a file exactly (six decimals would round both).
#[test]
fn parm_file_keeps_full_precision() {
    let mut p = Params::new();
    p.set("ALT_KP", f64::from(1.2345678_f32)).unwrap();
    p.set("ALT_KD", 0.123_456_789_012).unwrap();
    let text = p.to_parm_string();
    assert!(text.contains("ALT_KP           1.2345678\n"), "{text}");
    assert!(text.contains("ALT_KD           0.123456789012\n"), "{text}");
    let back = Params::from_parm_str(&text, Path::new("x.parm")).unwrap();
    // The same float32 on the wire.
    #[allow(clippy::cast_possible_truncation)]
    let kp = back.value("ALT_KP") as f32;
    assert_eq!(kp, 1.2345678_f32);
    assert_eq!(back.value("ALT_KD"), 0.123_456_789_012);
}

#[test]
fn parm_round_trip() {
    let mut p = Params::new();
    p.set("LAT_SAT_A", 1.75).unwrap();
    p.set("SYSID_MYGCS", 250.0).unwrap();
    p.set("SIM_PUSH_ROLL", 0.1).unwrap();
    let text = p.to_parm_string();
    assert!(text.contains("LAT_SAT_A        1.75\n"), "{text}");
    assert!(text.contains("SYSID_MYGCS      250\n"), "{text}");
    assert!(
        !text.contains("SIM_PUSH_ROLL"),
        "volatile params are not saved"
    );
    let back = Params::from_parm_str(&text, Path::new("x.parm")).unwrap();
    let mut expected = p.clone();
    expected.set("SIM_PUSH_ROLL", 0.0).unwrap();
    assert_eq!(back, expected);
    // MAVProxy / Mission Planner spellings.
    let mp = Params::from_parm_str("ALT_KP,6 # comment\n\nYAW_KD\t0x3\n", Path::new("m")).unwrap();
    assert_eq!((mp.value("ALT_KP"), mp.value("YAW_KD")), (6.0, 3.0));
}

#[test]
fn corrupt_files_are_errors() {
    let path = Path::new("bad.parm");
    for (text, needle) in [
        ("ALT_KP\n", "expected NAME VALUE"),
        ("ALT_KP 1 2\n", "expected NAME VALUE"),
        ("ALT_KP abc\n", "bad value"),
        ("NOT_A_PARAM 1\n", "unknown parameter"),
        ("ALT_KP 1000\n", "outside"),
        ("ALT_KP 1\nALT_KP 2\n", "already set"),
    ] {
        let e = Params::from_parm_str(text, path).unwrap_err();
        assert!(e.to_string().contains(needle), "{text:?}: {e}");
        assert!(e.to_string().starts_with("bad.parm:"), "{e}");
    }
    let e = Params::from_parm_str("LAT_SAT_D 0.5\n", path).unwrap_err();
    assert!(matches!(e, ParamFileError::Gains { .. }), "{e}");
}

#[test]
fn save_is_atomic_and_loads_back() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("twin.parm");
    let mut p = Params::new();
    p.set("HOVER_ALT", 2.5).unwrap();
    p.save(&path).unwrap();
    assert_eq!(Params::load(&path).unwrap(), p);
    let leftovers: Vec<_> = std::fs::read_dir(dir.path()).unwrap().collect();
    assert_eq!(leftovers.len(), 1, "no temporary file left behind");
    assert!(matches!(
        Params::load(&dir.path().join("missing.parm")),
        Err(ParamFileError::File(TextFileError::Io { .. }))
    ));
}

#[test]
fn forward_flight_cross_checks_refuse_a_write_and_say_why() {
    let mut p = Params::new();
    // Below the stall speed (5.5 m/s).
    let e = p.set("ARSPD_FBW_MIN", 5.0).unwrap_err();
    assert!(e.to_string().contains("stall speed"), "{e}");
    assert_eq!(p.value("ARSPD_FBW_MIN"), 10.0);
    // The trim airspeed above ARSPD_FBW_MAX.
    let e = p.set("TRIM_ARSPD_CM", 2000.0).unwrap_err();
    assert!(e.to_string().contains("TRIM_ARSPD_CM"), "{e}");
    assert_eq!(p.value("TRIM_ARSPD_CM"), 1200.0);
    // A consistent change is taken and reaches the gains.
    p.set("ARSPD_FBW_MAX", 20.0).unwrap();
    p.set("TRIM_ARSPD_CM", 1500.0).unwrap();
    assert!((p.gains().forward.airspeed_trim_m_s - 15.0).abs() < 1e-9);
}

/// The parameters the twin shares with ArduPlane 4.7 have ArduPlane's `MAV_PARAM_TYPE` (from
/// its AP_GROUPINFO/GSCALAR definitions: AP_Int8/16/32, AP_Float) and, where the twin does not
/// keep its airframe's own value, ArduPlane's default.
#[test]
fn shared_parameters_have_ardupilots_types_and_defaults() {
    use ParamType::{Int8 as I8, Int16 as I16, Int32 as I32, Real32 as F32};
    #[rustfmt::skip]
    let arduplane: &[(&str, ParamType, Option<f64>)] = &[
        ("FORMAT_VERSION", I16, None), ("SYSID_THISMAV", I16, Some(1.0)),
        ("SYSID_MYGCS", I16, Some(255.0)), ("FS_GCS_ENABL", I8, Some(0.0)),
        ("SR0_RAW_SENS", I16, None), ("SR0_EXT_STAT", I16, None), ("SR0_RC_CHAN", I16, None),
        ("SR0_POSITION", I16, None), ("SR0_EXTRA1", I16, None), ("SR0_EXTRA2", I16, None),
        ("SR0_EXTRA3", I16, None), ("SERVO1_FUNCTION", I16, None), ("SERVO5_FUNCTION", I16, None),
        ("SIM_WIND_SPD", F32, Some(0.0)), ("SIM_WIND_DIR", F32, None),
        ("SIM_WIND_TURB", F32, Some(0.0)), ("SIM_BATT_VOLTAGE", F32, Some(12.6)),
        ("WP_RADIUS", I16, Some(90.0)), ("WP_LOITER_RAD", I16, Some(60.0)),
        ("RTL_RADIUS", I16, Some(0.0)), ("RTL_ALTITUDE", F32, Some(100.0)), ("Q_RTL_MODE", I8, Some(0.0)),
        ("Q_GUIDED_MODE", I8, Some(0.0)), ("Q_TRANS_DECEL", F32, Some(6.0)),
        ("Q_WP_RADIUS", F32, Some(200.0)), ("Q_TAILSIT_ENABLE", I8, Some(1.0)), ("Q_ENABLE", I8, Some(1.0)),
        ("BATT_CAPACITY", I32, None), ("BATT_LOW_VOLT", F32, Some(10.5)),
        ("BATT_CRT_VOLT", F32, Some(0.0)), ("BATT_LOW_MAH", F32, Some(0.0)),
        ("BATT_CRT_MAH", F32, Some(0.0)), ("BATT_LOW_TIMER", I8, Some(10.0)),
        ("BATT_FS_LOW_ACT", I8, Some(0.0)), ("BATT_FS_CRT_ACT", I8, Some(0.0)),
        ("ARMING_CHECK", I32, Some(1.0)), ("TECS_TIME_CONST", F32, None),
        ("TECS_CLMB_MAX", F32, None), ("TECS_SINK_MAX", F32, None),
        ("Q_TAILSIT_RAT_FW", F32, Some(50.0)), ("Q_TAILSIT_RAT_VT", F32, Some(50.0)),
        ("Q_TAILSIT_ANGLE", I8, Some(45.0)), ("Q_TAILSIT_ANG_VT", I8, None),
        ("Q_TRANSITION_MS", I16, None), ("NAVL1_PERIOD", F32, None),
        ("NAVL1_DAMPING", F32, Some(0.75)), ("Q_P_POSXY_P", F32, None), ("Q_P_VELXY_P", F32, None),
        ("Q_P_VELXY_I", F32, None), ("Q_P_VELXY_IMAX", F32, None), ("Q_WP_SPEED", F32, None),
        ("Q_ANGLE_MAX", I16, Some(3000.0)),
    ];
    let p = Params::new();
    for (name, ty, default) in arduplane {
        let i = Params::index_of(name).unwrap_or_else(|| panic!("{name} missing"));
        let (d, v) = p.at(i).unwrap();
        assert_eq!(d.ty, *ty, "{name}");
        if let Some(default) = default {
            assert_eq!(v, *default, "{name}");
        }
    }
    // An integer parameter stores the C cast of what was sent: 0.4 reads back 0.
    let mut p = Params::new();
    assert_eq!(p.set("WP_RADIUS", 0.4).unwrap().new, 0.0);
    assert!(matches!(
        p.set("Q_TAILSIT_ENABLE", 0.0),
        Err(ParamError::ReadOnly(_))
    ));
}
