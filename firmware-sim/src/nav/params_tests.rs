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
