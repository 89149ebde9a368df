"""The power of the gate studies: for each gate against `chance` under the same allowance, the
paired differences of the area under the greedy-evaluation curve by seed, their mean, standard
deviation and the smallest true mean difference the study would detect with 80% power at the
5% level (two-sided, normal approximation: (1.96 + 0.84) * sd / sqrt(n)).

Run from the repository's root: python3 deploy/experiments/power.py > results/gate-power.md
"""
import csv
import math
import statistics as st

STUDIES = [("MountainCar-v0", "results/mountaincar-gates/runs.csv")] + [
    (f"DeepSea({n})", f"results/deepsea-gates/n{n}/runs.csv") for n in (10, 20, 30, 40, 50)
]
GATES = ["js", "q-std", "novelty", "record", "oracle"]


def rows(path):
    by = {}
    for r in csv.DictReader(open(path)):
        by.setdefault(r["method"], {})[r["seed"]] = float(r["eval_auc"])
    return by


def main():
    print(__doc__.split("\n\n")[0].replace("\n", " ").strip() + "\n")
    print("| task | gate | seeds | mean difference | sd | detectable with 80% power |")
    print("|---|---|---:|---:|---:|---:|")
    for task, path in STUDIES:
        by = rows(path)
        chance = by["chance"]
        for g in GATES:
            d = [by[g][s] - chance[s] for s in by[g] if s in chance]
            sd = st.stdev(d)
            mde = (1.96 + 0.84) * sd / math.sqrt(len(d))
            label = f"{g} (ceiling)" if g == "oracle" else g
            print(f"| {task} | {label} | {len(d)} | {st.mean(d):+.3f} | {sd:.3f} | {mde:.3f} |")


main()
