"""Writes the neural DeepSea study's experiment files (run from anywhere: python3 make.py [TORSO MARGIN]).

tune.toml: DeepSea(10), for the tuning seeds (`alfd sweep --first-seed 1000 --seeds 10`): the
network's heads with a shared torso or separate torsos (`agent.shared_torso`), DQfD's margin loss
on or off (`agent.margin_loss_weight` 1 or 0), each with B = 0 and the gates chance, js and oracle.
choose.py picks the (torso, margin) setting from its rows. gates-nN.toml for N = 10 and 14: B = 0
and every gate at the chosen setting, for the reported seeds 0-49. Each run: 30·N episodes, a
budget of B = N spread over its N·30·N steps, greedy evaluation after every episode; the primary
metric is the paired difference of the area under the greedy-evaluation curve against gate
`chance` under the same allowance.
"""
import sys
from pathlib import Path

GATES = ["chance", "js", "q-std", "novelty", "record", "oracle"]
TUNE_GATES = ["chance", "js", "oracle"]
HERE = Path(__file__).resolve().parent
CONFIG = "../../configs/deepsea-bdqn.toml"


def setting(torso, margin):
    return [f"agent.shared_torso={torso}", f"agent.margin_loss_weight={margin}"]


def methods(n, settings, gates):
    episodes = 30 * n
    common = [f"env.size={n}", f"query.horizon={n * episodes}"]
    out = []
    for torso, margin in settings:
        tag = f"-{'shared' if torso == 'true' else 'separate'}-m{margin}" if len(settings) > 1 else ""
        s = common + setting(torso, margin)
        out.append((f"never{tag}", f"B = 0{tag}", s + ["budget.total=0"]))
        for g in gates:
            label = f"{g} (ceiling){tag}" if g == "oracle" else f"{g}{tag}"
            out.append((f"{g}{tag}", label, s + [f"budget.total={n}", f"query.gate={g}"]))
    return episodes, out


def write(name, title, seeds, n, settings, gates):
    episodes, ms = methods(n, settings, gates)
    lines = [
        f"# {title}",
        "# Written by deploy/experiments/deepsea-neural/make.py.",
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
    if len(settings) == 1:
        lines.append('baseline = "chance"')
    for m, label, sets in ms:
        quoted = ", ".join(f'"{s}"' for s in sets)
        lines += ["", "[[method]]", f'name = "{m}"', f'label = "{label}"',
                  f'config = "{CONFIG}"', f"set = [{quoted}]"]
    (HERE / name).write_text("\n".join(lines) + "\n")


def main():
    grid = [(t, m) for t in ("true", "false") for m in ("0", "1")]
    write("tune.toml", "Neural DeepSea(10): torso and margin, tuning seeds", 10, 10, grid, TUNE_GATES)
    if len(sys.argv) > 2:
        chosen = [(sys.argv[1], sys.argv[2])]
        for n in (10, 14):
            write(f"gates-n{n}.toml", f"Neural DeepSea({n}): where to ask, B = {n} spread", 50, n,
                  chosen, GATES)


main()
