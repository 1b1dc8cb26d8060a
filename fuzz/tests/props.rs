//! Property tests over the fuzz targets' inputs, in the normal suite: any bytes into every
//! target (never a panic, errors one line, round trips hold: the targets check all three), and
//! well-formed inputs generated for the text formats, which must parse and come back unchanged.

use std::path::Path;

use proptest::prelude::*;
use vtol_fuzz::TARGETS;
use vtol_fuzz::runner::run_one;

fn cases(n: u32) -> ProptestConfig {
    // Seeded: the same cases on every run and machine (the fuzz runner explores further).
    ProptestConfig {
        cases: n,
        failure_persistence: None,
        rng_seed: proptest::test_runner::RngSeed::Fixed(0x5eed),
        ..ProptestConfig::default()
    }
}

proptest! {
    #![proptest_config(cases(48))]

    /// Any bytes, into every target.
    #[test]
    fn any_bytes_into_every_target(data in proptest::collection::vec(any::<u8>(), 0..700)) {
        for t in TARGETS {
            if let Err(message) = run_one(t, &data) {
                return Err(TestCaseError::fail(format!("{}: {message}", t.name)));
            }
        }
    }

    /// Any text (the text formats see letters, digits and separators more than raw bytes).
    #[test]
    fn any_text_into_every_target(text in "[ -~\t\n]{0,300}") {
        for t in TARGETS {
            if let Err(message) = run_one(t, text.as_bytes()) {
                return Err(TestCaseError::fail(format!("{}: {message}", t.name)));
            }
        }
    }
}

proptest! {
    #![proptest_config(cases(128))]

    /// A well-formed URL parses and prints as itself.
    #[test]
    fn urls_parse_and_round_trip(
        scheme in prop::sample::select(vec!["tcpin", "tcp", "udpin", "udpout"]),
        host in prop::sample::select(vec!["127.0.0.1", "0.0.0.0", "localhost", "10.1.2.3"]),
        port in any::<u16>(),
    ) {
        let text = format!("{scheme}:{host}:{port}");
        let url: vtol_link::LinkUrl = text.parse().map_err(|e| TestCaseError::fail(format!("{text}: {e}")))?;
        let back: vtol_link::LinkUrl = url.to_string().parse().unwrap();
        prop_assert_eq!(back, url);
    }

    /// A parameter table written in any of the three formats reads back bit for bit.
    #[test]
    fn parameter_files_round_trip(
        table in proptest::collection::btree_map("[A-Z][A-Z0-9_]{0,15}", any::<f32>().prop_filter("finite", |v| v.is_finite()), 1..20),
    ) {
        use vtol_gcs::params::file::{Format, ParamFile, render};
        use vtol_gcs::params::{Param, ParamSet};
        let set: ParamSet = table
            .iter()
            .map(|(n, v)| (n.clone(), Param { value: *v, ty: vtol_link::dialect::MavParamType::MAV_PARAM_TYPE_REAL32 }))
            .collect();
        for format in [Format::Mavproxy, Format::Missionplanner, Format::Qgc] {
            let text = render(&set, format, (vtol_link::SystemId(1), vtol_link::ComponentId(1)));
            let back = ParamFile::parse(&text, Path::new("p.param")).map_err(|e| TestCaseError::fail(format!("{format:?}: {e}")))?;
            prop_assert_eq!(back.params.len(), set.len());
            for (name, p) in &set {
                prop_assert_eq!(back.params[name].value.to_bits(), p.value.to_bits());
            }
        }
    }

    /// A STATUSTEXT sent in 50-character chunks is joined back whole.
    #[test]
    fn statustext_chunks_join(text in "[ -~]{1,400}", id in 1u16..) {
        use vtol_link::dialect::STATUSTEXT_DATA;
        let mut joiner = vtol_link::statustext::TextAssembler::default();
        let bytes = text.as_bytes();
        let mut chunks: Vec<&[u8]> = bytes.chunks(50).collect();
        if bytes.len() % 50 == 0 {
            chunks.push(&[]); // a text of whole chunks ends with an empty one
        }
        let mut joined = None;
        for (seq, c) in chunks.iter().enumerate() {
            let mut buf = [0u8; 50];
            buf[..c.len()].copy_from_slice(c);
            let t = STATUSTEXT_DATA { id, chunk_seq: seq as u8, text: buf.into(), ..Default::default() };
            joined = joiner.push(&t);
        }
        prop_assert_eq!(joined, Some(text));
    }

    /// The daemon's config with a sane status interval and a non-zero queue length applies; a
    /// zero, negative, tiny or absurd one is one line of error, never a panic (a huge one used
    /// to panic converting to a Duration, a tiny one to make a zero-period timer).
    #[test]
    fn config_numbers(secs in any::<f64>(), queue in any::<u32>()) {
        use vtol_gcs::config::{Config, FileConfig};
        let text = format!("status_interval_s = {secs:?}\nqueue_len = {queue}\n");
        match FileConfig::parse(&text) {
            Ok(f) => {
                let mut c = Config::default();
                match f.apply(&mut c) {
                    Ok(()) => {
                        prop_assert!(queue > 0 && secs > 0.0 && !c.status_interval.is_zero());
                        // Durations count whole nanoseconds.
                        prop_assert!((c.status_interval.as_secs_f64() - secs).abs() <= (secs * 1e-6).max(1e-9));
                    }
                    Err(e) => {
                        let sane = (1e-6..1e9).contains(&secs);
                        prop_assert!(queue == 0 || !sane, "{}", e);
                        prop_assert!(!e.to_string().contains('\n'), "{}", e);
                    }
                }
            }
            Err(e) => prop_assert!(!e.contains('\n'), "{}", e),
        }
    }

    /// `simulate --push` values round-trip their numbers.
    #[test]
    fn push_values(axis in prop::sample::select(vec!["roll", "pitch", "yaw"]), torque in -10.0f64..10.0, at in 0.0f64..100.0, ms in 1u32..5000) {
        let p = firmware_sim::shell::simulate::parse_push(&format!("{axis}={torque}@{at}:{ms}")).unwrap();
        prop_assert_eq!(p.torque_nm, torque);
        prop_assert_eq!(p.at_s, at);
        prop_assert_eq!(p.duration_ms, f64::from(ms));
    }
}
