#!/usr/bin/env bash
# Runs every test: formatting, lints, the Rust tests, then the pymavlink suite.
# On a fresh machine it installs what it needs itself (socat, tmux, a venv with the pinned Python
# packages in .venv).
set -euo pipefail
cd "$(dirname "$0")/.."

# --- system packages -------------------------------------------------------------------------
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

# --- Python venv with the pinned requirements -------------------------------------------------
VENV="${VENV:-.venv}"
REQ=tests/pymavlink/requirements.txt
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

# --- Rust -------------------------------------------------------------------------------------
cargo fmt --all -- --check
cargo clippy --workspace --all-targets -- -D warnings
cargo test --workspace
cargo build --workspace --bins

# --- pymavlink / MAVProxy against the real binaries ------------------------------------------
BIN_DIR="${CARGO_TARGET_DIR:-$PWD/target}/debug"
export FIRMWARE_SIM_BIN="$BIN_DIR/firmware-sim"
export VTOL_GCS_BIN="$BIN_DIR/vtol-gcs"
"$VENV/bin/python" -m pytest tests/pymavlink
