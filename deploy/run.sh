#!/usr/bin/env bash
# The main job: an experiment as separate processes (learner, expert, N actors over iceoryx2).
#   deploy/run.sh [--config FILE] [--actors N] [--set key=value]... [--out DIR]
# Without --config: `alfd run`'s default, the recommended CartPole-1000 preset
# (deploy/configs/recommended/cartpole.toml: Bootstrapped DQN with a budget of 300 active
# demonstrations of the cartpole-1000 expert, 50,000 steps), 2 actors.
# Builds the four binaries a run on this host uses first (alfd, alfd-actor, alfd-learner,
# alfd-expert), without runs across hosts (the `hosts` feature: zenoh and its TLS), Minari
# datasets (the `minari` feature: Arrow), web pages (the `pages` feature: axum; the watch
# page and a person's page) and the dependency features only the tests use (`test-features`),
# showing cargo's progress (quick when they are up to date). `cargo build --release --workspace` (as the
# test command does) builds every binary with every feature.
set -euo pipefail
root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
target="${CARGO_TARGET_DIR:-$root/target}"
echo "== building the release binaries (the first build takes a few minutes)" >&2
cargo build --release --manifest-path "$root/Cargo.toml" --no-default-features \
    --features alfd-deploy/png -p alfd-deploy -p alfd-actor -p alfd-learner -p alfd-expert \
    --bin alfd --bin alfd-actor --bin alfd-learner --bin alfd-expert
cd "$root"
echo "== alfd run $*" >&2
exec "$target/release/alfd" run "$@"
