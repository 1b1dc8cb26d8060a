#!/usr/bin/env bash
# Runs every test: formatting, lints, the Rust tests and the pymavlink suite, with every fuzz
# target running beside the tests.
# On a fresh machine it installs what it needs itself (socat, tmux, iproute2 and nftables, a venv
# with the pinned Python packages in .venv, the vtol_twin pytest plugin into that venv).
set -euo pipefail
cd "$(dirname "$0")/.."

# Each stage says when it starts, in seconds since the run began (where the time goes).
stage() { echo "=== tests/run.sh [${SECONDS} s] $*" >&2; }
# What runs in the background (set-up, fuzz streams) stops with the script.
BG_PIDS=()
trap 'kill "${BG_PIDS[@]}" 2>/dev/null || true' EXIT

# --- what the tests need besides Rust, set up in the background ------------------------------
# socat (serial pseudo-terminals), tmux (the terminal UI's end-to-end test) and the venv are
# only needed from `cargo test` on, so they install while fmt, clippy and the test build run.
VENV="${VENV:-.venv}"
REQ=tests/pymavlink/requirements.txt
setup() {
    if ! command -v socat >/dev/null 2>&1; then
        export DEBIAN_FRONTEND=noninteractive
        apt-get update
        apt-get install -y socat
    fi
    # The terminal UI's end-to-end test runs the binary in a real terminal.
    if ! command -v tmux >/dev/null 2>&1; then
        export DEBIAN_FRONTEND=noninteractive
        apt-get update
        apt-get install -y tmux
    fi

    # The network test bed (tests/netbed, docs/network.md): namespaces and tc from iproute2,
    # loss, duplication and partitions from nftables.
    if ! command -v nft >/dev/null 2>&1 || ! command -v ip >/dev/null 2>&1 || ! command -v tc >/dev/null 2>&1; then
        export DEBIAN_FRONTEND=noninteractive
        apt-get update
        apt-get install -y iproute2 nftables
    fi

    # The Python venv with the pinned requirements.
    if [ ! -x "$VENV/bin/python" ] || ! cmp -s "$REQ" "$VENV/.requirements.installed"; then
        if ! python3 -m venv "$VENV"; then
            export DEBIAN_FRONTEND=noninteractive
            apt-get update
            apt-get install -y python3-venv
            python3 -m venv "$VENV"
        fi
        "$VENV/bin/python" -m pip install --quiet --disable-pip-version-check -r "$REQ"
        cp "$REQ" "$VENV/.requirements.installed"
    fi
}
SETUP_LOG="$(mktemp)"
setup > "$SETUP_LOG" 2>&1 &
SETUP_PID=$!
BG_PIDS+=("$SETUP_PID")

# --- Rust -------------------------------------------------------------------------------------
TARGET="${CARGO_TARGET_DIR:-$PWD/target}"
stage "cargo fmt"
cargo fmt --all -- --check
stage "cargo clippy"
cargo clippy --workspace --all-targets -- -D warnings
stage "cargo test --no-run"
cargo test --workspace --no-run
# The binaries the pymavlink suite and the fuzz streams run: `cargo test` built them with the
# same profile and features, so this only confirms they are fresh.
cargo build --workspace --bins
stage "waiting for socat, tmux and the venv"
if ! wait "$SETUP_PID"; then
    cat "$SETUP_LOG" >&2
    echo "setting up the test tools failed (see above)" >&2
    exit 1
fi
rm -f "$SETUP_LOG"

# --- fuzzing, in the background while the tests run -------------------------------------------
# Every fuzz target runs for 60 s of wall time, in eight streams of at most two targets, at the
# idle scheduling class: they take only the CPU the tests leave, so they add no delay to a test.
# Where the nightly toolchain and cargo-fuzz are installed the targets run under libFuzzer, with
# coverage feedback (fuzz/libfuzzer/fuzz.sh builds them first, also at idle priority); elsewhere,
# or with FUZZ_ENGINE=stable, under the stable seeded runner `vtol-fuzz`. A crash fails the run
# and leaves its input in fuzz/regressions/, which `cargo test` replays from then on.
FUZZ_LOGS="$(mktemp -d)"
FUZZ_PIDS=()
FUZZ_SCHED=(nice -n 19)
if command -v chrt >/dev/null 2>&1; then FUZZ_SCHED=(chrt --idle 0); fi
FUZZ_ENGINE="${FUZZ_ENGINE:-auto}"
if [ "$FUZZ_ENGINE" = auto ]; then
    FUZZ_ENGINE=stable
    if fuzz/libfuzzer/fuzz.sh available; then FUZZ_ENGINE=libfuzzer; fi
fi
fuzz_stream() {
    local name="$1"; shift
    # exec: the stream's process is the fuzzer itself, so the trap above can stop it.
    exec "${FUZZ_SCHED[@]}" "$TARGET/debug/vtol-fuzz" run \
        --seconds "${FUZZ_SECONDS:-60}" "$@" > "$FUZZ_LOGS/$name.log" 2>&1
}
if [ "$FUZZ_ENGINE" = libfuzzer ]; then
    "${FUZZ_SCHED[@]}" fuzz/libfuzzer/fuzz.sh ci "${FUZZ_SECONDS:-60}" > "$FUZZ_LOGS/libfuzzer.log" 2>&1 &
    FUZZ_PIDS+=($!); BG_PIDS+=($!)
else
    fuzz_stream a tlog link_url & FUZZ_PIDS+=($!); BG_PIDS+=($!)
    fuzz_stream b param_file statustext & FUZZ_PIDS+=($!); BG_PIDS+=($!)
    fuzz_stream c twin_endpoint vehicle_source & FUZZ_PIDS+=($!); BG_PIDS+=($!)
    fuzz_stream d twin_param_file signing_state & FUZZ_PIDS+=($!); BG_PIDS+=($!)
    fuzz_stream e frame_decoder daemon_config & FUZZ_PIDS+=($!); BG_PIDS+=($!)
    fuzz_stream f mission_file sim_cli_values & FUZZ_PIDS+=($!); BG_PIDS+=($!)
    fuzz_stream g router tracker & FUZZ_PIDS+=($!); BG_PIDS+=($!)
    fuzz_stream h signing_verify & FUZZ_PIDS+=($!); BG_PIDS+=($!)
fi

stage "cargo test"
cargo test --workspace

# --- the vtol_twin pytest plugin, installed as a user installs it: the pymavlink suite's
# forward-flight tests use its fixture, and its own tests run after that suite ---------------
# Reinstalled only when its sources change (flit_core from requirements.txt builds it offline).
PLUGIN=python/vtol_twin
PLUGIN_SUM="$(find "$PLUGIN" -type f -not -path '*/__pycache__/*' | LC_ALL=C sort | xargs cat | cksum)"
if [ "$PLUGIN_SUM" != "$(cat "$VENV/.vtol_twin.installed" 2>/dev/null)" ]; then
    "$VENV/bin/python" -m pip install --quiet --disable-pip-version-check --no-deps \
        --no-build-isolation --force-reinstall "./$PLUGIN"
    echo "$PLUGIN_SUM" > "$VENV/.vtol_twin.installed"
fi

# --- pymavlink / MAVProxy against the real binaries ------------------------------------------
BIN_DIR="$TARGET/debug"
export FIRMWARE_SIM_BIN="$BIN_DIR/firmware-sim"
export VTOL_GCS_BIN="$BIN_DIR/vtol-gcs"
# Four workers, one test file each at a time (module fixtures stay in one worker): the tests
# mostly wait on the twin's and the daemon's real-time traffic, not on the CPU.
stage "pytest tests/pymavlink"
"$VENV/bin/python" -m pytest -n 4 --dist loadfile tests/pymavlink

# --- the fleet soak (docs/fleet.md): 60 vehicles over four ground daemons on one Zenoh router,
# vehicles leaving and joining, 130 s for the daemons' chart history to fill and 60 s measured;
# fails unless memory, descriptors and Zenoh sessions stay flat and no frame that reached a
# daemon is lost. About 3 min and most of a core, so it starts after the pymavlink suite, whose
# network tests time what an operator sees, and runs beside the conformance scenarios and the
# plugin's tests, which wait on vehicle time and asserted counts, not on the wall. The hour-long
# soak runs off CI.
stage "fleet soak (60 s measured), in the background"
SOAK_LOG="$(mktemp)"
cargo test --bench zenoh_fleet -- --soak > "$SOAK_LOG" 2>&1 &
SOAK_PID=$!
BG_PIDS+=("$SOAK_PID")

# --- conformance with ArduPlane (tests/conformance/README.md): every scenario against a fresh
# twin, compared with the traces recorded from ArduPlane SITL; one scenario per worker.
stage "pytest tests/conformance"
"$VENV/bin/python" -m pytest -n 4 tests/conformance

# Sixteen workers: the parallel test runs sixteen twins at once.
stage "pytest $PLUGIN/tests"
"$VENV/bin/python" -m pytest -n 16 "$PLUGIN/tests"

stage "waiting for the fleet soak"
SOAK_RC=0
wait "$SOAK_PID" || SOAK_RC=$?
cat "$SOAK_LOG"
rm -f "$SOAK_LOG"
if [ "$SOAK_RC" -ne 0 ]; then
    echo "the fleet soak failed (see above)" >&2
    exit 1
fi

# --- the fuzz streams' results ---------------------------------------------------------------
stage "waiting for the fuzz streams ($FUZZ_ENGINE)"
FUZZ_RC=0
for pid in "${FUZZ_PIDS[@]}"; do
    wait "$pid" || FUZZ_RC=1
done
cat "$FUZZ_LOGS"/*.log
rm -rf "$FUZZ_LOGS"
if [ "$FUZZ_RC" -ne 0 ]; then
    echo "fuzzing found a crash: its input is in fuzz/regressions/ (see above)" >&2
    exit 1
fi
stage "all passed"
