#!/usr/bin/env bash
# Runs an experiment as separate processes (learner, expert, N actors over iceoryx2):
#   deploy/run.sh [--config FILE] [--actors N] [--set key=value]... [--out DIR]
# With no arguments: CartPole, Bootstrapped DQN + KRR shaping, 2 actors, the 1000 expert.
# Builds the release binaries first (cargo is quick when they are up to date).
set -euo pipefail
root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
target="${CARGO_TARGET_DIR:-$root/target}"
cargo build --release --quiet --manifest-path "$root/Cargo.toml" \
    -p alfd-deploy -p alfd-learner -p alfd-actor -p alfd-expert
exec "$target/release/alfd" run "$@"
