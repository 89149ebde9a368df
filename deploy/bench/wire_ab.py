"""Two builds of `alfd-bench-ipc` side by side, in interleaved rounds on one machine: the wire's
query round trips and transitions throughput of each, as medians over the rounds (the range in
parentheses), and the ratio of the second to the first.

    python3 deploy/bench/wire_ab.py OLD_BIN_DIR NEW_BIN_DIR [ROUNDS [RUNS_CSV]] > wire-ab.md

RUNS_CSV, if given, gets one row per round, build and measure: what the medians come from.
"""

import json
import os
import statistics
import subprocess
import sys


def one(bin_dir):
    env = dict(os.environ, ALFD_BENCH_SCALE="0.3")
    out = subprocess.run([os.path.join(bin_dir, "alfd-bench-ipc")], env=env, check=True,
                         capture_output=True, text=True).stdout
    return json.loads(out.strip().splitlines()[-1])


METRICS = [
    ("query round trip, polling, p50 (µs)", lambda r: r["query-poll"]["p50_us"]),
    ("query round trip, blocking, p50 (µs)", lambda r: r["query-block"]["p50_us"]),
    ("transitions, actor → learner (M/s)", lambda r: r["transitions"]["transitions_per_s"] / 1e6),
    ("weight broadcast, p50 (µs)", lambda r: r["weights"]["p50_us"]),
]


def main():
    old, new = sys.argv[1], sys.argv[2]
    rounds = int(sys.argv[3]) if len(sys.argv) > 3 else 5
    got = {"old": [], "new": []}
    for i in range(rounds):
        for name, d in (("old", old), ("new", new)) if i % 2 == 0 else (("new", new), ("old", old)):
            got[name].append(one(d))
            print(f"wire_ab: round {i + 1}/{rounds} {name}", file=sys.stderr)
    if len(sys.argv) > 4:
        with open(sys.argv[4], "w") as f:
            f.write("round,build,measure,value\n")
            for name in ("old", "new"):
                for i, r in enumerate(got[name]):
                    for label, fn in METRICS:
                        f.write(f'{i + 1},{name},"{label}",{fn(r)!r}\n')
    print(f"{rounds} interleaved rounds, `ALFD_BENCH_SCALE=0.3`; medians, the range in parentheses.\n")
    print("| what | fixed-size messages | slices sized per run | ratio |")
    print("|---|---:|---:|---:|")
    for label, f in METRICS:
        o = [f(r) for r in got["old"]]
        n = [f(r) for r in got["new"]]
        mo, mn = statistics.median(o), statistics.median(n)
        print(f"| {label} | {mo:.2f} ({min(o):.2f}-{max(o):.2f}) | {mn:.2f} ({min(n):.2f}-{max(n):.2f}) "
              f"| {mn / mo:.2f} |")


if __name__ == "__main__":
    main()
