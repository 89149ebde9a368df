#!/usr/bin/env bash
# The neural DeepSea study, start to end: tuning seeds 1000-1009 choose the setting (choose.py),
# then the reported seeds 0-49 at N = 10 and 14. Usage: run.sh OUT_DIR RESULTS_DIR [JOBS].
set -euo pipefail
here=$(cd "$(dirname "$0")" && pwd)
out=$1 results=$2 jobs=${3:-2}
alfd=${ALFD:-alfd}
mkdir -p "$out" "$results/tuning"
start=$(date +%s)
python3 "$here/make.py"
"$alfd" sweep --config "$here/tune.toml" --first-seed 1000 --seeds 10 --jobs "$jobs" --out "$out/tune"
cp "$out/tune/runs.csv" "$results/tuning/tune-runs.csv"
cp "$out/tune/summary.md" "$results/tuning/tune-summary.md"
python3 "$here/choose.py" "$out/tune/runs.csv" | tee "$results/tuning/choice.md"
read -r torso margin < <(grep '^CHOSEN' "$results/tuning/choice.md" | cut -d' ' -f2-)
python3 "$here/make.py" "$torso" "$margin"
echo "tuning $(( $(date +%s) - start )) s" > "$results/wall-clock.txt"
for n in 10 14; do
  t=$(date +%s)
  "$alfd" sweep --config "$here/gates-n$n.toml" --seeds 50 --jobs "$jobs" --out "$out/n$n"
  mkdir -p "$results/n$n"
  cp "$out/n$n"/runs.csv "$out/n$n"/summary.md "$out/n$n"/*.svg "$out/n$n"/*.png "$results/n$n/" 2>/dev/null || true
  echo "n$n $(( $(date +%s) - t )) s" >> "$results/wall-clock.txt"
done
echo "total $(( $(date +%s) - start )) s" >> "$results/wall-clock.txt"
