#!/usr/bin/env bash
# Runs every test: formatting, lints, the Rust tests, then the pymavlink suite.
set -euo pipefail
cd "$(dirname "$0")/.."
cargo fmt --all -- --check
cargo clippy --workspace --all-targets -- -D warnings
cargo test --workspace
