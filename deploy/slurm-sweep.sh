#!/usr/bin/env bash
# An `alfd sweep` spread over a Slurm cluster as a job array: task I of N runs shard I/N of the
# sweep (`alfd sweep --shard I/N`: the runs whose index k in the method-major order has
# k % N == I - 1) into OUT/shards/I, and a job that starts when every task has succeeded merges
# them (`alfd sweep --collect`) into OUT: curves.csv, the plot and summary.md, the same numbers as
# the sweep run on one machine.
#
#   deploy/slurm-sweep.sh EXPERIMENT OUT [N [SWEEP-ARGS...]]
#   e.g. deploy/slurm-sweep.sh deploy/experiments/fig4-cartpole.toml ~/sweeps/fig4 10 --seeds 50
#
# Run it on the login node, from the repository with the release binaries built
# (`cargo build --release --workspace --bins`) on a file system the compute nodes share: it submits
# the array (N tasks, default 4) and the dependent collect job, and prints their ids. SWEEP-ARGS
# (say --seeds, --episodes) go to every shard and to the collect, which refuses shards of another
# experiment, seeds or episodes. The #SBATCH lines below are defaults; edit them for your cluster
# (partition, account, time). A failed task can be resubmitted alone
# (`sbatch --array=I deploy/slurm-sweep.sh ...` with the same arguments): its complete runs are
# kept, and the collect job is then submitted by hand:
#   alfd sweep --config EXPERIMENT SWEEP-ARGS... --collect OUT/shards/* --out OUT
#
# Without Slurm, the same split by hand: for i in 1 2; do alfd sweep --config E --shard $i/2
# --out OUT/shards/$i; done; then alfd sweep --config E --collect OUT/shards/1 OUT/shards/2 --out OUT.
#
#SBATCH --job-name=alfd-sweep
#SBATCH --array=1-4
#SBATCH --cpus-per-task=2
#SBATCH --time=04:00:00
#SBATCH --output=slurm-%x-%A_%a.out
set -euo pipefail

if [[ $# -lt 2 ]]; then
    echo "usage: $0 EXPERIMENT OUT [N [SWEEP-ARGS...]]" >&2
    exit 2
fi
experiment="$1"
out="$2"
shards="${3:-4}"
shift $(($# < 3 ? $# : 3))

if [[ -n "${SLURM_ARRAY_TASK_ID:-}" ]]; then
    # A task of the array, on a compute node: its shard, one run per allocated core. The
    # binary was found at submission (ALFD_BIN, exported by sbatch). N is the argument rather
    # than $SLURM_ARRAY_TASK_COUNT, which is 1 when a single task is resubmitted.
    alfd="${ALFD_BIN:?ALFD_BIN is set when the array is submitted by this script}"
    exec "$alfd" sweep --config "$experiment" "$@" \
        --shard "$SLURM_ARRAY_TASK_ID/$shards" \
        --jobs "${SLURM_CPUS_PER_TASK:-2}" --quiet \
        --out "$out/shards/$SLURM_ARRAY_TASK_ID"
fi

# On the login node: absolute paths (the tasks may start elsewhere), then the two submissions.
root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
export ALFD_BIN="${ALFD_BIN:-${CARGO_TARGET_DIR:-$root/target}/release/alfd}"
if [[ ! -x "$ALFD_BIN" ]]; then
    echo "no $ALFD_BIN: build it first (cargo build --release --workspace --bins)" >&2
    exit 2
fi
experiment="$(cd "$(dirname "$experiment")" && pwd)/$(basename "$experiment")"
mkdir -p "$out"
out="$(cd "$out" && pwd)"
if ! [[ "$shards" =~ ^[0-9]+$ ]] || ((shards < 1 || shards > 10000)); then
    echo "N must be from 1 to 10000, got $shards" >&2
    exit 2
fi

# The array: N tasks, each this script with SLURM_ARRAY_TASK_ID set (overrides --array above).
array=$(sbatch --parsable --array="1-$shards" --chdir="$out" \
    "${BASH_SOURCE[0]}" "$experiment" "$out" "$shards" "$@")
array="${array%%;*}"

# The merge, once every task of the array has succeeded (afterok); a failed task leaves it
# pending (DependencyNeverSatisfied): resubmit that task, then the collect by hand.
dirs=()
for ((i = 1; i <= shards; i++)); do
    dirs+=("$out/shards/$i")
done
collect=$(printf '%q ' "$ALFD_BIN" sweep --config "$experiment" "$@" --collect "${dirs[@]}" \
    --out "$out" --quiet)
merge=$(sbatch --parsable --dependency="afterok:$array" --job-name=alfd-sweep-collect \
    --cpus-per-task=2 --chdir="$out" --output="$out/slurm-collect-%j.out" --wrap "$collect")
echo "submitted: array job $array ($shards shards into $out/shards/), collect job $merge (into $out)"
