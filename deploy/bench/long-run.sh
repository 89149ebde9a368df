#!/usr/bin/env bash
# Memory and files of a run ten times longer than the recommended CartPole preset (500,000
# environment steps instead of 50,000, 2 actors): every process's resident memory and every file
# of the run directory sampled every 2 s, written to results/long-run/ (samples.csv, summary.md)
# for BENCHMARKS.md (`alfd docs` copies the table). About 5 minutes on the 2-core machine.
#
#   bash deploy/bench/long-run.sh              # 500,000 steps
#   bash deploy/bench/long-run.sh 100000       # another length
set -euo pipefail
cd "$(dirname "$0")/../.."
steps="${1:-500000}"
cargo build --release --quiet --workspace
out="$(mktemp -d /tmp/alfd-long-run-XXXXXX)"
trap 'rm -rf "$out"' EXIT
exec python3 deploy/bench/long_run.py --alfd "${CARGO_TARGET_DIR:-target}/release/alfd" \
    --steps "$steps" --run-dir "$out/run" --results results/long-run
