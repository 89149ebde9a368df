#!/usr/bin/env bash
# Counts the crates (with their build scripts' dependencies) the main job's build and the test
# command's build compile, by `cargo tree -e normal,build`, and writes results/build/crates.md.
set -euo pipefail
cd "$(dirname "$0")/../.."
count() {
  cargo tree -e normal,build --prefix none --no-dedupe "$@" |
    sed 's/ (\*)//; s/ (proc-macro)//' | sort -u | wc -l
}
main_job="$(count --no-default-features --features alfd-deploy/png -p alfd-deploy -p alfd-actor \
  -p alfd-learner -p alfd-expert)"
workspace="$(count --workspace)"
cat >results/build/crates.md <<MD
# Crates each build compiles

\`bash deploy/bench/crate-counts.sh\` ($(date +%Y-%m-%d)): crates with their build scripts'
dependencies, by \`cargo tree -e normal,build\`, the project's own included.

| build | crates |
|---|---:|
| the main job (\`deploy/run.sh\`: four binaries, features \`png\` only) | $main_job |
| the workspace (\`deploy/test.sh\`, every feature) | $workspace |
MD
cat results/build/crates.md
