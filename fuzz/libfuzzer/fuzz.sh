#!/usr/bin/env bash
# Coverage-guided fuzzing of the vtol-fuzz targets with libFuzzer (docs/fuzzing.md).
#
#   fuzz/libfuzzer/fuzz.sh available            exit 0 when nightly and cargo-fuzz are installed
#   fuzz/libfuzzer/fuzz.sh build                build every target (cargo +nightly fuzz build)
#   fuzz/libfuzzer/fuzz.sh run SECONDS TARGET…  fuzz each target for SECONDS, one after the other
#   fuzz/libfuzzer/fuzz.sh ci SECONDS           build, then every target for SECONDS, in eight
#                                               streams of at most two targets; a build not done
#                                               in FUZZ_BUILD_SECONDS (600) is left for the next
#                                               run (cargo keeps what it finished) and this run
#                                               uses the stable runner (target/debug/vtol-fuzz)
#   fuzz/libfuzzer/fuzz.sh merge TARGET…        add to fuzz/corpus/TARGET only the inputs of the
#                                               kept corpus that reach new edges
#
# A run starts from fuzz/corpus/TARGET and fuzz/regressions/TARGET (read only: what it finds
# goes to a scratch directory, so the repository's corpora stay minimised). With FUZZ_KEEP=1
# the scratch directory is target/libfuzzer/corpus/TARGET and stays, for a long run to go on
# where it stopped and for `merge`. An input that crashes a target is written to fuzz/regressions/TARGET/, which
# the stable test suite replays (fuzz/tests/replay.rs), and the run exits 1. Each target's run
# ends with one line: executions, rate, coverage (edges) and features.
set -euo pipefail
cd "$(dirname "$0")/../.."

TARGET_DIR="${CARGO_TARGET_DIR:-$PWD/target}/libfuzzer"
TRIPLE="$(rustc -vV | sed -n 's/^host: //p')"
BIN_DIR="$TARGET_DIR/$TRIPLE/release"
TARGETS=(frame_decoder tlog link_url vehicle_source daemon_config param_file twin_param_file
    mission_file signing_state sim_cli_values statustext twin_endpoint tracker router signing_verify)

available() {
    rustup toolchain list 2>/dev/null | grep -q '^nightly' && cargo +nightly fuzz --version >/dev/null 2>&1
}

build() {
    # No sanitizer: the code under test forbids `unsafe`, and AddressSanitizer would halve the
    # executions; debug assertions and overflow checks stay on (cargo-fuzz's default).
    cargo +nightly fuzz build --sanitizer none --fuzz-dir fuzz/libfuzzer --target-dir "$TARGET_DIR"
}

# run_one SECONDS TARGET: fuzz one target; its summary line; status 1 on a crash.
run_one() {
    local seconds="$1" t="$2" scratch log rc=0
    if [ "${FUZZ_KEEP:-0}" = 1 ]; then
        scratch="$TARGET_DIR/corpus/$t"
        mkdir -p "$scratch"
    else
        scratch="$(mktemp -d)"
    fi
    log="${FUZZ_LOG_DIR:-$(mktemp -d)}/$t.log"
    mkdir -p "fuzz/regressions/$t"
    # -timeout: wall seconds per input; generous, the run may be at idle priority on a busy host.
    "$BIN_DIR/$t" -max_total_time="$seconds" -max_len=4096 -timeout=60 -rss_limit_mb=2048 \
        -print_final_stats=1 -artifact_prefix="fuzz/regressions/$t/" \
        "$scratch" "fuzz/corpus/$t" "fuzz/regressions/$t" > "$log" 2>&1 || rc=$?
    local execs rate cov ft
    execs="$(sed -n 's/^stat::number_of_executed_units: *//p' "$log" | tail -1)"
    rate="$(sed -n 's/^stat::average_exec_per_sec: *//p' "$log" | tail -1)"
    cov="$(grep -o 'cov: [0-9]*' "$log" | tail -1 | cut -d' ' -f2)"
    ft="$(grep -o 'ft: [0-9]*' "$log" | tail -1 | cut -d' ' -f2)"
    if [ "$rc" -eq 0 ]; then
        printf '%-16s %s execs in %s s (%s/s), cov %s, ft %s, no crash\n' \
            "$t" "${execs:-?}" "$seconds" "${rate:-?}" "${cov:-?}" "${ft:-?}"
    else
        printf '%-16s CRASH (libFuzzer exit %s) after %s execs, cov %s; input kept in fuzz/regressions/%s/\n' \
            "$t" "$rc" "${execs:-?}" "${cov:-?}" "$t"
        grep -E 'panicked|ERROR|Test unit written' "$log" | head -5 || true
    fi
    if [ "${FUZZ_KEEP:-0}" != 1 ]; then rm -rf "$scratch"; fi
    if [ -z "${FUZZ_LOG_DIR:-}" ]; then rm -rf "$(dirname "$log")"; fi
    return "$rc"
}

run() {
    local seconds="$1" rc=0
    shift
    for t in "$@"; do
        run_one "$seconds" "$t" || rc=1
    done
    return "$rc"
}

ci() {
    local seconds="$1" rc=0 pids=()
    local engine=libfuzzer build_rc=0
    mkdir -p "$TARGET_DIR"
    timeout "${FUZZ_BUILD_SECONDS:-600}" "$0" build > "$TARGET_DIR/build.log" 2>&1 || build_rc=$?
    if [ "$build_rc" -eq 124 ]; then
        echo "the libFuzzer build took over ${FUZZ_BUILD_SECONDS:-600} s: this run fuzzes with the stable runner"
        engine=stable
    elif [ "$build_rc" -ne 0 ]; then
        cat "$TARGET_DIR/build.log" >&2
        return 2
    fi
    trap 'kill "${pids[@]}" 2>/dev/null || true' EXIT
    local streams=("tlog link_url" "param_file statustext" "twin_endpoint vehicle_source"
        "twin_param_file signing_state" "frame_decoder daemon_config" "mission_file sim_cli_values"
        "router tracker" "signing_verify")
    for s in "${streams[@]}"; do
        # shellcheck disable=SC2086 # two target names
        if [ "$engine" = libfuzzer ]; then
            run "$seconds" $s & pids+=($!)
        else
            "${CARGO_TARGET_DIR:-$PWD/target}/debug/vtol-fuzz" run --seconds "$seconds" $s & pids+=($!)
        fi
    done
    for p in "${pids[@]}"; do
        wait "$p" || rc=1
    done
    return "$rc"
}

merge() {
    for t in "$@"; do
        local before
        before="$(find "fuzz/corpus/$t" -type f | wc -l)"
        # -use_counters=0: an input is kept for a new edge, not for a new hit count of a known
        # one (a quarter of the files and a ninth of the bytes on daemon_config).
        "$BIN_DIR/$t" -merge=1 -use_counters=0 -max_len=4096 "fuzz/corpus/$t" "$TARGET_DIR/corpus/$t" \
            > /dev/null 2>&1
        echo "$t: $before -> $(find "fuzz/corpus/$t" -type f | wc -l) inputs"
    done
}

cmd="${1:-}"
shift || true
case "$cmd" in
    available) available ;;
    build) build ;;
    run) run "$@" ;;
    ci) ci "$@" ;;
    merge) merge "$@" ;;
    *) sed -n '2,18p' "$0" >&2; exit 2 ;;
esac
