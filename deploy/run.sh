#!/usr/bin/env bash
# The main job: an experiment as separate processes (learner, expert, N actors over iceoryx2).
#   deploy/run.sh [--config FILE] [--actors N] [--set key=value]... [--out DIR]
# Without --config: `alfd run`'s default, the recommended CartPole-1000 preset
# (deploy/configs/recommended/cartpole.toml: Bootstrapped DQN with a budget of 300 active
# demonstrations of the cartpole-1000 expert, 50,000 steps), 2 actors.
# Builds the release binaries first, showing cargo's progress (quick when they are up to date).
set -euo pipefail
root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
target="${CARGO_TARGET_DIR:-$root/target}"
echo "== building the release binaries (the first build takes a few minutes)" >&2
cargo build --release --manifest-path "$root/Cargo.toml" --workspace --bins
cd "$root"
echo "== alfd run $*" >&2
exec "$target/release/alfd" run "$@"
