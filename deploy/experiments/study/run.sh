#!/usr/bin/env bash
# The query-rule study ("Does asking pay?" in EXPERIMENTS.md) in one sitting: the experiment
# files re-made by make.py, then the study's eight sweeps one after the other (the four tasks at
# every budget on seeds 0-9, the four headlines on seeds 0-29), two jobs each, into OUT; each
# sweep's wall-clock and the whole study's are printed. Complete runs in OUT are kept, so a
# stopped study goes on where it stopped. About 4.3 hours on the 2-core machine of BENCHMARKS.md.
#
#   bash deploy/experiments/study/run.sh [OUT]      # default sweeps/study
set -euo pipefail
cd "$(dirname "$0")/../../.."
out="${1:-sweeps/study}"
cargo build --release --quiet -p alfd-deploy --bin alfd
alfd="${CARGO_TARGET_DIR:-target}/release/alfd"
python3 deploy/experiments/study/make.py
start=$(date +%s)
for t in cliffwalk mountaincar acrobot cartpole \
         cliffwalk-headline mountaincar-headline acrobot-headline cartpole-headline; do
  seeds=10
  [[ $t == *-headline ]] && seeds=30
  s=$(date +%s)
  "$alfd" sweep --config "deploy/experiments/study/$t.toml" --seeds "$seeds" --jobs 2 \
      --out "$out/$t" --quiet
  echo "study: $t $(( $(date +%s) - s )) s"
done
echo "study: all eight sweeps $(( $(date +%s) - start )) s"
