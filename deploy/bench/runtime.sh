#!/usr/bin/env bash
# The runtime's speed, written to results/runtime/ (summary.md, results.json) for BENCHMARKS.md
# (`alfd docs` copies the tables): the wire on shared memory and over zenoh on loopback, Gymnasium
# environments and an external expert through the Python adapter, the cost of a checkpoint.
# About 3 minutes on the 2-core machine after the builds; run it on an idle machine.
#
#   bash deploy/bench/runtime.sh [ROUNDS]          # default 3 interleaved rounds
#   bash deploy/bench/runtime.sh 3 --summary-only  # rewrite summary.md from results.json
set -euo pipefail
cd "$(dirname "$0")/../.."
cargo build --release --quiet -p alfd-deploy --bin alfd-bench-ipc --bin alfd-bench-remote
python="$(bash deploy/python/setup-venv.sh)"
exec python3 deploy/bench/runtime.py --bin "${CARGO_TARGET_DIR:-target}/release" \
    --python "$python" --out results/runtime --rounds "${1:-3}" "${@:2}"
