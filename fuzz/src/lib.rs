//! Fuzz targets for every input the programs parse by hand, and a seeded mutation runner that
//! needs nothing but stable Rust.
//!
//! - [`targets`]: one `fn(&[u8])` per input (frames, tlogs, URLs, config and parameter files,
//!   missions, signing state, command-line values, STATUSTEXT chunks, the twin's handling of
//!   every message it reads, the tracker and the message inspector). Each one panics only on a
//!   broken contract: a panic inside the code, an error that is not one line, a round trip that
//!   does not come back.
//! - [`mutate`]: byte-level mutations (bit flips, interesting values, inserted, deleted and
//!   repeated runs, splices of two inputs), driven by a seeded ChaCha generator.
//! - [`runner`]: runs a target on mutations of its corpus for a time or a number of inputs, and
//!   keeps every input that panics.
//!
//! The runner is blind (no coverage feedback); it starts from corpora of real inputs
//! (`fuzz/corpus/TARGET/`) so the mutations start deep in each format. The targets have the
//! signature cargo-fuzz and cargo-afl take, so a coverage-guided engine can drive the same
//! functions where one is installed. `fuzz/regressions/TARGET/` keeps every input that ever
//! crashed a target; the test suite replays both directories.

pub mod mutate;
pub mod runner;
pub mod targets;

/// One fuzz target: a name (its corpus directory) and the function under test.
#[derive(Debug, Clone, Copy)]
pub struct Target {
    /// Name, also the directory of its corpus and regressions.
    pub name: &'static str,
    /// What it feeds, for `vtol-fuzz list`.
    pub about: &'static str,
    /// The function: panics only when a contract is broken.
    pub run: fn(&[u8]),
}

/// Every target.
pub const TARGETS: &[Target] = &[
    Target {
        name: "frame_decoder",
        about: "byte stream -> vtol-link frames (v1, v2, signed), split anywhere; every frame's accessors and decode",
        run: targets::frame_decoder,
    },
    Target {
        name: "tlog",
        about: "a tlog file -> TlogReader records and `log stats`",
        run: targets::tlog,
    },
    Target {
        name: "link_url",
        about: "--serve/--vehicle/--listen URLs -> LinkUrl, round trip through Display",
        run: targets::link_url,
    },
    Target {
        name: "vehicle_source",
        about: "--vehicle values (embedded, URLs, replay:FILE?speed=N)",
        run: targets::vehicle_source,
    },
    Target {
        name: "daemon_config",
        about: "the daemon's TOML config file, parsed and applied",
        run: targets::daemon_config,
    },
    Target {
        name: "param_file",
        about: "parameter files in the three formats, round trip through each format",
        run: targets::param_file,
    },
    Target {
        name: "twin_param_file",
        about: "the twin's --param-file, round trip",
        run: targets::twin_param_file,
    },
    Target {
        name: "mission_file",
        about: "the twin's QGC WPL 110 mission file, round trip",
        run: targets::mission_file,
    },
    Target {
        name: "signing_state",
        about: "the signing state file (key and timestamp), round trip",
        run: targets::signing_state,
    },
    Target {
        name: "sim_cli_values",
        about: "`firmware-sim simulate` values: --initial, --setpoint, --param, --push",
        run: targets::sim_cli_values,
    },
    Target {
        name: "statustext",
        about: "STATUSTEXT chunks (id, chunk_seq, text) -> joined texts",
        run: targets::statustext,
    },
    Target {
        name: "twin_endpoint",
        about: "valid-CRC frames of every message the twin reads (params, commands, missions, FTP, setpoints, RC) into its endpoint",
        run: targets::twin_endpoint,
    },
    Target {
        name: "tracker",
        about: "vehicle frames into the tracker, and the message inspector's field parser",
        run: targets::tracker,
    },
    Target {
        name: "router",
        about: "frames from three links through the router's raw-byte addressing and its routing table",
        run: targets::router,
    },
    Target {
        name: "signing_verify",
        about: "frames (signed or not) into signature verification",
        run: targets::signing_verify,
    },
];

/// The target of that name.
#[must_use]
pub fn target(name: &str) -> Option<&'static Target> {
    TARGETS.iter().find(|t| t.name == name)
}
