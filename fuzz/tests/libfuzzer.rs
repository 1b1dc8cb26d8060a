//! The libFuzzer build (fuzz/libfuzzer, nightly) stays in step with the targets: one binary per
//! target, each calling that target's body, and every target in the CI streams of fuzz.sh.

use vtol_fuzz::TARGETS;
use vtol_fuzz::runner;

fn read(rel: &str) -> String {
    let path = runner::fuzz_dir().join(rel);
    std::fs::read_to_string(&path).unwrap_or_else(|e| panic!("{}: {e}", path.display()))
}

#[test]
fn every_target_is_a_libfuzzer_binary_calling_its_body() {
    let manifest = read("libfuzzer/Cargo.toml");
    let bins: Vec<&str> = manifest
        .lines()
        .filter_map(|l| l.strip_prefix("name = \""))
        .filter_map(|l| l.strip_suffix('"'))
        .filter(|n| *n != "vtol-fuzz-libfuzzer")
        .collect();
    let mut names: Vec<&str> = TARGETS.iter().map(|t| t.name).collect();
    let mut sorted_bins = bins.clone();
    names.sort_unstable();
    sorted_bins.sort_unstable();
    assert_eq!(sorted_bins, names, "fuzz/libfuzzer/Cargo.toml [[bin]]s");
    for t in TARGETS {
        let body = read(&format!("libfuzzer/fuzz_targets/{}.rs", t.name));
        assert!(
            body.contains(&format!("vtol_fuzz::targets::{}(data)", t.name)),
            "fuzz/libfuzzer/fuzz_targets/{}.rs does not call its target",
            t.name
        );
    }
}

#[test]
fn every_target_is_in_the_scripts_lists() {
    let script = read("libfuzzer/fuzz.sh");
    let list = script
        .split_once("TARGETS=(")
        .and_then(|(_, rest)| rest.split_once(')'))
        .map(|(l, _)| l)
        .expect("TARGETS=( … ) in fuzz.sh");
    let streams = script
        .split_once("local streams=(")
        .and_then(|(_, rest)| rest.split_once(')'))
        .map(|(l, _)| l.replace('"', " "))
        .expect("streams=( … ) in fuzz.sh");
    for t in TARGETS {
        assert!(
            list.split_whitespace().any(|n| n == t.name),
            "{} not in TARGETS",
            t.name
        );
        assert!(
            streams.split_whitespace().any(|n| n == t.name),
            "{} in no CI stream",
            t.name
        );
    }
}
