#!/usr/bin/env bash
# Side-by-side speed of alfd and PyTorch / Gymnasium: the train step, the act
# step, environment steps/s and an end-to-end DQN, measured interleaved; prints one table and
# writes it to results/peers/summary.md (with results.json) unless --quick.
#
#   bash deploy/bench/peers.sh            # 5 rounds, about 5 minutes after the first install
#   bash deploy/bench/peers.sh --quick    # one short round, a smoke run
#   bash deploy/bench/peers.sh --rounds 9 # more rounds
#   bash deploy/bench/peers.sh --solve-only  # only the wall-clock to 475 (solve.py)
#
# After the speed table, in the same sitting, solve.py times alfd and Stable-Baselines3's DQN to
# a greedy evaluation of 475 on CartPole-v1 (three seeds each) into
# results/peers/solve.md (with solve.json); --quick leaves it out.
#
# On first use it makes the virtual environment .venv-bench/ (or $ALFD_BENCH_VENV) with Python
# 3.11 and installs deploy/bench/requirements.txt from PyPI (about 3 GB: PyPI's torch for Linux
# brings CUDA libraries); later runs reuse it until requirements.txt changes.
set -euo pipefail

cd "$(dirname "$0")/../.."
venv="${ALFD_BENCH_VENV:-.venv-bench}"
requirements="deploy/bench/requirements.txt"

# --no-deps: the list is torch's dependency closure pinned, less what CPU code never loads
# (about 3 GB).
source deploy/bench/venv.sh
bench_venv peers.sh "$venv" "$requirements" 'import torch, gymnasium, numpy, stable_baselines3'

echo "peers.sh: building alfd and the Criterion benches (release)" >&2
cargo build --release --quiet -p alfd-deploy --bin alfd
benches="$(cargo bench --quiet -p alfd-common --bench core --bench envs --no-run \
    --message-format=json-render-diagnostics)"
bench_exe() {
    "$venv/bin/python" -c '
import json, sys
name = sys.argv[1]
for line in sys.stdin:
    m = json.loads(line)
    if m.get("reason") == "compiler-artifact" and m["target"]["name"] == name \
            and m.get("executable"):
        print(m["executable"])
' "$1" <<<"$benches" | tail -n1
}
core="$(bench_exe core)"
envs="$(bench_exe envs)"
[[ -n "$core" && -n "$envs" ]] || { echo "peers.sh: bench binaries not found" >&2; exit 1; }

# A full run writes results/peers/ (summary.md, results.json) for BENCHMARKS.md; --quick does not.
out=(--out results/peers)
quick=0 solve_only=0 args=()
for a in "$@"; do
    case "$a" in
        --quick) out=(); quick=1; args+=("$a") ;;
        --solve-only) solve_only=1 ;;
        *) args+=("$a") ;;
    esac
done
if [[ $solve_only == 0 ]]; then
    "$venv/bin/python" deploy/bench/peers.py --alfd target/release/alfd \
        --core-bench "$core" --envs-bench "$envs" "${out[@]}" "${args[@]}"
fi
if [[ $quick == 0 ]]; then
    "$venv/bin/python" deploy/bench/solve.py --alfd target/release/alfd --out results/peers
fi
