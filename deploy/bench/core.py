"""The core benchmarks of deploy/bench/core.sh: the train step's CPU time per step, the
demonstration model (fit on B demonstrations, then 100 queries) against scikit-learn, and KRR's
cost of one more demonstration (grown against fitted anew), measured interleaved in one sitting. Writes OUT/summary.md (the tables BENCHMARKS.md shows) and
OUT/results.json (every measurement).

Ours is the whole `alfd demo-model` command (start, read, fit, 100 queries, print); scikit-learn's
is the fit and the predictions in this process (reading the same files, after its import), so the
ratio leans in scikit-learn's favour by our process start.
"""

import argparse
import json
import os
import random
import statistics
import subprocess
import tempfile
import time

import numpy as np
import sklearn
from sklearn.kernel_ridge import KernelRidge
from sklearn.svm import SVC

import host

ALFD = "target/release/alfd"
TRAIN_STEPS = "target/release/examples/train_steps"
KRR_GROW = "target/release/examples/krr_grow"
NYSTROM = "target/release/examples/nystrom_agreement"
# Demonstrations of the approximate model's table (the exact model up to 10,000 of them).
NYSTROM_SIZES = [1000, 3000, 10000, 100000]
GROWN = 10
SIZES = [500, 1000, 2000, 3000, 10000]
SVM_SIZES = [500, 1000, 3000, 10000]
# KRR grown by one from B: B + GROWN demonstrations at most (the exact model's limit, 10,000).
GROW_SIZES = [500, 1000, 2000, 3000, 9990]
QUERIES = 100
# Below this many demonstrations a fit and its queries take tens of milliseconds, where this
# virtual machine's speed varies by as much from one command to the next: each round's figure is
# then the median of SMALL_REPEATS runs, for ours and scikit-learn's alike.
SMALL_BELOW = 2000
SMALL_REPEATS = 5
# The train steps timed: name -> (arguments after N, steps per run, hidden, heads, batch, double).
TRAIN_SHAPES = {
    "hidden 64": (["64"], 20000, 64, 2, 64, False),
    "hidden 128": (["128"], 10000, 128, 2, 64, False),
    "preset": (["preset"], 2000, 128, 4, 128, True),
}
PEAK_ROUNDS = 100_000_000


def machine():
    return host.machine() | {"scikit_learn": sklearn.__version__, "numpy": np.__version__}


cpu_seconds = host.cpu_seconds


def step_flops(hidden, heads, batch, double, obs=4, actions=2):
    """Flops of the products of one train step (2 per multiply-add): the forward passes (online
    on the states, target on the next states, and online on the next states for double DQN)
    and the backward pass (every weight's gradient, the input gradients of the two upper
    layers; the first layer's input gradient is not computed)."""
    out = heads * actions
    forward = obs * hidden + hidden * hidden + hidden * out
    backward = forward + hidden * hidden + hidden * out
    return 2 * batch * ((3 if double else 2) * forward + backward)


def product(m, k, n):
    """The flops of an `(m, k) x (k, n)` product and whether it is fused (`nn::mlp`: every
    dimension above 5 goes to the FMA kernels, the others multiply and add apart)."""
    return 2 * m * k * n, m > 5 and k > 5 and n > 5


def part_flops(hidden, heads, batch, double, obs=4, actions=2):
    """The fused and the thin flops of one forward pass and of the backward pass."""
    out = heads * actions
    forward = [product(batch, obs, hidden), product(batch, hidden, hidden),
               product(batch, hidden, out)]
    backward = [product(hidden, batch, out), product(batch, out, hidden),
                product(hidden, batch, hidden), product(batch, hidden, hidden),
                product(obs, batch, hidden)]

    def split(products):
        return {"fused": sum(f for f, fused in products if fused),
                "thin": sum(f for f, fused in products if not fused)}

    return {"forward": split(forward), "backward": split(backward)}


def at_peak_us(flops, peak):
    """Microseconds of `flops` at the peak: fused multiply-adds at it, a rounded multiply and an
    add (two instructions for the two flops) at half of it."""
    return (flops["fused"] + 2 * flops["thin"]) / peak * 1e6


def peak_flops():
    """One core's f32 FMA peak now, in flops per second of CPU time (`host.fma_peak`)."""
    return host.fma_peak(TRAIN_STEPS, PEAK_ROUNDS)


def states(n, rng):
    """CartPole-like states, and a sensible expert's actions on them."""
    xs = [
        [rng.uniform(-2.4, 2.4), rng.uniform(-3, 3), rng.uniform(-0.21, 0.21), rng.uniform(-3.5, 3.5)]
        for _ in range(n)
    ]
    return xs, [int(s[2] + 0.5 * s[3] > 0) for s in xs]


def write_jsonl(path, rows):
    with open(path, "w") as f:
        for r in rows:
            f.write(json.dumps(r) + "\n")


def sklearn_krr(demos, queries):
    t = time.perf_counter()
    d = [json.loads(line) for line in open(demos)]
    q = np.array([json.loads(line)["state"] for line in open(queries)])
    x = np.array([r["state"] for r in d])
    y = np.eye(2)[[r["action"] for r in d]]
    raw = KernelRidge(alpha=0.1, kernel="rbf", gamma=0.1).fit(x, y).predict(q)
    return time.perf_counter() - t, raw


def sklearn_svc(demos, queries):
    t = time.perf_counter()
    d = [json.loads(line) for line in open(demos)]
    q = np.array([json.loads(line)["state"] for line in open(queries)])
    x = np.array([r["state"] for r in d])
    y = np.array([r["action"] for r in d])
    SVC(C=10, kernel="rbf", gamma=0.1, probability=True, random_state=0).fit(x, y).predict_proba(q)
    return time.perf_counter() - t


def ours(kind, demos, queries, threads=None):
    """The whole command, on every core unless `threads` is given."""
    extra = [] if threads is None else ["--threads", str(threads)]
    t = time.perf_counter()
    out = subprocess.run(
        [ALFD, "demo-model", "--kind", kind, "--demos", demos, "--query", queries] + extra,
        check=True,
        capture_output=True,
        text=True,
    ).stdout
    took = time.perf_counter() - t
    return took, [json.loads(line)["raw"] for line in out.splitlines() if line.startswith("{")]


def repeated(n, run):
    """`run()` (a time and an output) once, or SMALL_REPEATS times below SMALL_BELOW
    demonstrations: the median time and the last output."""
    runs = [run() for _ in range(SMALL_REPEATS if n < SMALL_BELOW else 1)]
    return statistics.median(t for t, _ in runs), runs[-1][1]


def span(xs, fmt):
    return f"{fmt(statistics.median(xs))} ({fmt(min(xs))}-{fmt(max(xs))})"


def parts_rows(runs, split, peak):
    """The parts of one shape's step: (part, calls per step, µs per step, flops per step, µs at
    the peak or None), each the median over the rounds."""
    med = lambda key: statistics.median(r[key] for r in runs)  # noqa: E731
    passes = runs[0]["forwards_per_step"]
    fwd, bwd = split["forward"], split["backward"]
    fwd_flops = {k: passes * v for k, v in fwd.items()}
    rows = [
        ("forward pass", passes, passes * med("forward_us"), sum(fwd_flops.values()),
         at_peak_us(fwd_flops, peak)),
        ("backward pass", 1, med("backward_us"), sum(bwd.values()), at_peak_us(bwd, peak)),
        ("Adam", 1, med("adam_us"), 0, None),
    ]
    if med("clip_us") > 0:
        rows.append(("gradient clipping", 1, med("clip_us"), 0, None))
    measured = sum(r[2] for r in rows)
    rows.append(("the rest: the loss, the batch's layout", 1, med("step_us") - measured, 0, None))
    rows.append(("the whole step", 1, med("step_us"), sum(r[3] for r in rows), None))
    return rows


def parts_section(parts, split, flops, peak):
    """The table of where each shape's step goes, and what 75% of the peak leaves."""
    lines = [
        "Each part of the step alone and the whole step, in one process (`train_steps parts "
        "N SHAPE`, with N of the table above: N calls of each, in turns of 100 calls of each "
        "part, wall-clock per call, the median over the rounds); \"the rest\" is the whole "
        "step less the parts. \"At the peak\" is "
        "the time of a part's products at the FMA peak of the table above: fused multiply-adds "
        "at it, and the thin products (a dimension of 5 or less: a rounded multiply and an add, "
        "PyTorch's order) at half of it.",
        "",
        "| step | part | calls per step | time per step | flops per step | of peak | at the peak |",
        "|---|---|---:|---:|---:|---:|---:|",
    ]
    sentences = []
    for name in TRAIN_SHAPES:
        rows = parts_rows(parts[name], split[name], peak)
        for part, calls, us_, fl, best in rows:
            share = f"{100 * fl / (us_ * 1e-6) / peak:.1f}%" if fl and us_ > 0 else ""
            lines.append(
                f"| {name} | {part} | {calls} | {us_:.2f} µs | "
                f"{f'{fl / 1e6:.3f} M' if fl else ''} | {share} | "
                f"{f'{best:.2f} µs' if best is not None else ''} |")
        products = sum(r[4] for r in rows if r[4] is not None)
        others = rows[-1][2] - rows[0][2] - rows[1][2]
        sentences.append(
            f"{name}: 75% of the peak is {flops[name] / (0.75 * peak) * 1e6:.1f} µs a step; "
            f"the products of its forward and backward passes at the peak take "
            f"{products:.1f} µs, and the rest of the step (the whole step less those passes: "
            f"Adam, the loss, the layout) takes {others:.1f} µs as measured.")
    return lines + ["", " ".join(sentences)]


def main():
    p = argparse.ArgumentParser()
    p.add_argument("--out", required=True)
    p.add_argument("--rounds", type=int, default=3)
    args = p.parse_args()
    os.makedirs(args.out, exist_ok=True)
    load_before = os.getloadavg()[0]
    rng = random.Random(20261201)
    tmp = tempfile.mkdtemp(prefix="alfd-bench-core-")
    qs, _ = states(QUERIES, rng)
    queries = os.path.join(tmp, "queries.jsonl")
    write_jsonl(queries, [{"state": s} for s in qs])
    demos = {}
    for n in SIZES:
        xs, acts = states(n, rng)
        demos[n] = os.path.join(tmp, f"demos-{n}.jsonl")
        write_jsonl(demos[n], [{"state": s, "action": a} for s, a in zip(xs, acts)])

    train = {name: [] for name in TRAIN_SHAPES}
    parts = {name: [] for name in TRAIN_SHAPES}
    peak = []
    krr = {n: {"ours": [], "ours_1": [], "sklearn": [], "max_diff": 0.0} for n in SIZES}
    svm = {n: {"ours": [], "ours_1": [], "sklearn": []} for n in SVM_SIZES}
    grow = {n: {"grow": [], "push": [], "model": [], "grow_2": [], "push_2": [], "model_2": [],
                "fit": [], "same_bits": True}
            for n in GROW_SIZES}
    for r in range(args.rounds):
        print(f"core.py: round {r + 1} of {args.rounds}", flush=True)
        peak.append(peak_flops())
        for name, (shape, steps, *_) in TRAIN_SHAPES.items():
            cpu, _ = cpu_seconds([TRAIN_STEPS, str(steps)] + shape)
            train[name].append(cpu / steps * 1e6)
            parts[name].append(json.loads(subprocess.run(
                [TRAIN_STEPS, "parts", str(steps)] + shape,
                check=True, capture_output=True, text=True).stdout))
        for n in SIZES:
            # Alternate which goes first, so neither always meets a warmer cache.
            pair = [("ours", None), ("sklearn", None)]
            for who, _ in pair if r % 2 == 0 else reversed(pair):
                if who == "ours":
                    t, raw_ours = repeated(n, lambda: ours("krr", demos[n], queries))
                    krr[n]["ours_1"].append(
                        repeated(n, lambda: ours("krr", demos[n], queries, threads=1))[0])
                else:
                    t, raw_sk = repeated(n, lambda: sklearn_krr(demos[n], queries))
                krr[n][who].append(t)
            diff = float(np.max(np.abs(np.array(raw_ours) - raw_sk)))
            krr[n]["max_diff"] = max(krr[n]["max_diff"], diff)
        for n in GROW_SIZES:
            out = json.loads(subprocess.run(
                [KRR_GROW, str(n), str(GROWN)], check=True, capture_output=True, text=True
            ).stdout)
            for key in ["grow", "push", "model", "grow_2", "push_2", "model_2"]:
                grow[n][key].append(out[key + "_s"])
            grow[n]["fit"].append(out["fit_s"])
            grow[n]["same_bits"] = grow[n]["same_bits"] and out["same_bits"]
        for n in SVM_SIZES:
            svm[n]["ours"].append(repeated(n, lambda: ours("svm", demos[n], queries))[0])
            svm[n]["ours_1"].append(
                repeated(n, lambda: ours("svm", demos[n], queries, threads=1))[0])
            svm[n]["sklearn"].append(
                repeated(n, lambda: (sklearn_svc(demos[n], queries), None))[0])
    # Once: the approximate model against the exact one (deterministic apart from its times).
    print("core.py: the Nyström model against the exact KRR", flush=True)
    nystrom = [json.loads(line) for line in subprocess.run(
        [NYSTROM] + [str(n) for n in NYSTROM_SIZES], check=True, capture_output=True, text=True
    ).stdout.splitlines()]
    load_after = os.getloadavg()[0]

    m = machine()
    m["load_average_before"] = round(load_before, 2)
    m["load_average_after"] = round(load_after, 2)
    m["rounds"] = args.rounds
    flops = {name: step_flops(*shape[2:]) for name, shape in TRAIN_SHAPES.items()}
    split = {name: part_flops(*shape[2:]) for name, shape in TRAIN_SHAPES.items()}
    results = {"machine": m, "train_step_us": train, "train_step_flops": flops,
               "train_parts_us": parts, "train_parts_flops": split,
               "peak_flops": peak, "krr_s": krr, "svm_s": svm,
               "krr_grow_s": grow, "nystrom": nystrom}
    with open(os.path.join(args.out, "results.json"), "w") as f:
        json.dump(results, f, indent=1, sort_keys=True)

    us = lambda x: f"{x:.1f} µs"  # noqa: E731
    s = lambda x: f"{x:.3f} s"  # noqa: E731
    lines = [
        "# Core benchmarks",
        "",
        "Written by `bash deploy/bench/core.sh`; every number is in `results.json`.",
        "",
        "## Machine",
        "",
        f"{m['cpu']}, {m['cores']} cores, {m['memory_gib']} GiB; {m['date']}; "
        f"load average {m['load_average_before']} before, {m['load_average_after']} after; "
        f"{m['rounds']} rounds, each figure the median (min-max) over them. Peer: scikit-learn "
        f"{m['scikit_learn']}, NumPy {m['numpy']}, Python {m['python']}.",
        "",
        "## Train step",
        "",
        "One train step of the 4-HIDDEN-HIDDEN-K·A network: the CPU time of `train_steps N "
        "HIDDEN` (the example `common/core/examples/train_steps.rs`: online and target forward, "
        "Huber TD loss, backward, Adam; K = 2 heads, A = 2 actions, batch 64) divided by N, and "
        "of `train_steps N preset`, the recommended CartPole preset's step (hidden 128, K = 4, "
        "batch 128, double DQN: one more forward pass, the large-margin loss, clipped gradients). "
        "\"Flops\" counts the products' multiply-adds twice (the forward passes, every weight's "
        "gradient, the input gradients of the two upper layers); \"of peak\" divides the flops "
        "per second of CPU time by one core's f32 FMA peak measured in the same rounds, "
        f"{span([p / 1e9 for p in peak], lambda x: f'{x:.1f}')} GFLOP/s (`train_steps peak`: "
        "independent chains of fused multiply-adds as wide as the train step's products: 16 lanes "
        "where the CPU has AVX-512, 8 with AVX2; at the clock the core runs then).",
        "",
        "| step | CPU time per step | flops per step | GFLOP/s | of peak | steps per run |",
        "|---|---:|---:|---:|---:|---:|",
    ]
    peak_median = statistics.median(peak)
    for name, (_, steps, *_) in TRAIN_SHAPES.items():
        step_us = statistics.median(train[name])
        rate = flops[name] / (step_us * 1e-6)
        lines.append(
            f"| {name} | {span(train[name], us)} | {flops[name] / 1e6:.2f} M | "
            f"{rate / 1e9:.1f} | {100 * rate / peak_median:.1f}% | {steps:,} |")
    lines += ["", "## Where the train step goes", ""]
    lines += parts_section(parts, split, flops, peak_median)
    lines += [
        "",
        "## Demonstration model",
        "",
        "Fit on B CartPole-like demonstrations (two actions), then 100 queries: ours is the "
        "whole `alfd demo-model` command, scikit-learn's the fit and predictions in its process "
        "(reading the same files). KRR: `KernelRidge(alpha=0.1, kernel=\"rbf\", gamma=0.1)` on "
        "one-hot actions; SVM: `SVC(C=10, gamma=0.1, probability=True)`. \"ours\" shares the "
        "fit's independent work among the machine's cores (the default), \"1 thread\" is "
        "`--threads 1` (the same numbers); scikit-learn's KRR runs on NumPy's BLAS threads, its "
        "SVC (libsvm) on one core. \"ours / theirs\" compares \"ours\". \"max |Δ|\": the "
        "largest difference between the two KRR's outputs on the queries. Below "
        f"{SMALL_BELOW:,} demonstrations (tens of milliseconds a fit) each round's figure is the "
        f"median of {SMALL_REPEATS} runs, for both.",
        "",
        "| demonstrations | KRR ours | KRR ours, 1 thread | KRR scikit-learn | ours / theirs | max \\|Δ\\| | SVM ours | SVM ours, 1 thread | SVC scikit-learn | ours / theirs |",
        "|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|",
    ]
    for n in SIZES:
        k = krr[n]
        ratio = statistics.median(k["ours"]) / statistics.median(k["sklearn"])
        row = (f"| {n:,} | {span(k['ours'], s)} | {span(k['ours_1'], s)} | {span(k['sklearn'], s)} | "
               f"{ratio:.2f} | {k['max_diff']:.1e} |")
        if n in svm:
            v = svm[n]
            vr = statistics.median(v["ours"]) / statistics.median(v["sklearn"])
            row += f" {span(v['ours'], s)} | {span(v['ours_1'], s)} | {span(v['sklearn'], s)} | {vr:.2f} |"
        else:
            row += " | | | |"
        lines.append(row)
    ms = lambda x: f"{x * 1e3:.1f} ms"  # noqa: E731
    lines += [
        "",
        "## One more demonstration",
        "",
        f"KRR's cost of a demonstration arriving at B: the factor grown by one row and the model "
        f"solved from it (`KrrFactor::push_on` + `model_on`; \"new row\" and \"solve\" are the "
        f"two parts), on one lane and on two lanes that run at once (the {GROWN} arrivals from B "
        "on take turns, every model is solved both ways; the median per arrival), "
        f"against a fit anew on B + {GROWN} (`KrrFactor::fit` + `model`, on one thread); "
        "in-process times of the "
        "example `common/core/examples/krr_grow.rs`. Both solves read the whole factor "
        "(n²/2 values) once, so memory bandwidth bounds them; on two lanes each row is split "
        "between the lanes from 2,048 demonstrations on. \"same bits\": every grown model "
        "(either lanes) equals the fitted one bit for bit. scikit-learn's `KernelRidge` has no "
        "update: it refits (its fit column above).",
        "",
        "| demonstrations | grown by one, 1 lane | new row | solve | grown by one, 2 lanes "
        "| new row | solve | fitted anew | fitted / grown (2 lanes) | same bits |",
        "|---:|---:|---:|---:|---:|---:|---:|---:|---:|:---:|",
    ]
    for n in GROW_SIZES:
        g = grow[n]
        ratio = statistics.median(g["fit"]) / statistics.median(g["grow_2"])
        lines.append(
            f"| {n:,} | {span(g['grow'], ms)} | {span(g['push'], ms)} | {span(g['model'], ms)} | "
            f"{span(g['grow_2'], ms)} | {span(g['push_2'], ms)} | {span(g['model_2'], ms)} | "
            f"{span(g['fit'], ms)} | {ratio:.0f} | "
            f"{'yes' if g['same_bits'] else 'no'} |"
        )
    lines += nystrom_section(nystrom)
    with open(os.path.join(args.out, "summary.md"), "w") as f:
        f.write("\n".join(lines) + "\n")
    print(f"core.py: wrote {args.out}/summary.md and results.json")


def nystrom_section(rows):
    """The approximate model's table: agreement with the exact model, costs, against B."""
    lines = [
        "",
        "## An approximate model for many demonstrations",
        "",
        "KRR on 512 Nyström landmarks (`--kind nystrom`, `expert.model = \"nystrom\"`) against the "
        "exact KRR, both fitted on B demonstrations of CartPole-v1 episodes played by a linear "
        "controller that takes a random action one step in four, each with the controller's action; "
        "compared on 2,000 held-out states of other episodes (the example "
        "`common/core/examples/nystrom_agreement.rs`, run once). \"agree\": the share of held-out "
        "states on which the two greedy actions are the same; \"max |Δp|\": the largest difference "
        "of p(a|s); \"vs controller\": each model's greedy action against the controller's. Fits are "
        "in-process (a run's expert grows either model a demonstration at a time instead).",
        "",
        "| demonstrations | agree | max \\|Δp\\| | Nyström vs controller | exact vs controller "
        "| Nyström fit | exact fit | Nyström query | exact query |",
        "|---:|---:|---:|---:|---:|---:|---:|---:|---:|",
    ]
    for r in rows:
        if "agreement" in r:
            exact = (f"{100 * r['agreement']:.1f}% | {r['max_dp']:.4f} | "
                     f"{100 * r['nystrom_vs_controller']:.1f}% | {100 * r['krr_vs_controller']:.1f}% | "
                     f"{r['nystrom_fit_s']:.2f} s | {r['krr_fit_s']:.2f} s | "
                     f"{r['nystrom_query_us']:.1f} µs | {r['krr_query_us']:.1f} µs |")
        else:
            exact = (f"| | {100 * r['nystrom_vs_controller']:.1f}% | (beyond 10,000) | "
                     f"{r['nystrom_fit_s']:.2f} s | | {r['nystrom_query_us']:.1f} µs | |")
        lines.append(f"| {r['demos']:,} | {exact}")
    return lines


if __name__ == "__main__":
    main()
