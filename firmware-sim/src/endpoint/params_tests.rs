//! State-machine tests of the parameter protocol.

use super::test_support::*;

/// What the twin answers a PARAM_SET of `name` to `value` from the ground station.
fn set(ep: &mut Endpoint, name: &str, value: f32) -> Vec<apm::MavMessage> {
    decode(&ep.handle(GCS, &v2(&param_set(name, value))))
}

/// The one PARAM_VALUE among `msgs`.
fn the_echo(msgs: &[apm::MavMessage]) -> apm::PARAM_VALUE_DATA {
    let [echo] = &param_values(msgs)[..] else {
        panic!("one echo: {msgs:?}")
    };
    echo.clone()
}

#[test]
fn param_list_is_complete_and_paced() {
    let mut ep = endpoint();
    let first = ep.handle(
        GCS,
        &v2(&apm::MavMessage::PARAM_REQUEST_LIST(
            apm::PARAM_REQUEST_LIST_DATA {
                target_system: 1,
                target_component: 0,
            },
        )),
    );
    assert!(
        param_values(&decode(&first)).is_empty(),
        "values are paced from tick"
    );
    let out = run_until(&mut ep, 200_000);
    let values = param_values(&decode(&out));
    assert_eq!(values.len(), TABLE.len());
    for (i, v) in values.iter().enumerate() {
        assert_eq!(usize::from(v.param_index), i);
        assert_eq!(usize::from(v.param_count), TABLE.len());
        assert_eq!(v.param_id.to_str().unwrap(), TABLE[i].name);
    }
}

#[test]
fn param_set_echoes_stored_value_type_and_index() {
    let mut ep = endpoint();
    let msgs = set(&mut ep, "LAT_SAT_A", 1.5);
    let echo = the_echo(&msgs);
    assert_eq!(echo.param_id.to_str().unwrap(), "LAT_SAT_A");
    assert_eq!(echo.param_value, 1.5);
    assert_eq!(echo.param_type, apm::MavParamType::MAV_PARAM_TYPE_REAL32);
    assert_eq!(
        usize::from(echo.param_index),
        Params::index_of("LAT_SAT_A").unwrap()
    );
    assert_eq!(usize::from(echo.param_count), TABLE.len());
    assert_eq!(
        ep.vehicle().gains().lateral.a,
        f64::from(1.5f32),
        "applied to the controller"
    );

    // An integer parameter sent as REAL32 (pymavlink's default) is C-cast and echoed as INT16.
    let msgs = set(&mut ep, "SR0_EXTRA1", 4.6);
    let echo = the_echo(&msgs);
    assert_eq!(
        (echo.param_value, echo.param_type),
        (5.0, apm::MavParamType::MAV_PARAM_TYPE_INT16)
    );
}

#[test]
fn refused_param_write_keeps_value_and_says_why() {
    let mut ep = endpoint();
    // a = 0.9 breaks a > b + c + d (= 1.0).
    let msgs = set(&mut ep, "LAT_SAT_A", 0.9);
    let echo = the_echo(&msgs);
    assert_eq!(echo.param_value, 1.2, "unchanged value echoed");
    let [err] = &param_errors(&msgs)[..] else {
        panic!("{msgs:?}")
    };
    assert_eq!(
        err.error,
        apm::MavParamError::MAV_PARAM_ERROR_VALUE_OUT_OF_RANGE
    );
    assert_eq!(
        (err.target_system, err.target_component),
        (GCS_SYSID, GCS_COMPID)
    );
    let t = texts(&msgs);
    assert!(
        t.iter().any(|s| s.starts_with("Param write denied")),
        "{t:?}"
    );
    assert_eq!(ep.params().value("LAT_SAT_A"), 1.2);

    for (name, value, code) in [
        (
            "ALT_KP",
            f32::NAN,
            apm::MavParamError::MAV_PARAM_ERROR_VALUE_OUT_OF_RANGE,
        ),
        (
            "SERVO1_FUNCTION",
            33.0,
            apm::MavParamError::MAV_PARAM_ERROR_READ_ONLY,
        ),
    ] {
        let msgs = set(&mut ep, name, value);
        assert_eq!(param_errors(&msgs)[0].error, code, "{name}");
        assert_eq!(param_values(&msgs).len(), 1, "{name}: current value echoed");
    }
}

#[test]
fn unknown_param_gets_param_error_and_no_value() {
    let mut ep = endpoint();
    let msgs = set(&mut ep, "NO_SUCH_PARAM", 1.0);
    assert!(param_values(&msgs).is_empty());
    let [err] = &param_errors(&msgs)[..] else {
        panic!("{msgs:?}")
    };
    assert_eq!(
        err.error,
        apm::MavParamError::MAV_PARAM_ERROR_DOES_NOT_EXIST
    );
    assert_eq!(err.param_index, -1);
    assert_eq!(err.param_id.to_str().unwrap(), "NO_SUCH_PARAM");

    let read = |id: &str, index: i16| {
        apm::MavMessage::PARAM_REQUEST_READ(apm::PARAM_REQUEST_READ_DATA {
            param_index: index,
            target_system: 1,
            target_component: 1,
            param_id: CharArray::from(id),
        })
    };
    let msgs = decode(&ep.handle(GCS, &v2(&read("NO_SUCH_PARAM", -1))));
    assert_eq!(
        param_errors(&msgs)[0].error,
        apm::MavParamError::MAV_PARAM_ERROR_DOES_NOT_EXIST
    );
    // By name and by index (the id is ignored then).
    let msgs = decode(&ep.handle(GCS, &v2(&read("HOVER_ALT", -1))));
    assert_eq!(param_values(&msgs)[0].param_value, 1.0);
    let msgs = decode(&ep.handle(GCS, &v2(&read("ignored", 0))));
    assert_eq!(
        param_values(&msgs)[0].param_id.to_str().unwrap(),
        TABLE[0].name
    );
}

#[test]
fn param_set_with_type_outside_the_enum_is_still_handled() {
    let mut ep = endpoint();
    // PARAM_SET payload: f32 value, tsys, tcomp, char[16] id, u8 type = 0 (not a MAV_PARAM_TYPE).
    let mut payload = Vec::new();
    payload.extend_from_slice(&2.5f32.to_le_bytes());
    payload.extend_from_slice(&[1, 1]);
    let mut id = [0u8; 16];
    id[..9].copy_from_slice(b"HOVER_ALT");
    payload.extend_from_slice(&id);
    payload.push(0);
    let frame = from_gcs(0, 23, &payload);
    let msgs = decode(&ep.handle(GCS, &frame));
    assert_eq!(param_values(&msgs)[0].param_value, 2.5);
}
