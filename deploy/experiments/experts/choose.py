"""Applies the tuning rule of make.py to the tuning sweeps' runs.csv files and prints the choice
(python3 choose.py TUNE_OUT_DIR...): per `expert.double_ask` value, the runs of `interval` and
`upper-per-cost` over every task that reached the threshold, and their mean cost to it (a run
that never reached it counted at its total cost); the most reached wins, ties by lower cost."""
import csv
import sys
from collections import defaultdict

TUNED = ("interval-d", "upper-per-cost-d")


def main():
    reached, costs = defaultdict(int), defaultdict(list)
    for out in sys.argv[1:]:
        with open(f"{out}/runs.csv", newline="") as f:
            for r in csv.DictReader(f):
                for prefix in TUNED:
                    if r["method"].startswith(prefix):
                        d = r["method"][len(prefix):]
                        hit = r["reached"] == "true"
                        reached[d] += hit
                        costs[d].append(float(r["cost_to_threshold"] if hit else r["cost"]))
    lines = [f"double_ask {d}: {reached[d]} of {len(costs[d])} runs reached, "
             f"mean cost {sum(costs[d]) / len(costs[d]):.1f}" for d in sorted(costs)]
    best = min(costs, key=lambda d: (-reached[d], sum(costs[d]) / len(costs[d])))
    print("\n".join(lines + [f"chosen: expert.double_ask = {best}"]))


if __name__ == "__main__":
    main()
