#!/usr/bin/env bash
# Builds everything and runs the whole test suite (unit, fixture, CLI and multi-process tests).
# One profile (release) serves the binaries the multi-process tests start and the tests themselves.
set -euo pipefail
cd "$(dirname "$0")/.."
cargo build --release --workspace --locked
cargo test --release --workspace --locked
