"""Right moves per greedy evaluation episode in a DeepSea sweep (python3 count.py SWEEP_OUT N
RESULTS_DIR): a greedy episode that misses the treasure returns -0.01/N per move right, one that
reaches it moved right N times. Per run, the mean over its last 10 evaluations; per method, the
mean over the runs with a 95% bootstrap interval (2000 resamples, random.Random(0)). Writes
runs.csv and summary.md."""
import csv
import random
import sys
from pathlib import Path

LAST = 10


def rights(ret, n):
    return n if ret > 0.5 else -ret / (0.01 / n)


def main():
    out, n, results = Path(sys.argv[1]), int(sys.argv[2]), Path(sys.argv[3])
    rows = []
    for method_dir in sorted((out / "runs").iterdir()):
        for run in sorted(method_dir.iterdir(), key=lambda p: int(p.name.split("-")[-1])):
            with open(run / "episodes.csv", newline="") as f:
                evals = [float(r["eval_return"]) for r in csv.DictReader(f) if r["eval_return"]]
            last = evals[-LAST:]
            rows.append((method_dir.name, run.name.split("-")[-1],
                         sum(rights(r, n) for r in last) / len(last),
                         sum(r > 0.5 for r in last)))
    results.mkdir(parents=True, exist_ok=True)
    with open(results / "runs.csv", "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(["method", "seed", "right_moves", "treasure_evaluations"])
        w.writerows((m, s, f"{r:.3f}", t) for m, s, r, t in rows)
    lines = [f"# Right moves per greedy episode, DeepSea({n})", "",
             f"Written by `deploy/experiments/shaping-bias/count.py` from `{out.name}`: per run, "
             f"the mean right moves (of {n}) over its last {LAST} greedy evaluations; per method, "
             "their mean over the runs with a 95% bootstrap interval.", "",
             "| method | runs | right moves | runs whose last 10 evaluations all found the treasure |",
             "|---|---:|---:|---:|"]
    for method in sorted({r[0] for r in rows}):
        values = [r[2] for r in rows if r[0] == method]
        # Each method its own generator: its interval does not move when methods are added.
        rng = random.Random(0)
        means = sorted(sum(rng.choice(values) for _ in values) / len(values) for _ in range(2000))
        found = sum(1 for r in rows if r[0] == method and r[3] == LAST)
        lines.append(f"| {method} | {len(values)} | {sum(values) / len(values):.2f} "
                     f"[{means[49]:.2f}, {means[1949]:.2f}] | {found} |")
    (results / "summary.md").write_text("\n".join(lines) + "\n")
    print("\n".join(lines))


if __name__ == "__main__":
    main()
