#!/usr/bin/env bash
# Environment steps/s through the Python adapter (alfd-bench-remote) beside Gymnasium stepping
# in-process (deploy/python/bench_inprocess.py), interleaved, and the external expert's round
# trip; one JSON line per measurement.
#
#   bash deploy/bench/remote.sh [ROUNDS]     # default 3 rounds, CartPole-v1 and Acrobot-v1
set -euo pipefail
cd "$(dirname "$0")/../.."
rounds="${1:-3}"
cargo build --release --quiet -p alfd-deploy --bin alfd-bench-remote
python="$(bash deploy/python/setup-venv.sh)"
bin="${CARGO_TARGET_DIR:-target}/release/alfd-bench-remote"
for r in $(seq "$rounds"); do
    for id in CartPole-v1 Acrobot-v1; do
        "$python" deploy/python/bench_inprocess.py "$id" 20000
        "$bin" "$id" 20000 2000
    done
done
