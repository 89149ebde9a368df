#!/usr/bin/env bash
# Benchmarks of the core's hot paths, written to results/bench/ (summary.md, results.json) for
# BENCHMARKS.md (`alfd docs` copies the tables): the train step (CPU time per step) and the
# demonstration model against scikit-learn, measured interleaved in one sitting.
#
#   bash deploy/bench/core.sh            # 3 rounds, about 5 minutes after the first install
#   bash deploy/bench/core.sh --rounds 5
#
# Run it on an idle machine: the table records the load average it ran under. On first use it
# makes .venv-bench-core/ (or $ALFD_BENCH_CORE_VENV) with Python 3.11 and installs
# deploy/bench/core-requirements.txt from PyPI (about 100 MB).
set -euo pipefail

cd "$(dirname "$0")/../.."
venv="${ALFD_BENCH_CORE_VENV:-.venv-bench-core}"
requirements="deploy/bench/core-requirements.txt"
python="${ALFD_BENCH_PYTHON:-python3}"
if ! "$python" -c 'import sys; sys.exit(sys.version_info[:2] != (3, 11))'; then
    echo "core.sh: needs Python 3.11 (the pinned wheels are for CPython 3.11); set ALFD_BENCH_PYTHON" >&2
    exit 2
fi
stamp="$venv/.requirements.sha256"
want="$(sha256sum "$requirements" | cut -d' ' -f1)"
if [[ ! -x "$venv/bin/python" || ! -f "$stamp" || "$(cat "$stamp")" != "$want" ]]; then
    echo "core.sh: installing scikit-learn into $venv (once)" >&2
    [[ -x "$venv/bin/python" ]] || "$python" -m venv "$venv"
    "$venv/bin/python" -m pip install --quiet --no-deps -r "$requirements"
    "$venv/bin/python" -c 'import sklearn, numpy, scipy'
    echo "$want" >"$stamp"
fi
echo "core.sh: building alfd and the train-step example (release)" >&2
cargo build --release --quiet -p alfd-deploy --bin alfd
cargo build --release --quiet -p alfd-common --example train_steps
exec "$venv/bin/python" deploy/bench/core.py --out results/bench "$@"
