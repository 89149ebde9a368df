#!/usr/bin/env bash
# Builds everything and runs the whole test suite (unit, fixture, CLI and multi-process tests).
set -euo pipefail
cd "$(dirname "$0")/.."
# The multi-process tests start the release binaries of every process.
cargo build --release --workspace --locked
cargo test --workspace --locked
