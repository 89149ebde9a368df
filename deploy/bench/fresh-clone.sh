#!/usr/bin/env bash
# The README's two commands timed on fresh clones of this repository's HEAD, one after the
# other: `bash .ci/run` (the test command as CI runs it: build, the Python pieces, every test)
# and `bash deploy/run.sh` (the main job: build and train), each in a clone of its own with an
# empty target directory (crates already downloaded stay in ~/.cargo). Written to
# results/fresh-clone/summary.md for README.md (`alfd docs` copies it), and one row per command
# to results/fresh-clone/runs.csv. About 18 minutes on the
# 2-core machine; run it on an idle machine. A `../shared` beside this repository is linked
# beside the clones, as CI has it.
#
#   bash deploy/bench/fresh-clone.sh
#   bash deploy/bench/fresh-clone.sh --main-job-only   # the main job alone (about 4 minutes),
#                                                      # to results/fresh-clone/main-job.md
set -euo pipefail
main_job_only=false
[ "${1:-}" = "--main-job-only" ] && main_job_only=true
repo="$(cd "$(dirname "$0")/../.." && pwd)"
work="$(mktemp -d /tmp/alfd-fresh-clone-XXXXXX)"
trap 'rm -rf "$work"' EXIT
[ -d "$repo/../shared" ] && ln -s "$(cd "$repo/../shared" && pwd)" "$work/shared"
commit="$(git -C "$repo" rev-parse --short HEAD)"

timed() { # NAME DIR COMMAND...: runs COMMAND in DIR, prints its seconds, keeps its log
  local name="$1" dir="$2"; shift 2
  local start end
  start="$(date +%s)"
  (cd "$dir" && "$@") >"$work/$name.log" 2>&1 || {
    echo "fresh-clone.sh: $name failed; the end of its log:" >&2
    tail -n 30 "$work/$name.log" >&2
    exit 1
  }
  end="$(date +%s)"
  echo $((end - start))
}

if ! $main_job_only; then
  git clone -q "$repo" "$work/ci"
  ci_s="$(timed ci "$work/ci" bash .ci/run)"
  tests="$(grep -o 'test result: ok. [0-9]* passed' "$work/ci.log" | awk '{s += $4} END {print s}')"
fi
git clone -q "$repo" "$work/main-job"
job_s="$(timed main-job "$work/main-job" bash deploy/run.sh --quiet --json)"
train_s="$(tail -n 1 "$work/main-job.log" | python3 -c 'import json,sys; print(json.loads(sys.stdin.read())["wall_clock_s"])')"

mmss() { printf '%d min %d s' $(($1 / 60)) $(($1 % 60)); }
cpu="$(grep -m1 'model name' /proc/cpuinfo | cut -d: -f2 | sed 's/^ *//')"
mkdir -p "$repo/results/fresh-clone"
# One row per measured command, appended (results/fresh-clone/runs.csv).
runs="$repo/results/fresh-clone/runs.csv"
[ -f "$runs" ] || echo "date,cpu,cores,commit,command,seconds,training_s,tests_passed,how" >"$runs"
how="fresh-clone.sh${1:+ $1}"
row() { echo "$(date -u +%Y-%m-%d),${cpu//,/ },$(nproc),$commit,$1,$2,$3,$4,$how" >>"$runs"; }
$main_job_only || row "bash .ci/run" "$ci_s" "" "$tests"
row "bash deploy/run.sh" "$job_s" "$(printf '%.0f' "$train_s")" ""
if $main_job_only; then
  cat >"$repo/results/fresh-clone/main-job.md" <<MD
# The main job on a fresh clone

Written by \`bash deploy/bench/fresh-clone.sh --main-job-only\`.

## Times

Measured $(date -u +%Y-%m-%d) on $cpu, $(nproc) cores, commit $commit, in a fresh clone with an
empty target directory: \`bash deploy/run.sh\` (the main job) took $(mmss "$job_s"), of which
training $(printf '%.0f' "$train_s") s and the build the rest.
MD
  echo "fresh-clone.sh: deploy/run.sh $(mmss "$job_s")"
  exit 0
fi
cat >"$repo/results/fresh-clone/summary.md" <<MD
# The README's two commands on a fresh clone

Written by \`bash deploy/bench/fresh-clone.sh\`.

## Times

Measured $(date -u +%Y-%m-%d) on $cpu, $(nproc) cores, commit $commit, each command in a fresh
clone with an empty target directory: \`bash .ci/run\` (the test command: builds, the Python
adapter and every test; $tests tests passed) took $(mmss "$ci_s"); \`bash deploy/run.sh\` (the main
job) took $(mmss "$job_s"), of which training $(printf '%.0f' "$train_s") s and the build the rest.
MD
echo "fresh-clone.sh: .ci/run $(mmss "$ci_s"), deploy/run.sh $(mmss "$job_s")"
