#!/usr/bin/env bash
# The weak expert's dataset of the Minari study (EXPERIMENTS.md, "A weak expert's dataset, then
# active queries"): 10 MountainCar-v0 episodes in which every action is mountaincar-poor's
# (measured return -191.4, `alfd expert list`), recorded by `alfd local --transitions` and
# exported as the Minari dataset results/minari/datasets/alfd/mountaincar-poor-v0.
#
#   bash deploy/experiments/minari/make-dataset.sh
set -euo pipefail
cd "$(dirname "$0")/../../.."
cargo build --release --quiet -p alfd-deploy --bin alfd
alfd="${CARGO_TARGET_DIR:-target}/release/alfd"
run="$(mktemp -d)/weak-run"
out=results/minari/datasets/alfd/mountaincar-poor-v0
rm -rf "$out"
"$alfd" local --config deploy/configs/recommended/mountaincar.toml --quiet --transitions \
  --set seed=7000 --set steps=0 --set episodes=10 --set query.rule=uniform \
  --set query.probability=1.0 --set budget.total=2000 --set expert.name=mountaincar-poor \
  --out "$run" >/dev/null
"$alfd" demos export "$run" --out "$out"
rm -rf "$(dirname "$run")"
