"""Whom each route asked (python3 answers.py SWEEP_OUT PREFIX RESULTS_DIR): per method of a
several-experts sweep, the mean number of answers of each expert per run and in how many runs
each was the one asked most, from the runs' `demos.jsonl` (runs that asked no one left out).
Writes answers.md and answers.csv (per run: method, seed, answers of good, fair and poor)."""
import json
import sys
from collections import Counter
from pathlib import Path

QUALITIES = ("good", "fair", "poor")


def counts(path, prefix):
    c = Counter()
    with open(path) as f:
        for line in f:
            c[json.loads(line)["expert"]] += 1
    return [c[f"{prefix}-{q}"] for q in QUALITIES]


def main():
    out, prefix, results = Path(sys.argv[1]), sys.argv[2], Path(sys.argv[3])
    rows, table = ["method,seed,good,fair,poor"], []
    for method in sorted(p for p in (out / "runs").iterdir() if p.is_dir()):
        runs = [(run.name, counts(run / "demos.jsonl", prefix))
                for run in sorted(method.iterdir(), key=lambda p: int(p.name))
                if (run / "demos.jsonl").is_file()]
        # B = 0 asks no one.
        runs = [(seed, c) for seed, c in runs if sum(c)]
        if not runs:
            continue
        rows += [",".join([method.name, seed, *map(str, c)]) for seed, c in runs]
        # The expert asked most in each run (the better of equals).
        most = Counter(QUALITIES[max(range(3), key=lambda i: (c[i], -i))] for _, c in runs)
        means = [sum(c[i] for _, c in runs) / len(runs) for i in range(3)]
        table.append((method.name, len(runs), means, most))
    results.mkdir(parents=True, exist_ok=True)
    (results / "answers.csv").write_text("\n".join(rows) + "\n")
    md = [f"# Whom each route asked ({prefix})", "",
          f"Written by `deploy/experiments/experts/answers.py` from `{out.name}`'s `demos.jsonl` "
          "files; per run in `answers.csv`. Answers per run, mean over the runs, and the runs "
          "in which each expert answered most (the better expert of equals).", "",
          "| method | runs | good | fair | poor | most: good | most: fair | most: poor |",
          "|---|---:|---:|---:|---:|---:|---:|---:|"]
    for name, n, means, most in table:
        md.append(f"| {name} | {n} | " + " | ".join(f"{m:.1f}" for m in means) + " | "
                  + " | ".join(f"{most[q]} of {n}" for q in QUALITIES) + " |")
    (results / "answers.md").write_text("\n".join(md) + "\n")
    print("\n".join(md))


if __name__ == "__main__":
    main()
