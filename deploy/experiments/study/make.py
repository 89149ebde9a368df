#!/usr/bin/env python3
"""Writes the experiment files of the query-rule study ("Does asking pay?" in EXPERIMENTS.md).

Every rule at every budget on one task's recommended preset, the only change being the rule and
B. `random` replays the query steps of the `js` run of the same budget and the sweep's next seed
(`{out}` is the sweep's output directory, `{other_seed}` its next seed): the same number of
queries at the same times, at states unrelated to the heads' disagreement. `js-paced` keeps at
least 100 / (100 - p_r) steps between queries, uniform's mean spacing; `js-spread` allows the
(n+1)-th demonstration from step n·H/B (H the run's steps), B spread evenly over the run, and
`random-spread` is its matched control (js-spread's query steps of the next seed). (Replaying the js run
of the same seed reproduces that run: every state up to the first query is the same, so the same
states are asked about.) `uniform` asks with probability
(100 - p_r) / 100, the rate the percentile gate of the disagreement rules aims at. The burst
length of `js-burst` was chosen on tuning seeds 1000-1004 (EXPERIMENTS.md gives the screen).

Run: python3 deploy/experiments/study/make.py  (rewrites the files next to this script)
"""
from pathlib import Path

HERE = Path(__file__).resolve().parent
RULES = ["first", "js", "random", "uniform", "q-std", "novelty", "js-burst", "js-paced", "js-spread",
         "random-spread"]
BUDGETS = [10, 25, 50, 100, 200]
BURST = 30
# CliffWalk's runs are limited by episodes: js-spread spreads B over 100,000 steps, about what
# 3,000 episodes take without demonstrations (101,686 to 284,699 steps, median 114,072, on
# tuning seeds 1000-1004).
CLIFFWALK_HORIZON = 100_000

TASKS = {
    # name: (title, preset, x, thresholds, last, p_r, eval threshold)
    "mountaincar": ("MountainCar-v0, 60,000 steps", "../../configs/recommended/mountaincar.toml",
                    "steps", [-180, -150, -130], 20, 99.0, -130),
    "acrobot": ("Acrobot-v1, 100,000 steps", "../../configs/recommended/acrobot.toml",
                "steps", [-150, -120, -100], 20, 95.0, -100),
    "cartpole": ("CartPole-1000, 50,000 steps", "../../configs/recommended/cartpole.toml",
                 "steps", [200, 500, 900], 20, 99.0, 900),
    "cliffwalk": ("CliffWalk, 3,000 episodes", "../../configs/cliffwalk-bootstrapped.toml",
                  "episodes", [-20, 0, 1], 50, 90.0, None),
}


def methods(task, budgets, rules, burst=BURST):
    _, preset, _, _, _, p_r, _ = TASKS[task]
    out = [("never", "never (B = 0)", ["query.rule=never", "budget.total=0", "query.burst=10"])]
    for b in budgets:
        for rule in rules:
            s = [f"query.rule={rule}", f"budget.total={b}"]
            if rule == "random":
                s.append(f"query.schedule={{out}}/runs/js-b{b}/{{other_seed}}/demos.jsonl")
            if rule == "random-spread":
                # js-spread's matched control: its query steps, at unrelated states.
                s[0] = "query.rule=random"
                s.append(f"query.schedule={{out}}/runs/js-spread-b{b}/{{other_seed}}/demos.jsonl")
            if rule == "uniform":
                s.append(f"query.probability={(100 - p_r) / 100}")
            # Every method names its burst length: js-burst's, and the default 10 for the rules
            # that do not read it, whatever the preset says.
            s.append(f"query.burst={burst if rule == 'js-burst' else 10}")
            if rule == "js-paced":
                s.append(f"query.gap={round(100 / (100 - p_r))}")
            if rule == "js-spread" and task == "cliffwalk":
                s.append(f"query.horizon={CLIFFWALK_HORIZON}")
            out.append((f"{rule}-b{b}", f"{rule}, B = {b}", s))
    return preset, out


def write(path, title, task, seeds, preset, ms, comment):
    _, _, x, thresholds, last, _, eval_threshold = TASKS[task]
    lines = [f"# {comment}", "# Written by deploy/experiments/study/make.py.",
             f'title = "{title}"', f"seeds = {seeds}", f'x = "{x}"',
             f"thresholds = {thresholds}", f"last = {last}", "smooth = 3",
             'legend = "lower-right"']
    if eval_threshold is not None:
        lines.append(f"eval_threshold = {eval_threshold}")
    if not path.name.startswith("screen"):
        lines.append("by_budget = true")
    if not path.name.startswith("screen-burst"):
        lines.append("learner_episodes_only = true")
        if eval_threshold is not None:
            lines.append("eval_curves = true")
    for name, label, s in ms:
        sets = ", ".join(f'"{v}"' for v in s)
        lines += ["", "[[method]]", f'name = "{name}"', f'label = "{label}"',
                  f'config = "{preset}"', f"set = [{sets}]"]
    path.write_text("\n".join(lines) + "\n")


# Every task at every budget.
TASK_BUDGETS = {}
# The headline comparisons: one budget, 30 seeds (0-29).
HEADLINE = {"mountaincar": 10, "acrobot": 10, "cliffwalk": 10, "cartpole": 10}


def main():
    for task, (title, *_rest) in TASKS.items():
        budgets = TASK_BUDGETS.get(task, BUDGETS)
        preset, ms = methods(task, budgets, RULES)
        write(HERE / f"{task}.toml", f"Query rules: {title}", task, 10, preset, ms,
              f"Every query rule at B in {budgets} on the {task} preset, 10 seeds (0-9).")
    for task, b in HEADLINE.items():
        title = TASKS[task][0]
        preset, ms = methods(task, [b], RULES)
        write(HERE / f"{task}-headline.toml", f"Query rules at B = {b}: {title}", task, 30,
              preset, ms, f"Every query rule at B = {b} on the {task} preset, 30 seeds (0-29).")
    screen_rules()
    prior_study()
    for task in ["mountaincar", "acrobot"]:
        title = TASKS[task][0]
        preset = TASKS[task][1]
        ms = [("js-b100", "js, B = 100", ["query.rule=js", "budget.total=100"]),
              ("first-b100", "first, B = 100", ["query.rule=first", "budget.total=100"])]
        for burst in [3, 10, 30]:
            ms.append((f"js-burst{burst}-b100", f"js-burst {burst}, B = 100",
                       ["query.rule=js-burst", "budget.total=100", f"query.burst={burst}"]))
        write(HERE / f"screen-burst-{task}.toml", f"Burst-length screen: {title}", task, 5,
              preset, ms, "The burst length of js-burst, screened on tuning seeds 1000-1004.")


# The presets' rule, chosen on tuning seeds 1000-1009 at each preset's budget: the rules that do
# best in the study, and js with randomized prior functions of three scales.
PRESET_BUDGET = {"mountaincar": 100, "acrobot": 100, "cartpole": 300}
PRIOR_SCALES = [3, 10, 30]


def screen_rules():
    for task, b in PRESET_BUDGET.items():
        title = TASKS[task][0]
        preset, ms = methods(task, [b], ["first", "js", "uniform", "js-burst", "js-paced",
                                         "js-spread"])
        for scale in PRIOR_SCALES:
            ms.append((f"js-prior{scale}-b{b}", f"js, prior {scale}, B = {b}",
                       ["query.rule=js", f"budget.total={b}", f"agent.prior_scale={scale}",
                        "query.burst=10"]))
        write(HERE / f"screen-rules-{task}.toml", f"Rule screen at B = {b}: {title}", task, 10,
              preset, [m for m in ms if m[0] != "never"],
              "The presets' query rule, screened on tuning seeds 1000-1009.")


# Randomized prior functions on held-out seeds 0-9: the scale that did best on the tuning seeds
# (screen-rules-*) against the plain js rule, at three budgets.
PRIOR_SCALE = 30


def prior_study():
    for task in ["mountaincar", "acrobot"]:
        title = TASKS[task][0]
        preset, _ = methods(task, [], [])
        ms = []
        for b in [10, 50, 100]:
            ms.append((f"js-b{b}", f"js, B = {b}", ["query.rule=js", f"budget.total={b}"]))
            ms.append((f"js-prior-b{b}", f"js + prior {PRIOR_SCALE}, B = {b}",
                       ["query.rule=js", f"budget.total={b}", f"agent.prior_scale={PRIOR_SCALE}"]))
        write(HERE / f"prior-{task}.toml", f"Randomized prior functions: {title}", task, 10,
              preset, ms, f"The js rule with and without prior functions (scale {PRIOR_SCALE}), "
              "10 seeds (0-9).")


if __name__ == "__main__":
    main()
