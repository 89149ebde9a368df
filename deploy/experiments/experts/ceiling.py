"""How often can three experts be ranked right after n answers each? A simulation of the
experts of the study (each answers the right action, or with probability epsilon a uniformly
random one of the task's actions) under round-robin routing, with two estimates of each expert's quality:

- gold: the share of its answers that are the right action (what no run can see; the ceiling);
- double asks: the share of its double-asked answers that the other expert's answer agrees with
  (the panel's reward from double asks, without the demonstration model's opinion).

Writes results/experts-ranking-ceiling/summary.md and runs.csv (one row per simulated run: its
task, answers per expert, double-ask rate, seed, each expert's two estimates and whether each
estimate ranks the three right). Standard library only; seeded.

    python3 deploy/experiments/experts/ceiling.py
"""

import math
import random
from pathlib import Path

SEEDS = 1000
# task: (epsilon of the good, fair and poor experts, number of actions)
TASKS = {"MountainCar-v0": ([0.1, 0.25, 0.5], 3), "Acrobot-v1": ([0.25, 0.5, 0.75], 3),
         "DeepSea(20)": ([0.1, 0.25, 0.5], 2)}
GOAL_SEEDS, GOAL_RIGHT = 10, 9
EXPERTS = ["good", "fair", "poor"]


def run(eps, actions, double_ask, n, seed):
    """One simulated run until every expert has answered n times: (gold, double-ask) estimates."""
    rng = random.Random(seed)
    k = len(eps)
    answers = [0] * k
    right = [0] * k
    agreed = [0] * k
    doubles = [0] * k

    def answer(i):
        a = rng.randrange(actions) if rng.random() < eps[i] else 0
        answers[i] += 1
        right[i] += a == 0
        return a

    turn = 0
    while min(answers) < n:
        first = turn % k
        turn += 1
        if answers[first] >= n:
            continue
        second = None
        if rng.random() < double_ask:
            others = [j for j in range(k) if j != first and answers[j] < n]
            if others:
                second = min(others, key=lambda j: answers[j])
        a = answer(first)
        if second is not None:
            b = answer(second)
            for i in (first, second):
                agreed[i] += a == b
                doubles[i] += 1
    gold = [right[i] / answers[i] for i in range(k)]
    double = [agreed[i] / doubles[i] if doubles[i] else 0.5 for i in range(k)]
    return gold, double


def ranked(q):
    return all(q[i] > q[i + 1] for i in range(len(q) - 1))


def wilson(hits, n, z=1.96):
    p = hits / n
    centre = (p + z * z / (2 * n)) / (1 + z * z / n)
    half = z * math.sqrt(p * (1 - p) / n + z * z / (4 * n * n)) / (1 + z * z / n)
    return 100 * (centre - half), 100 * (centre + half)


def goal_chance(hits):
    """The chance that at least GOAL_RIGHT of GOAL_SEEDS runs rank right, each with the cell's
    share: how often a study of the issue's size would meet its ranking goal."""
    p = hits / SEEDS
    return sum(math.comb(GOAL_SEEDS, k) * p**k * (1 - p) ** (GOAL_SEEDS - k)
               for k in range(GOAL_RIGHT, GOAL_SEEDS + 1))


def cell(hits):
    lo, hi = wilson(hits, SEEDS)
    return f"{100 * hits / SEEDS:.1f}% [{lo:.1f}, {hi:.1f}]"


def main():
    lines = [
        "# Ranking three experts from n answers each: the ceiling",
        "",
        "Written by `deploy/experiments/experts/ceiling.py` (a simulation, seeded, "
        f"{SEEDS} runs per cell). Each expert answers the right action, or with probability "
        "ε one of the task's actions at random; round-robin routing. \"gold\" ranks by the share "
        "of right answers (no run can see it: the ceiling of any estimate); \"double asks\" by "
        "the share of double-asked answers the other expert agreed with. A cell is the share of "
        "runs whose three estimates are in the true order, with a 95% Wilson interval; each run's "
        "estimates are in `runs.csv`. \"9 of 10\": the chance that at least 9 of 10 runs rank right "
        "with that share (binomial), i.e. that a study of 10 seeds meets the ranking goal.",
        "",
        "| task | ε (good, fair, poor) | answers each | double-ask rate | gold | gold: 9 of 10 "
        "| double asks | double asks: 9 of 10 |",
        "|---|---|---:|---:|---:|---:|---:|---:|",
    ]
    rows = ["task,answers_each,double_ask,seed," + ",".join(
        f"{k}_{e}" for k in ("gold", "double") for e in EXPERTS) + ",gold_ranked_right,double_ranked_right"]
    for task, (eps, actions) in TASKS.items():
        for n, d in [(50, 0.1), (50, 0.5), (50, 1.0), (100, 0.5), (200, 0.5)]:
            gold = double = 0
            for seed in range(SEEDS):
                g, q = run(eps, actions, d, n, seed)
                gold += ranked(g)
                double += ranked(q)
                values = ",".join(f"{v:.6f}" for v in g + q)
                rows.append(f"{task},{n},{d},{seed},{values},{str(ranked(g)).lower()},{str(ranked(q)).lower()}")
            lines.append(
                f"| {task} | {', '.join(map(str, eps))} | {n} | {d} | {cell(gold)} | "
                f"{goal_chance(gold):.2f} | {cell(double)} | {goal_chance(double):.2f} |"
            )
    out = Path(__file__).resolve().parents[3] / "results" / "experts-ranking-ceiling" / "summary.md"
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text("\n".join(lines) + "\n")
    (out.parent / "runs.csv").write_text("\n".join(rows) + "\n")
    print(out.read_text())


if __name__ == "__main__":
    main()
