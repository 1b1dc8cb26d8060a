//! The fuzz targets in the normal test suite: every stored input (the seed corpora and every
//! input that ever crashed a target) is replayed, then each target runs on a fixed number of
//! seeded mutations, the same ones on every machine. Longer runs: `vtol-fuzz run` (README).

use vtol_fuzz::runner::{self, Budget};
use vtol_fuzz::{TARGETS, target};

/// Mutated inputs per target in the suite (a few seconds for all of them together).
const SUITE_INPUTS: u64 = 300;

#[test]
fn every_stored_input_passes_its_target() {
    let dir = runner::fuzz_dir();
    let mut replayed = 0;
    let mut failures = Vec::new();
    for sub in ["corpus", "regressions"] {
        let root = dir.join(sub);
        for entry in std::fs::read_dir(&root).unwrap().map(Result::unwrap) {
            let name = entry.file_name().to_string_lossy().into_owned();
            let t = target(&name).unwrap_or_else(|| {
                panic!("{} is not named after a target", entry.path().display())
            });
            for (path, data) in runner::load_dir(&entry.path()).unwrap() {
                replayed += 1;
                if let Err(message) = runner::run_one(t, &data) {
                    failures.push(format!("{}: {message}", path.display()));
                }
            }
        }
    }
    assert!(failures.is_empty(), "{}", failures.join("\n"));
    assert!(replayed >= TARGETS.len(), "only {replayed} stored inputs");
}

#[test]
fn every_target_has_a_seed_corpus() {
    let dir = runner::fuzz_dir().join("corpus");
    for t in TARGETS {
        let seeds = runner::load_dir(&dir.join(t.name)).unwrap();
        assert!(!seeds.is_empty(), "no seed corpus for {}", t.name);
    }
}

#[test]
fn every_target_survives_seeded_mutations() {
    let dir = runner::fuzz_dir();
    for t in TARGETS {
        let corpus: Vec<Vec<u8>> = runner::load_dir(&dir.join("corpus").join(t.name))
            .unwrap()
            .into_iter()
            .map(|(_, d)| d)
            .collect();
        let report = runner::fuzz(t, &corpus, 7, Budget::Inputs(SUITE_INPUTS), 4096);
        if let Some(c) = report.crash {
            panic!(
                "{} crashed after {} inputs: {}\ninput ({} bytes): {:?}",
                t.name,
                report.inputs,
                c.message,
                c.input.len(),
                String::from_utf8_lossy(&c.input)
            );
        }
    }
}
