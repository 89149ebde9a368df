"""Chooses the neural DeepSea study's setting from the tuning seeds' rows (python3 choose.py RUNS_CSV).

The rule, fixed before the tuning runs: of the four (torso, margin) settings, the one whose runs
of the gates chance, js and oracle have the highest mean area under the greedy-evaluation curve
(`eval_auc`), pooled over gates and seeds. Prints the table and `CHOSEN torso margin`
(torso `true` = shared) for make.py.
"""
import csv
import sys
from collections import defaultdict


def main():
    rows = list(csv.DictReader(open(sys.argv[1])))
    auc = defaultdict(list)
    for r in rows:
        gate, torso, margin = r["method"].split("-")
        if gate != "never":
            auc[(torso, margin)].append(float(r["eval_auc"]))
    print("| torso | margin | runs | mean eval_auc |\n|---|---|---:|---:|")
    for (torso, margin), v in sorted(auc.items()):
        print(f"| {torso} | {margin[1:]} | {len(v)} | {sum(v) / len(v):.4f} |")
    torso, margin = max(auc, key=lambda k: sum(auc[k]) / len(auc[k]))
    print(f"\nCHOSEN {'true' if torso == 'shared' else 'false'} {margin[1:]}")


main()
