"""Writes the several-experts study's files (run from anywhere: python3 make.py [DOUBLE_ASK |
TASK=DOUBLE_ASK]...).

Three experts of one task at once, a good, a fair and a poor one at costs 10, 2 and 1 per answer
(`alfd expert eval` ranks them good > fair > poor). Each run: the task's recommended preset (for
DeepSea(20), the neural or the Q-table DeepSea preset as PRESET_SETS changes it) with the experts in
`[[experts]]`, B = 150 answers spread over the run's steps (`query.allowance = "spread"`), asked
at state-blind moments (`query.gate = "chance"`: the study is about whom to ask, not where; DeepSea's
Q-tables where their greedy action differs from the optimal expert's, GATES),
shaping from the first demonstration (`shaping.min_demos = 1`), greedy evaluation of 20 episodes
(DeepSea: 1, it is deterministic) after every 10 training episodes. Each task has its own tuned
`expert.double_ask` (`python3 make.py 0.1 deepsea=0.3 deepsea-q=0.1` writes the study's files as run).

Methods: one per route (`best-known` = always the good expert, `cheapest` = always the poor one,
`round-robin`, `interval`, `upper-per-cost`, `escalate` = the poor one, and the next up the cost
ladder where its answer disagrees with the demonstration model, `signal-per-cost` = the most
agreement above chance, squared, per unit of cost), B = 0, and `good-turns-poor`
(round-robin, the good expert answering as the poor one after its 25th answer). Primary metrics: the cost spent when
greedy evaluation first reaches the threshold (Kaplan-Meier median; a run that never reaches it
is censored at its total cost) and the paired difference of the final greedy evaluation against
`best-known`.

Tuning (seeds 1000-1009, `tune-TASK.toml`): `expert.double_ask` in {0.1, 0.3} for `interval` and
`upper-per-cost` (`round-robin` and `good-turns-poor` ask a second expert at the first value;
`best-known`, `cheapest` and `escalate` never at random). The choice, fixed before the tuning runs: the value under which those two
routes together reach the threshold in the most runs, ties broken by the lower mean cost to the
threshold (censored runs at their total cost). The reported seeds 0-29 (`study-TASK.toml`) run
with the chosen value only, and `recovery-TASK.toml` runs `good-turns-poor` with B = 400 on them,
so that the changed expert answers more than 100 times after the change. `tune-routes-TASK.toml`
runs the routes of this project's own (`escalate`, `signal-per-cost`) on the tuning seeds beside
`best-known`, `cheapest`, `round-robin` and `always-fair` (the fair expert always).
"""
import sys
from pathlib import Path

HERE = Path(__file__).resolve().parent
CONFIGS = HERE.parent.parent / "configs"
TASKS = {
    # task: (preset, experts good/fair/poor, steps, evaluation threshold, evaluation episodes)
    "mountaincar": ("recommended/mountaincar.toml", "mountaincar", 60000, -140, 20),
    "acrobot": ("recommended/acrobot.toml", "acrobot", 100000, -100, 20),
    # DeepSea(20) is deterministic: one evaluation episode is exact; the treasure is the threshold.
    "deepsea": ("deepsea-bdqn.toml", "deepsea", 12000, 0.5, 1),
    "deepsea-q": ("deepsea-bootstrapped.toml", "deepsea", 20000, 0.5, 1),
}
# What a task's preset is changed in. DeepSea: the neural DeepSea study's network (separate
# torsos, no margin) at N = 20, where the network alone seldom finds the treasure, for 30 N
# episodes; the demonstration model fitted (for the routes' and the quality estimates' use) but
# shaping nothing (lambda = 0), as the neural DeepSea study shapes nothing.
PRESET_SETS = {
    "deepsea": ["env.size=20", "episodes=600", "agent.shared_torso=false",
                "agent.margin_loss_weight=0", "expert.model=krr", "shaping.kind=paper",
                "shaping.lambda=0"],
    # The Q-tables of the DeepSea gates study at N = 20 (its tuned prior scale), for its
    # 50 N episodes. At N = 20 they reach the treasure with no answers in none of that study's
    # runs, and with answers at state-blind moments in none either; with answers where the greedy
    # action differs from the optimal expert's (gate `oracle`) in all.
    "deepsea-q": ["env.size=20", "episodes=1000", "agent.prior_scale=0.3"],
}
# Where a task asks (default `chance`: state-blind). DeepSea's Q-tables ask at the oracle's
# ceiling of where, so that whom to ask is what the methods change.
GATES = {"deepsea-q": "oracle"}
COSTS = {"good": 10, "fair": 2, "poor": 1}
BUDGET = 150
TURN_AFTER = 25
ROUTES = ["best-known", "cheapest", "round-robin", "interval", "upper-per-cost", "escalate",
          "signal-per-cost"]
# The routes of this project's own, tried on the tuning seeds beside the fixed ones and
# `always-fair` (`best-known` with the fair expert named: not a route, the bar for one that finds it).
OWN = ["escalate", "signal-per-cost"]
TUNED = ["interval", "upper-per-cost"]
# The tasks whose tuning seeds the routes of one's own were tried on (DeepSea came after them).
ROUTE_TUNING_TASKS = ["mountaincar", "acrobot"]
# Routes that never ask a second expert at random (`escalate` asks one by its own rule).
FIXED = ["best-known", "cheapest", "escalate"]


def config(task):
    """The preset with its `[expert]` name left out and the three experts listed."""
    preset, prefix, _, _, _ = TASKS[task]
    lines, section = [], None
    for line in (CONFIGS / preset).read_text().splitlines():
        if line.startswith("["):
            section = line.strip()
        if section == "[expert]" and line.startswith("name ="):
            continue
        lines.append(line)
    head = [f"# The {task} preset with three experts at once.",
            "# Written by deploy/experiments/experts/make.py."]
    if task in PRESET_SETS:
        head.append(f"# The study's methods change the preset in: {', '.join(PRESET_SETS[task])}.")
    # The study fits the demonstration model on every answer alike.
    lines += ["[demos]", 'weighting = "none"', ""]
    for quality, cost in COSTS.items():
        lines += ["", "[[experts]]", f'name = "{prefix}-{quality}"', f"cost = {cost}"]
    (HERE / f"config-{task}.toml").write_text("\n".join(head + lines) + "\n")


def common(task):
    _, prefix, steps, _, evaluation = TASKS[task]
    return PRESET_SETS.get(task, []) + [
        "query.rule=never", f"query.horizon={steps}", "query.allowance=spread",
        f"query.gate={GATES.get(task, 'chance')}",
        f"budget.total={BUDGET}", "shaping.min_demos=1", "evaluation.every=10",
        f"evaluation.episodes={evaluation}", f"expert.best_known={prefix}-good",
    ]


def methods(task, double_asks, routes=ROUTES):
    out = [("never", "B = 0", common(task) + ["budget.total=0"], None)]
    for route in routes:
        # The fixed routes never ask a second expert at random.
        for d in double_asks if route in TUNED else [0 if route in FIXED else double_asks[0]]:
            tag = f"-d{d}" if len(double_asks) > 1 and route in TUNED else ""
            out.append((f"{route}{tag}", f"{route}{tag}",
                        common(task) + [f"expert.route={route}", f"expert.double_ask={d}"], None))
    return out


def write(task, name, title, seeds, double_asks, turn, routes=ROUTES):
    threshold = TASKS[task][3]
    lines = [
        f"# {title}", "# Written by deploy/experiments/experts/make.py.",
        f'title = "{title}"', f"seeds = {seeds}", 'x = "steps"', "last = 20", "smooth = 3",
        'legend = "lower-right"', f"eval_threshold = {threshold}", "eval_curves = true",
        'baseline = "best-known"',
    ]
    ms = methods(task, double_asks, routes)
    if turn:
        ms.append(("good-turns-poor", "good turns poor", common(task) + [
            "expert.route=round-robin", f"expert.double_ask={double_asks[0]}"], f"config-{task}-turns.toml"))
    for m, label, sets, cfg in ms:
        quoted = ", ".join(f'"{s}"' for s in sets)
        lines += ["", "[[method]]", f'name = "{m}"', f'label = "{label}"',
                  f'config = "{cfg or f"config-{task}.toml"}"', f"set = [{quoted}]"]
    (HERE / name).write_text("\n".join(lines) + "\n")


def own_routes(task, double_ask):
    """`tune-routes-TASK.toml`: the routes of this project's own against the fixed ones and
    `always-fair`, on the tuning seeds (run with `--first-seed 1000`)."""
    _, prefix, _, threshold, _ = TASKS[task]
    title = f"{task}: routes of one's own, tuning seeds"
    lines = [
        f"# {title}", "# Written by deploy/experiments/experts/make.py.",
        f'title = "{title}"', "seeds = 10", 'x = "steps"', "last = 20", "smooth = 3",
        'legend = "lower-right"', f"eval_threshold = {threshold}", "eval_curves = true",
        'baseline = "best-known"',
    ]
    ms = [m for m in methods(task, [double_ask])
          if m[0] in ("best-known", "cheapest", "round-robin", *OWN)]
    fair = [s.replace(f"{prefix}-good", f"{prefix}-fair") for s in common(task)]
    ms.append(("always-fair", "always-fair", fair + ["expert.route=best-known",
                                                     "expert.double_ask=0"], None))
    for m, label, sets, _ in ms:
        quoted = ", ".join(f'"{s}"' for s in sets)
        lines += ["", "[[method]]", f'name = "{m}"', f'label = "{label}"',
                  f'config = "config-{task}.toml"', f"set = [{quoted}]"]
    (HERE / f"tune-routes-{task}.toml").write_text("\n".join(lines) + "\n")


def recovery(task, double_ask):
    """The study's `good-turns-poor` with B = 400: the changed expert answers 100 times and more
    after the change (about 25 at B = 150), so that recovery within 100 answers can be seen."""
    threshold = TASKS[task][3]
    sets = [s.replace(f"budget.total={BUDGET}", "budget.total=400") for s in common(task)]
    sets += ["expert.route=round-robin", f"expert.double_ask={double_ask}"]
    title = f"{task}: the good expert turns poor, B = 400"
    quoted = ", ".join(f'"{s}"' for s in sets)
    lines = [
        f"# {title}", "# Written by deploy/experiments/experts/make.py.",
        f'title = "{title}"', "seeds = 30", 'x = "steps"', "last = 20", "smooth = 3",
        'legend = "lower-right"', f"eval_threshold = {threshold}", "eval_curves = true",
        "", "[[method]]", 'name = "good-turns-poor-b400"', 'label = "good turns poor, B = 400"',
        f'config = "config-{task}-turns.toml"', f"set = [{quoted}]",
    ]
    (HERE / f"recovery-{task}.toml").write_text("\n".join(lines) + "\n")


def turns(task):
    """The same experts, the good one answering as the poor one after its 25th answer."""
    prefix = TASKS[task][1]
    text = (HERE / f"config-{task}.toml").read_text()
    good = f'name = "{prefix}-good"\ncost = 10\n'
    assert good in text
    text = text.replace(good, good + f'becomes = "{prefix}-poor"\nafter = {TURN_AFTER}\n')
    (HERE / f"config-{task}-turns.toml").write_text(text)


def chosen_values(args):
    """`VALUE` for every task, or `TASK=VALUE` for some: each task's tuned `expert.double_ask`."""
    chosen = {}
    for arg in args:
        task, _, value = arg.rpartition("=")
        for t in [task] if task else TASKS:
            chosen[t] = float(value)
    return chosen


def main():
    chosen = chosen_values(sys.argv[1:])
    for task in TASKS:
        config(task)
        turns(task)
        # The double-ask tuning's routes (`signal-per-cost` has its own tuning file).
        write(task, f"tune-{task}.toml", f"{task}: three experts, tuning seeds", 10,
              [0.1, 0.3], False, ROUTES[:-1])
        if task in chosen:
            write(task, f"study-{task}.toml", f"{task}: three experts at costs 10/2/1", 30,
                  [chosen[task]], True)
            recovery(task, chosen[task])
            if task in ROUTE_TUNING_TASKS:
                own_routes(task, chosen[task])


if __name__ == "__main__":
    main()
