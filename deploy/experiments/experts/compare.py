"""The several-experts study's goals from a sweep's runs.csv (python3 compare.py SWEEP_OUT RESULTS_DIR):
per route, the Kaplan-Meier median cost until greedy evaluation first reaches the threshold
against `best-known`'s, as a ratio with a 95% paired bootstrap interval (the seeds resampled,
each keeping its pair; 2000 resamples, random.Random(0)), and the final greedy evaluation's
paired difference against `cheapest` and against `best-known`. Writes compare.md."""
import csv
import random
import sys
from pathlib import Path

RESAMPLES = 2000


def km_median(runs):
    """The Kaplan-Meier median of (time, reached) pairs; None when the share still waiting
    never falls to one half (as the lab's `km_median`)."""
    runs = sorted(runs, key=lambda r: (r[0], not r[1]))
    at_risk, surviving, i = len(runs), 1.0, 0
    while i < len(runs):
        t = runs[i][0]
        same = [r for r in runs[i:] if r[0] == t]
        events = sum(1 for r in same if r[1])
        if events:
            surviving *= 1 - events / at_risk
            if surviving <= 0.5:
                return t
        at_risk -= len(same)
        i += len(same)
    return None


def cost_time(row):
    reached = row["reached"] == "true"
    return (float(row["cost_to_threshold"] if reached else row["cost"]), reached)


def percentile(values, q):
    v = sorted(values)
    k = (len(v) - 1) * q
    lo, hi = int(k), min(int(k) + 1, len(v) - 1)
    return v[lo] + (v[hi] - v[lo]) * (k - lo)


def interval(stat, seeds, rng):
    values = []
    for _ in range(RESAMPLES):
        sample = [rng.choice(seeds) for _ in seeds]
        v = stat(sample)
        if v is not None:
            values.append(v)
    if len(values) < RESAMPLES * 0.975:
        return None
    return percentile(values, 0.025), percentile(values, 0.975)


def fmt(v, ci, signed=False):
    f = "{:+.2f}" if signed else "{:.2f}"
    if v is None:
        return "–"
    tail = "not bounded" if ci is None else f"[{f.format(ci[0])}, {f.format(ci[1])}]"
    return f"{f.format(v)} {tail}"


def main():
    out, results = Path(sys.argv[1]), Path(sys.argv[2])
    rows = list(csv.DictReader(open(out / "runs.csv", newline="")))
    by = {}
    for r in rows:
        by.setdefault(r["method"], {})[int(r["seed"])] = r
    best, cheap = by["best-known"], by["cheapest"]
    md = ["# Several experts: cost to the threshold and final evaluation", "",
          f"Written by `deploy/experiments/experts/compare.py` from `{out.name}/runs.csv`. "
          "\"cost ratio\": the Kaplan-Meier median cost until greedy evaluation first reaches the "
          "threshold (a run that never does counted as still waiting at its total cost), over "
          "`best-known`'s; \"final\": the paired difference of the last greedy evaluation. 95% paired "
          f"bootstrap intervals over the seeds ({RESAMPLES} resamples); \"not bounded\": in more "
          "than 2.5% of the resamples a median was not reached.", "",
          "| method | median cost | cost ratio to best-known | final − best-known | final − cheapest |",
          "|---|---:|---:|---:|---:|"]
    for method, runs in by.items():
        if method == "never":
            continue
        seeds = sorted(set(runs) & set(best) & set(cheap))
        rng = random.Random(0)

        def ratio(sample):
            a = km_median([cost_time(runs[s]) for s in sample])
            b = km_median([cost_time(best[s]) for s in sample])
            return None if a is None or b is None or b == 0 else a / b

        def diff(other):
            return lambda sample: sum(float(runs[s]["final_eval"]) - float(other[s]["final_eval"])
                                      for s in sample) / len(sample)

        med = km_median([cost_time(runs[s]) for s in seeds])
        cells = [fmt(ratio(seeds), interval(ratio, seeds, rng))]
        for other in (best, cheap):
            d = diff(other)
            cells.append("–" if other is runs else fmt(d(seeds), interval(d, seeds, rng), True))
        md.append(f"| {method} | {'not reached' if med is None else f'{med:g}'} | " + " | ".join(cells) + " |")
    results.mkdir(parents=True, exist_ok=True)
    (results / "compare.md").write_text("\n".join(md) + "\n")
    print("\n".join(md))


if __name__ == "__main__":
    main()
