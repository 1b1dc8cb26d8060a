//! Runs a target on mutations of its corpus for a time or a number of inputs, from a seed, and
//! stops at the first input that panics. Also replays stored inputs (corpus and regressions).

use std::panic::{AssertUnwindSafe, catch_unwind};
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

use crate::Target;
use crate::mutate::mutate;

/// How long a run goes on.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Budget {
    /// Until this much wall time has passed.
    Time(Duration),
    /// This many inputs (repeatable whatever the machine's speed).
    Inputs(u64),
}

/// An input that broke a contract.
#[derive(Debug, Clone)]
pub struct Crash {
    /// The input.
    pub input: Vec<u8>,
    /// The panic's message.
    pub message: String,
}

/// What a run did.
#[derive(Debug, Clone)]
pub struct Report {
    /// Inputs tried.
    pub inputs: u64,
    /// Wall time taken.
    pub elapsed: Duration,
    /// The first crash, if any (the run stops there).
    pub crash: Option<Crash>,
}

/// Where the corpora and regressions live: `fuzz/` of this checkout.
#[must_use]
pub fn fuzz_dir() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

/// Every file of `dir`, sorted by name (an absent directory holds none).
///
/// # Errors
/// A directory or file that exists but cannot be read.
pub fn load_dir(dir: &Path) -> std::io::Result<Vec<(PathBuf, Vec<u8>)>> {
    let Ok(entries) = std::fs::read_dir(dir) else {
        return Ok(Vec::new());
    };
    let mut paths: Vec<PathBuf> = entries
        .map(|e| e.map(|e| e.path()))
        .collect::<Result<_, _>>()?;
    paths.retain(|p| p.is_file());
    paths.sort();
    paths
        .into_iter()
        .map(|p| std::fs::read(&p).map(|d| (p, d)))
        .collect()
}

/// Runs the target once; the panic's message if it panicked.
///
/// # Errors
/// The message of the panic.
pub fn run_one(target: &Target, input: &[u8]) -> Result<(), String> {
    catch_unwind(AssertUnwindSafe(|| (target.run)(input))).map_err(|payload| {
        payload
            .downcast_ref::<String>()
            .cloned()
            .or_else(|| payload.downcast_ref::<&str>().map(|s| (*s).to_owned()))
            .unwrap_or_else(|| "panic with a non-text payload".to_owned())
    })
}

/// Mutates inputs of `corpus` (or grows from nothing when it is empty) and runs the target on
/// each until the budget is spent or an input panics.
#[must_use]
pub fn fuzz(
    target: &Target,
    corpus: &[Vec<u8>],
    seed: u64,
    budget: Budget,
    max_len: usize,
) -> Report {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let start = Instant::now();
    let empty = Vec::new();
    let mut inputs = 0u64;
    loop {
        let done = match budget {
            Budget::Time(d) => start.elapsed() >= d,
            Budget::Inputs(n) => inputs >= n,
        };
        if done {
            return Report {
                inputs,
                elapsed: start.elapsed(),
                crash: None,
            };
        }
        let pick = |rng: &mut ChaCha8Rng| {
            if corpus.is_empty() {
                &empty
            } else {
                &corpus[rng.random_range(0..corpus.len())]
            }
        };
        let (a, b) = (pick(&mut rng), pick(&mut rng));
        let input = mutate(a, b, &mut rng, max_len);
        inputs += 1;
        if let Err(message) = run_one(target, &input) {
            return Report {
                inputs,
                elapsed: start.elapsed(),
                crash: Some(Crash { input, message }),
            };
        }
    }
}

/// A stable name for a crash file: `crash-` and the FNV-1a hash of the input.
#[must_use]
pub fn crash_name(input: &[u8]) -> String {
    let mut h: u64 = 0xcbf2_9ce4_8422_2325;
    for b in input {
        h ^= u64::from(*b);
        h = h.wrapping_mul(0x0000_0100_0000_01b3);
    }
    format!("crash-{h:016x}")
}
