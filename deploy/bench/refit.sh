#!/usr/bin/env bash
# How long a query waits for its answer while the expert refits a large demonstration model,
# written to results/refit/ (summary.md, results.json) for BENCHMARKS.md (`alfd docs` copies the
# table): `alfd run` on CartPole with one actor, the exact KRR model seeded by a dataset of 9,000
# expert steps (each refit grows a 9,000-row factor), refitting inline or in the background
# (`--refit`), against the same run without the dataset (refits of a few hundred rows) and with
# no model at all (no refits). About 4 minutes on the 2-core machine; run it on an idle machine.
#
#   bash deploy/bench/refit.sh [ROUNDS]      # default 3 interleaved rounds
set -euo pipefail
cd "$(dirname "$0")/../.."
cargo build --release --quiet --workspace --bins
exec python3 deploy/bench/refit.py --alfd "${CARGO_TARGET_DIR:-target}/release/alfd" \
    --out results/refit --rounds "${1:-3}"
