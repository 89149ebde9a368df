#!/usr/bin/env bash
# Benchmarks of the core's hot paths, written to results/bench/ (summary.md, results.json) for
# BENCHMARKS.md (`alfd docs` copies the tables): the train step (CPU time per step, and each
# part's time: `train_steps parts`), the demonstration model against scikit-learn, and KRR's
# cost of one more demonstration, measured interleaved in one sitting.
#
#   bash deploy/bench/core.sh            # 3 rounds, several minutes after the first install
#   bash deploy/bench/core.sh --rounds 5
#
# Run it on an idle machine: the table records the load average it ran under. On first use it
# makes .venv-bench-core/ (or $ALFD_BENCH_CORE_VENV) with Python 3.11 and installs
# deploy/bench/core-requirements.txt from PyPI (about 300 MB on disk).
set -euo pipefail

cd "$(dirname "$0")/../.."
venv="${ALFD_BENCH_CORE_VENV:-.venv-bench-core}"
requirements="deploy/bench/core-requirements.txt"
source deploy/bench/venv.sh
bench_venv core.sh "$venv" "$requirements" 'import sklearn, numpy, scipy'
echo "core.sh: building alfd and the train-step example (release)" >&2
cargo build --release --quiet -p alfd-deploy --bin alfd
cargo build --release --quiet -p alfd-common --example train_steps --example krr_grow --example nystrom_agreement
exec "$venv/bin/python" deploy/bench/core.py --out results/bench "$@"
