"""The answer waits of deploy/bench/refit.sh: each setup's `alfd run` once per round (rounds
interleaved, seed = round), the waits the actor logs when it stops (`answer_wait_p50_ms`,
`answer_wait_p99_ms`, `answer_wait_max_ms`: from asking to the answer in hand, over every
answered query), and the run's learner updates per second. Writes OUT/summary.md and
OUT/results.json.
"""

import argparse
import json
import os
import re
import statistics
import subprocess
import tempfile

import host

CONFIG = "deploy/configs/cartpole-bdqn-krr.toml"
PRIOR_STEPS = 9000
BUDGET = 500
EPISODES = 600
# The query path's threads at the system's default slice instead of their short one.
DEFAULT_SLICE = {"ALFD_QUERY_SLICE_US": "0"}
# (name, with the dataset, --refit, config overrides, environment)
SETUPS = [
    ("no model, no dataset (no refits)", False, "inline", ["expert.model=none"], {}),
    ("no dataset, refits inline (up to 500 rows)", False, "inline", [], {}),
    ("9,000-step dataset, refits inline", True, "inline", [], {}),
    ("9,000-step dataset, refits in the background", True, "background", [], {}),
    ("the same, the query path at the default slice", True, "background", [], DEFAULT_SLICE),
]
WAITS = ("answers", "answer_wait_p50_ms", "answer_wait_p99_ms", "answer_wait_max_ms")


def make_dataset(alfd, tmp):
    """9 CartPole-1000 episodes in which the preset's expert takes every action, as a Minari
    dataset (no model is fitted while they are recorded)."""
    run = os.path.join(tmp, "expert-run")
    subprocess.run(
        [alfd, "local", "--config", CONFIG, "--quiet", "--transitions", "--set", "seed=9100",
         "--set", "steps=0", "--set", f"episodes={PRIOR_STEPS // 1000}", "--set",
         "query.rule=uniform", "--set", "query.probability=1.0", "--set",
         f"budget.total={PRIOR_STEPS}", "--set", "expert.model=none", "--out", run],
        check=True, capture_output=True)
    out = os.path.join(tmp, "datasets", "alfd", "cartpole-expert-v0")
    subprocess.run([alfd, "demos", "export", run, "--out", out], check=True, capture_output=True)
    return out


def one_run(alfd, tmp, dataset, refit, sets, env, seed, tag):
    out = os.path.join(tmp, f"run-{tag}-{seed}")
    cmd = [alfd, "run", "--config", CONFIG, "--quiet", "--json", "--actors", "1",
           "--refit", refit, "--set", f"seed={seed}", "--set", f"episodes={EPISODES}",
           "--set", f"budget.total={BUDGET}", "--set", "query.rule=uniform",
           "--set", "query.probability=0.05", "--out", out]
    if dataset:
        cmd += ["--set", f"demos.prior={dataset}"]
    for s in sets:
        cmd += ["--set", s]
    summary = json.loads(subprocess.run(cmd, check=True, capture_output=True, text=True,
                                        env=os.environ | env).stdout)
    with open(os.path.join(out, "actor-0.log")) as f:
        line = next(l for l in f if "actor stopping" in l)
    waits = {k: float(re.search(rf"\b{k}=([0-9.e+-]+)", line).group(1)) for k in WAITS}
    return waits | {"updates_per_s": summary["updates_per_s"], "wall_clock_s": summary["wall_clock_s"]}


def span(xs, fmt):
    return f"{fmt(statistics.median(xs))} ({fmt(min(xs))}-{fmt(max(xs))})"


def write(results, out):
    runs = results["runs"]
    ms = lambda x: f"{x:.2f} ms"  # noqa: E731
    base = statistics.median(r["answer_wait_p99_ms"] for r in runs[SETUPS[0][0]])
    lines = [
        "# Answers while the model refits",
        "",
        "Written by `bash deploy/bench/refit.sh`; every number is in `results.json`.",
        "",
        "## Machine",
        "",
        f"{results['machine']}; {results['date']}; load average {results['load_before']:.2f} "
        f"before; {results['rounds']} rounds, each figure the median (min-max) over them.",
        "",
        "## Answer waits with refits running",
        "",
        f"`alfd run` on `{CONFIG}` with one actor, B = {BUDGET} asked uniformly (probability "
        f"0.05 a step), {EPISODES} episodes, the exact KRR model; with the dataset, "
        f"`demos.prior` holds {PRIOR_STEPS:,} steps of the preset's expert, so every refit grows "
        "a factor of over 9,000 rows (its cost: \"One more demonstration\" of the core "
        "benchmarks). The wait is the "
        "actor's, from asking to the answer in hand (`answer_wait_*` in `actor-0.log`), over "
        "every answered query of a run; \"p99 / no refits\" divides the median p99 by the "
        "first row's, whose expert keeps no model (`expert.model = \"none\"`). The actor's "
        "and the expert's main threads ask Linux's EEVDF scheduler for a 100 µs slice, so that "
        "a query or an answer preempts the learner or a refit at once; the last row sets "
        "`ALFD_QUERY_SLICE_US=0`, which leaves them at the system's default slice.",
        "",
        "| setup | answers | p50 wait | p99 wait | max wait | p99 / no refits | learner updates/s |",
        "|---|---:|---:|---:|---:|---:|---:|",
    ]
    for name, *_ in SETUPS:
        rs = runs[name]
        p99 = statistics.median(r["answer_wait_p99_ms"] for r in rs)
        lines.append(
            f"| {name} | {statistics.median(r['answers'] for r in rs):.0f} | "
            f"{span([r['answer_wait_p50_ms'] for r in rs], ms)} | "
            f"{span([r['answer_wait_p99_ms'] for r in rs], ms)} | "
            f"{span([r['answer_wait_max_ms'] for r in rs], ms)} | {p99 / base:.1f} | "
            f"{span([r['updates_per_s'] for r in rs], lambda x: f'{x:,.0f}')} |")
    with open(os.path.join(out, "summary.md"), "w") as f:
        f.write("\n".join(lines) + "\n")


def main():
    p = argparse.ArgumentParser()
    p.add_argument("--alfd", required=True)
    p.add_argument("--out", required=True)
    p.add_argument("--rounds", type=int, default=3)
    a = p.parse_args()
    os.makedirs(a.out, exist_ok=True)
    load = os.getloadavg()[0]
    m = host.machine()
    runs = {name: [] for name, *_ in SETUPS}
    with tempfile.TemporaryDirectory(prefix="alfd-bench-refit-") as tmp:
        print("refit.py: the 9,000-step dataset", flush=True)
        dataset = make_dataset(a.alfd, tmp)
        for r in range(a.rounds):
            print(f"refit.py: round {r + 1} of {a.rounds}", flush=True)
            order = SETUPS if r % 2 == 0 else list(reversed(SETUPS))
            for i, (name, prior, refit, sets, env) in enumerate(order):
                data = dataset if prior else None
                runs[name].append(one_run(a.alfd, tmp, data, refit, sets, env, r, i))
    results = {"machine": host.described(m), "date": m["date"], "load_before": load,
               "rounds": a.rounds, "runs": runs}
    with open(os.path.join(a.out, "results.json"), "w") as f:
        json.dump(results, f, indent=1)
    write(results, a.out)
    print(f"refit.py: wrote {a.out}/summary.md and results.json", flush=True)


if __name__ == "__main__":
    main()
