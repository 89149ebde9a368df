"""Writes the MountainCar-v0 gate study's experiment files (run from anywhere: python3 make.py VARIANT).

tune.toml: every gate and B = 0 under three head variants, for the tuning seeds
(`alfd sweep --first-seed 1000 --seeds 10`); gates.toml: every gate and B = 0 under the variant
VARIANT the tuning seeds chose, for the reported seeds 0-49.

Each run: the recommended MountainCar preset (60,000 steps, the energy expert, the KRR model as a
potential), a budget of B = 20 spread over the run's 60,000 steps (`query.allowance = "spread"`),
shaping from the first demonstration on (`shaping.min_demos = 1`), greedy evaluation of 20
episodes after every 10 training episodes. The primary metric is the paired difference of the
area under the greedy-evaluation curve against gate `chance` under the same allowance.

The choice, fixed before the tuning runs: the variant whose best state-choosing gate (`js`,
`q-std`, `novelty` or `record`) is furthest ahead of `chance` in mean area on the tuning seeds; that
gate is the one the study's goal names. The oracle (a ceiling) and B = 0 take no part in it.
"""
import sys
from pathlib import Path

GATES = ["chance", "js", "q-std", "novelty", "record", "oracle"]
VARIANTS = {
    "k2": ["agent.heads=2", "agent.prior_scale=0"],
    "k8": ["agent.heads=8", "agent.prior_scale=0"],
    "k8-p3": ["agent.heads=8", "agent.prior_scale=3"],
}
BUDGET = 20
STEPS = 60000
HERE = Path(__file__).resolve().parent
CONFIG = "../../configs/recommended/mountaincar.toml"
COMMON = [
    "query.rule=never",
    f"query.horizon={STEPS}",
    "shaping.min_demos=1",
    "evaluation.every=10",
    "evaluation.episodes=20",
]


def methods(variants):
    out = []
    for v in variants:
        tag = f"-{v}" if len(variants) > 1 else ""
        sets = COMMON + VARIANTS[v]
        out.append((f"never{tag}", f"B = 0{tag}", sets + ["budget.total=0"]))
        for g in GATES:
            label = f"{g} (ceiling){tag}" if g == "oracle" else f"{g}{tag}"
            gate = ["query.allowance=spread", f"query.gate={g}", f"budget.total={BUDGET}"]
            out.append((f"{g}{tag}", label, sets + gate))
    return out


def write(name, title, seeds, variants):
    lines = [
        f"# {title}",
        "# Written by deploy/experiments/mountaincar-gates/make.py.",
        f'title = "{title}"',
        f"seeds = {seeds}",
        'x = "steps"',
        "thresholds = [-180, -150, -130]",
        "last = 20",
        "smooth = 3",
        'legend = "lower-right"',
        "eval_threshold = -130",
        "eval_curves = true",
    ]
    if len(variants) == 1:
        lines.append('baseline = "chance"')
    for m, label, sets in methods(variants):
        quoted = ", ".join(f'"{s}"' for s in sets)
        lines += ["", "[[method]]", f'name = "{m}"', f'label = "{label}"',
                  f'config = "{CONFIG}"', f"set = [{quoted}]"]
    (HERE / name).write_text("\n".join(lines) + "\n")


def main():
    variant = sys.argv[1] if len(sys.argv) > 1 else "k2"
    if variant not in VARIANTS:
        sys.exit(f"unknown variant {variant!r}; one of {', '.join(VARIANTS)}")
    write("tune.toml", "MountainCar-v0 gates under three head variants: tuning seeds", 10,
          list(VARIANTS))
    title = f"MountainCar-v0: where to ask, B = {BUDGET} spread ({variant})"
    write("gates.toml", title, 50, [variant])


main()
