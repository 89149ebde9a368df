#!/usr/bin/env bash
# The main job near the machine's limit, written to results/whole-run/ (summary.md, results.json)
# for BENCHMARKS.md (`alfd docs` copies the tables): where the learner's time goes in `alfd run`
# (perf's samples of the learner by part of the code, and the time it waits), its share of one
# core's FMA peak, `alfd run` against `alfd local` in updates per second, 1, 2, 4 and 8 actors,
# and the replay buffer's memory per million transitions. Needs `perf` (Debian's linux-perf,
# installed here when absent and run as root). Its summary gives the minutes its runs took; run
# it on an idle machine.
#
#   bash deploy/bench/whole-run.sh [REPEATS]      # each configuration REPEATS times (default 2)
#   bash deploy/bench/whole-run.sh 2 --summary-only   # rewrite summary.md from results.json
set -euo pipefail
cd "$(dirname "$0")/../.."
if ! command -v perf >/dev/null && [ "$(id -u)" = 0 ] && command -v apt-get >/dev/null; then
  (apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq linux-perf) >/dev/null
fi
command -v perf >/dev/null || { echo "whole-run.sh: perf is needed (Debian: linux-perf)" >&2; exit 2; }
cargo build --release --quiet --workspace
cargo build --release --quiet -p alfd-common --example replay_memory --example train_steps
bin="${CARGO_TARGET_DIR:-target}/release"
exec python3 deploy/bench/whole_run.py --alfd "$bin/alfd" --train-steps "$bin/examples/train_steps" \
    --replay-example "$bin/examples/replay_memory" --out results/whole-run --repeats "${1:-2}" \
    "${@:2}"
