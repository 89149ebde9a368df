"""Writes the DeepSea gate study's experiment files (run from anywhere: python3 make.py BETA).

tune-n10.toml, tune-n30.toml: every gate and B = 0 at three prior scales, for the tuning seeds
(`alfd sweep --first-seed 1000 --seeds 10`); gates-nN.toml for N = 10, 20, 30, 40, 50: every gate
and B = 0 at the prior scale BETA the tuning seeds chose, for the reported seeds 0-49. Each run:
50·N episodes, a budget of B = 2N spread over its N·50·N steps, greedy evaluation after every
episode; the primary metric is the paired difference of the area under the greedy-evaluation curve
against gate `chance` under the same allowance.
"""
import sys
from pathlib import Path

GATES = ["chance", "js", "q-std", "novelty", "record", "oracle"]
HERE = Path(__file__).resolve().parent
CONFIG = "../../configs/deepsea-bootstrapped.toml"


def methods(n, betas):
    episodes = 50 * n
    common = [f"env.size={n}", f"query.horizon={n * episodes}"]
    out = []
    for beta in betas:
        tag = f"-p{beta}" if len(betas) > 1 else ""
        prior = [f"agent.prior_scale={beta}"]
        out.append((f"never{tag}", f"B = 0{tag}", common + prior + ["budget.total=0"]))
        for g in GATES:
            label = f"{g} (ceiling){tag}" if g == "oracle" else f"{g}{tag}"
            sets = common + prior + [f"budget.total={2 * n}", f"query.gate={g}"]
            out.append((f"{g}{tag}", label, sets))
    return episodes, out


def write(name, title, seeds, n, betas):
    episodes, ms = methods(n, betas)
    lines = [
        f"# {title}",
        "# Written by deploy/experiments/deepsea/make.py.",
        f'title = "{title}"',
        f"seeds = {seeds}",
        f"episodes = {episodes}",
        "thresholds = [0.5]",
        "last = 50",
        "smooth = 10",
        'legend = "lower-right"',
        "eval_threshold = 0.5",
        "eval_curves = true",
    ]
    if len(betas) == 1:
        lines.append('baseline = "chance"')
    for m, label, sets in ms:
        quoted = ", ".join(f'"{s}"' for s in sets)
        lines += ["", "[[method]]", f'name = "{m}"', f'label = "{label}"',
                  f'config = "{CONFIG}"', f"set = [{quoted}]"]
    (HERE / name).write_text("\n".join(lines) + "\n")


def main():
    beta = sys.argv[1] if len(sys.argv) > 1 else "1.0"
    for n in (10, 30):
        write(f"tune-n{n}.toml", f"DeepSea({n}) gates at three prior scales: tuning seeds",
              10, n, ["0.3", "1.0", "3.0"])
    for n in (10, 20, 30, 40, 50):
        write(f"gates-n{n}.toml", f"DeepSea({n}): where to ask, B = {2 * n} spread", 50, n, [beta])


main()
