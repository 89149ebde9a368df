#!/usr/bin/env bash
# The long chaos run: seeded `alfd chaos` runs of the recommended CartPole preset back to back for
# MINUTES minutes (default 40), each beside the same run without faults (same config seed), then
# results/chaos-long/summary.md and runs.csv: faults by kind, the invariants, and the last 50
# episodes' mean return with and without faults (the manual's "Faults" chapter, docs/src/faults.md, quotes them).
#
#   bash deploy/chaos/long.sh [MINUTES] [ROOT]
#
# ROOT (default /mnt/chaos) should be a small file system (a tmpfs of 512 MB, made here when
# run as root and ROOT is not a mount point) so that the disk faults fill it; elsewhere they
# write up to 512 MB and give up. Needs the release binaries (cargo build --release --workspace).
set -euo pipefail
cd "$(dirname "$0")/../.."
minutes="${1:-40}"
root="${2:-/mnt/chaos}"
alfd="${ALFD:-target/release/alfd}"
mkdir -p "$root"
if [ "$(id -u)" = 0 ] && ! mountpoint -q "$root"; then
  mount -t tmpfs -o size=512m tmpfs "$root"
fi
end=$(( $(date +%s) + minutes * 60 ))
seed=1
while [ "$(date +%s)" -lt "$end" ]; do
  rm -rf "$root/chaos-$seed" "$root/control-$seed"
  echo "long.sh: seed $seed" >&2
  "$alfd" chaos --out "$root/chaos-$seed" --seed "$seed" --set "seed=$seed" \
    --duration 600 --every 3 --faults kill=4,pause=3,swap=1,launcher=1,disk=1 \
    --experts cartpole-500,cartpole-1000,cartpole-perfect >"$root/chaos-$seed.log" 2>&1 || true
  "$alfd" run --out "$root/control-$seed" --set "seed=$seed" --checkpoint-every 2000 \
    --quiet >/dev/null 2>"$root/control-$seed.log" || true
  # Keep what the summary reads; the rest (checkpoints, logs) frees the small file system.
  for d in "$root/chaos-$seed" "$root/control-$seed"; do
    find "$d" -type f ! -name chaos.json ! -name summary.json ! -name episodes.csv -delete 2>/dev/null || true
  done
  seed=$((seed + 1))
done
mkdir -p results/chaos-long
python3 deploy/chaos/summary.py "$root" results/chaos-long
