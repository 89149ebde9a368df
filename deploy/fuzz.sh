#!/usr/bin/env bash
# Fuzzes what a bridge does with a remote peer's bytes (`alfd_bridge::peer_bytes::take_in`: the
# decoders of frames, join and restart messages, the hub's check of who may send a frame, the
# wire's checks of sizes and states) with libFuzzer through cargo-fuzz, for SECONDS (default
# 600), from a seed corpus of one valid frame of every kind. An input that panics is a finding:
# libFuzzer stops and leaves it in common/bridge/fuzz/artifacts/peer_bytes/. The run's figures
# (inputs executed, code edges reached, findings) go to results/fuzz/summary.md.
#
#   bash deploy/fuzz.sh [SECONDS]
#
# cargo-fuzz is installed into .tools/ on first use (a few minutes). It passes rustc flags of
# the nightly toolchain; RUSTC_BOOTSTRAP=1 lets the stable compiler take them.
set -euo pipefail
cd "$(dirname "$0")/.."
seconds="${1:-600}"
if [ ! -x .tools/bin/cargo-fuzz ]; then
  echo "fuzz.sh: installing cargo-fuzz into .tools/" >&2
  cargo install --quiet --locked cargo-fuzz@0.13.1 --root .tools
fi
corpus=common/bridge/fuzz/corpus/peer_bytes
mkdir -p "$corpus"
cargo run --release --quiet -p alfd-bridge --example fuzz_seeds -- "$corpus"
export RUSTC_BOOTSTRAP=1
log="$(mktemp)"
status=0
.tools/bin/cargo-fuzz run --fuzz-dir common/bridge/fuzz --sanitizer none peer_bytes \
  "$corpus" -- -max_total_time="$seconds" -print_final_stats=1 2>&1 | tee "$log" || status=$?
python3 deploy/fuzz_summary.py "$log" "$seconds" "$status" > results/fuzz/summary.md
rm -f "$log"
exit "$status"
