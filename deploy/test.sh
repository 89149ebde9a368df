#!/usr/bin/env bash
# Builds everything and runs the whole test suite (unit, fixture, CLI and multi-process tests).
# One profile (release) serves the binaries the multi-process tests start and the tests themselves.
# At the end, also when a test fails: the 15 slowest tests with their times, and whether the tests
# left anything named alfd-* in the temporary directory (they should not: each removes its own).
set -euo pipefail
cd "$(dirname "$0")/.."
# The fuzz pass (proptest) draws its cases from this seed, so the test command gives the same
# verdict every time; set PROPTEST_RNG_SEED to another number (or unset it) to explore more cases.
export PROPTEST_RNG_SEED="${PROPTEST_RNG_SEED:-20261129}"
# The tests of deploy/cli/tests append "NAME SECONDS" to $ALFD_TEST_TIMES/times.txt as they end.
export ALFD_TEST_TIMES="${ALFD_TEST_TIMES:-${CARGO_TARGET_DIR:-$PWD/target}/test-times}"
mkdir -p "$ALFD_TEST_TIMES"
rm -f "$ALFD_TEST_TIMES/times.txt"
tmp="${TMPDIR:-/tmp}"
leftovers() { ls -A "$tmp" | grep '^alfd-' | sort || true; }
before="$(leftovers)"

setup_pid=""
mdbook_pid=""
report() {
  local status=$?
  set +e
  if [ -n "$mdbook_pid" ]; then
    kill "$mdbook_pid" 2>/dev/null
    wait "$mdbook_pid" 2>/dev/null
  fi
  if [ -n "$setup_pid" ]; then
    kill "$setup_pid" 2>/dev/null
    wait "$setup_pid" 2>/dev/null
    cat "$setup_log" 2>/dev/null
    rm -f "$setup_log"
  fi
  if [ -s "$ALFD_TEST_TIMES/times.txt" ]; then
    echo
    echo "slowest tests:"
    sort -k2,2 -rn "$ALFD_TEST_TIMES/times.txt" | head -n 15 |
      awk '{ printf "  %7.1f s  %s\n", $2, $1 }'
  fi
  local after new
  after="$(leftovers)"
  new="$(comm -13 <(echo "$before") <(echo "$after") | sed '/^$/d')"
  echo
  echo "alfd-* entries in $tmp: $(echo "$before" | grep -c . || true) before the tests," \
    "$(echo "$after" | grep -c . || true) after"
  if [ -n "$new" ]; then
    echo "warning: new since the tests started (a test that does not clean up, or another" \
      "test run at the same time):"
    echo "$new" | head -n 10 | sed 's/^/  /'
  fi
  exit "$status"
}
trap report EXIT

# The set-up that waits on the network and the disk more than on the processors runs in the
# background while cargo builds, its messages shown once it is done:
# - the Python side (the Gymnasium adapter's .venv/, deploy/python/requirements.txt), installed
#   here the way alfd installs it on first use, so that no test waits on it (a no-op once
#   installed);
# - the human page's browser test: Debian's Chromium driven by Playwright
#   (deploy/cli/tests/browser/package.json, pinned), installed with npm here as the test would.
#   Chromium is installed from Debian's packages when absent and this runs as root; a browser
#   test that still cannot run fails when CI is set (as .ci/run sets it) and says SKIPPED
#   otherwise.
setup_log="$tmp/test-setup.$$.log"
(
  set -e
  bash deploy/python/setup-venv.sh >/dev/null
  if [ ! -x /usr/bin/chromium ] && [ "$(id -u)" = 0 ] && command -v apt-get >/dev/null; then
    echo "== installing Debian's chromium for the human page's browser test"
    (apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq chromium) \
      >/dev/null || echo "warning: apt-get install chromium failed"
  fi
  if [ -x /usr/bin/chromium ] && [ ! -d deploy/cli/tests/browser/node_modules/playwright-core ]; then
    (cd deploy/cli/tests/browser && npm ci --no-audit --no-fund --silent)
  fi
) >"$setup_log" 2>&1 &
setup_pid=$!
# Every binary, and the tests compiled (unit tests of every library and binary, the integration
# tests), in one cargo invocation, whose scheduler then keeps both processors busy to the end.
# Not the doc tests: no doc comment holds a Rust example (tidy_features checks it), and rustdoc
# takes about 40 s to find none. Nor the examples, which `cargo clippy --all-targets` compiles.
cargo build --release --workspace --locked --lib --bins --tests
setup_status=0
wait "$setup_pid" || setup_status=$?
setup_pid=""
cat "$setup_log"
rm -f "$setup_log"
if [ "$setup_status" != 0 ]; then
  echo "the set-up above failed (exit code $setup_status)"
  exit 1
fi
# The manual (docs/, an mdBook): mdBook is built from crates.io into .tools/ on first use (its
# own pinned lock file, without the server and search features, at a lower optimisation level),
# at the lowest priority beside the tests (running, they leave a processor
# idle much of the time); the book is built after them, and its links are checked by a test.
mdbook_version=0.4.52
mdbook_pid=""
if ! .tools/bin/mdbook --version 2>/dev/null | grep -q "v$mdbook_version"; then
  echo "== building mdBook $mdbook_version into .tools/ (once), beside the tests"
  CARGO_PROFILE_RELEASE_OPT_LEVEL=1 CARGO_PROFILE_RELEASE_LTO=false \
    CARGO_PROFILE_RELEASE_CODEGEN_UNITS=16 CARGO_PROFILE_RELEASE_DEBUG=0 \
    nice -n 19 cargo install --quiet --locked "mdbook@$mdbook_version" --no-default-features \
    --root .tools -j 1 &
  mdbook_pid=$!
fi
# The multi-process tests wait on processes more than they compute: three at a time, not one per
# processor (ALFD_TEST_THREADS sets another number).
cargo test --release --workspace --locked --lib --bins --tests -- \
  --test-threads="${ALFD_TEST_THREADS:-3}"
if [ -n "$mdbook_pid" ]; then
  wait "$mdbook_pid" || { echo "building mdBook failed"; exit 1; }
  mdbook_pid=""
fi
book="$(.tools/bin/mdbook build docs 2>&1)" || { echo "$book"; exit 1; }
if grep -E '\[(WARN|ERROR)\]' <<<"$book"; then
  echo "mdbook: the manual builds with the warnings above"
  exit 1
fi
