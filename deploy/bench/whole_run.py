"""The main job near the machine's limit: where the learner's time goes in `alfd run` (a perf
profile of the learner process by part, beside the idle time it logs), its share of one core's
FMA peak, `alfd run` against `alfd local` in learner updates per second, 1, 2, 4 and 8 actors,
and the replay buffer's memory per million transitions. Writes results.json and summary.md
(see whole-run.sh)."""

import argparse
import csv
import json
import os
import re
import statistics
import subprocess
import tempfile
import time

import host

PRESET = "deploy/configs/recommended/cartpole.toml"

# The learner's code by part, as perf names its symbols (first match wins).
PARTS = [
    ("replay sampling", r"replay::|sample_with_demos|sample_into"),
    ("train step: networks and Adam", r"alfd_common::nn::|gemm|adam|td_loss|train_step"),
    ("the wire (iceoryx2)", r"iceoryx2|alfd_wire|iox2"),
    ("n-step returns, shaping, credits", r"n_step|shaping|credit_book|alfd_learner"),
    ("maths library (exp, ln)", r"libm::"),
    ("operating system", r"^\[k\]"),
]


def sh(cmd, **kw):
    return subprocess.run(cmd, check=True, capture_output=True, text=True, **kw)


def run_json(cmd, env=None):
    t = time.monotonic()
    out = sh(cmd, env=env).stdout
    return json.loads(out.strip().splitlines()[-1]), time.monotonic() - t


def learner_log_fields(run_dir):
    """The numbers of the learner's "learner stopping" line."""
    with open(os.path.join(run_dir, "learner.log")) as f:
        line = [l for l in f if "learner stopping" in l][-1]
    return {k: float(v) for k, v in re.findall(r"(\w+)=([0-9.]+)", line)}


def profile(alfd, tmp):
    """One `alfd run` of the preset under `perf record`; the learner's samples by part."""
    run_dir = os.path.join(tmp, "profiled")
    data = os.path.join(tmp, "perf.data")
    summary, wall = run_json(
        ["perf", "record", "-q", "-F", "499", "-o", data, "--",
         alfd, "run", "--config", PRESET, "--quiet", "--json", "--out", run_dir]
    )
    report = sh(["perf", "report", "-i", data, "--comm", "alfd-learner", "--no-children",
                 "--sort", "sym", "--stdio", "-q"]).stdout
    shares = {name: 0.0 for name, _ in PARTS}
    shares["other"] = 0.0
    for line in report.splitlines():
        m = re.match(r"\s*([0-9.]+)%\s+(\[.\])\s+(.*)", line)
        if not m:
            continue
        pct, kind, sym = float(m.group(1)), m.group(2), m.group(3).strip()
        text = f"{kind} {sym}" if kind == "[k]" else sym
        for name, pattern in PARTS:
            if re.search(pattern, text if name == "operating system" else sym):
                shares[name] += pct
                break
        else:
            shares["other"] += pct
    log = learner_log_fields(run_dir)
    return {"summary": summary, "wall_s": wall, "learner_log": log, "cpu_shares_pct": shares,
            "weights": weight_shapes(os.path.join(run_dir, "weights.safetensors"))}


def weight_shapes(path):
    with open(path, "rb") as f:
        n = int.from_bytes(f.read(8), "little")
        header = json.loads(f.read(n))
    return {k: v["shape"] for k, v in header.items() if k != "__metadata__"}


def flops_per_update(shapes, batch):
    """Multiply-adds of one update: online forward on states and on next states (double DQN),
    the target forward on next states, and the backward pass (twice the forward), times 2."""
    macs = sum(s[0] * s[1] for s in shapes.values() if len(s) == 2)
    return 2 * batch * macs * (3 + 2)


PEAK_ROUNDS = 100_000_000


def core_peak_flops(train_steps):
    """One core's f32 FMA peak now, as `deploy/bench/core.sh` measures it (`host.fma_peak`), the
    median of 3 runs."""
    return statistics.median(host.fma_peak(train_steps, PEAK_ROUNDS) for _ in range(3))


def run_row(alfd, tmp, name, actors, extra=(), env=None):
    """One `alfd run` of the preset with `actors` actors (the flags in `extra`, the environment
    variables in `env`), with the learner's own counts: its doorbell rings and their time, the
    time it spent publishing weights and waiting for transitions."""
    run_dir = os.path.join(tmp, name)
    s, wall = run_json([alfd, "run", "--config", PRESET, "--actors", str(actors), "--quiet",
                        "--json", "--out", run_dir, *extra], env={**os.environ, **(env or {})})
    log = learner_log_fields(run_dir)
    return {"updates_per_s": s["updates_per_s"], "env_steps_per_s": s["env_steps_per_s"],
            "last_50": s["mean_return_last_50"], "wall_s": wall,
            "rings": log.get("rings"), "ring_s": log.get("ring_s"),
            "publish_s": log.get("publish_s"), "waiting_s": log.get("idle_running_s")}


def actors_sweep(alfd, tmp, counts, repeats):
    return {n: [run_row(alfd, tmp, f"actors-{n}-{r}", n) for r in range(repeats)]
            for n in counts}


def local_row(alfd, tmp, name):
    d = os.path.join(tmp, name)
    t = time.monotonic()
    sh([alfd, "local", "--config", PRESET, "--quiet", "--out", d])
    wall = time.monotonic() - t
    with open(os.path.join(d, "summary.json")) as f:
        s = json.load(f)
    with open(os.path.join(d, "episodes.csv")) as f:
        steps = sum(int(r["length"]) for r in csv.DictReader(f))
    row = {"env_steps": steps, "wall_s": wall, "run_wall_s": s["wall_clock_s"],
           "env_steps_per_s": steps / s["wall_clock_s"]}
    if "updates" in s:
        row["updates_per_s"] = s["updates"] / s["wall_clock_s"]
    return row


def paired(alfd, tmp, repeats):
    """`alfd run` (2 actors: the default window, the same with actors that sleep on their
    doorbell at once, `--window 32`) and `alfd local` in rounds, one after the other, so that
    each round's ratio compares runs minutes apart (this virtual machine's speed drifts by more
    than the difference measured over a longer span); every other round in the reverse order,
    so that neither runtime always runs first."""
    runs = {
        "run": lambda r: run_row(alfd, tmp, f"paired-run-{r}", 2),
        "local": lambda r: local_row(alfd, tmp, f"paired-local-{r}"),
        "run_no_poll": lambda r: run_row(alfd, tmp, f"paired-sleep-{r}", 2,
                                         env={"ALFD_CREDIT_POLL_US": "0"}),
        "run_window32": lambda r: run_row(alfd, tmp, f"paired-w32-{r}", 2, ["--window", "32"]),
    }
    out = {name: [] for name in runs}
    for r in range(repeats):
        for name in runs if r % 2 == 0 else reversed(list(runs)):
            out[name].append(runs[name](r))
    return out


def replay_bytes(example):
    return json.loads(sh([example]).stdout)


def med(xs):
    return statistics.median(xs)


def runs_minutes(results):
    """The wall-clock of every run of the benchmark, summed, in minutes (the paired `alfd run`s
    are the 2-actor rows of `actors`)."""
    rows = [results["profile"]] + [row for key in ("local", "run_no_poll", "run_window32")
                                   for row in results.get(key, [])]
    rows += [row for runs in results["actors"].values() for row in runs]
    return sum(row["wall_s"] for row in rows) / 60


def write(results, out):
    with open(os.path.join(out, "results.json"), "w") as f:
        json.dump(results, f, indent=1)
    p = results["profile"]
    log, raw = p["learner_log"], p["cpu_shares_pct"]
    # perf's percentages are of every process's samples: made shares of the learner's own.
    total = sum(raw.values()) or 1.0
    shares = {k: 100.0 * v / total for k, v in raw.items()}
    wall = p["summary"]["wall_clock_s"]
    idle = log.get("idle_running_s", 0.0)
    busy = max(wall - idle, 0.0)
    peak = results["peak"]
    fl = results["flops_per_update"]
    achieved = p["summary"]["updates_per_s"] * fl
    L = ["# The main job near the machine's limit", "",
         "Written by `bash deploy/bench/whole-run.sh`; every number is in `results.json`.", "",
         "## Machine", "", f"{results['machine']}; {results['date']}; load average "
         f"{results['load_before']:.2f} before. Runs one at a time, the recommended CartPole-1000 "
         "preset (50,000 environment steps), release build; the runs took "
         f"{runs_minutes(results):.0f} minutes of wall-clock together.", "",
         "## Where the learner's time goes", "",
         f"`alfd run` (2 actors) under `perf record -F 499`: {p['summary']['updates_per_s']:.0f} "
         f"updates/s over {wall:.1f} s. The learner waited {idle:.1f} s of it for transitions "
         f"(its own count, `idle_running_s`); its CPU samples, split by part of the code, share "
         "the rest:", "",
         "| part | share of the learner's CPU samples | seconds (of the time not waiting) |",
         "|---|---:|---:|"]
    for name, pct in sorted(shares.items(), key=lambda kv: -kv[1]):
        L.append(f"| {name} | {pct:.1f}% | {busy * pct / 100:.1f} s |")
    L.append(f"| waiting for transitions | | {idle:.1f} s |")
    L += ["", f"One update is {fl / 1e6:.2f} MFLOP (forward on states and next states, the target "
          "network's forward, backward twice the forward; from the shapes in "
          "`weights.safetensors`, batch "
          f"{results['batch']}); at {p['summary']['updates_per_s']:.0f} updates/s that is "
          f"{achieved / 1e9:.2f} GFLOP/s, {100 * achieved / peak:.1f}% of one core's f32 FMA "
          f"peak, {peak / 1e9:.1f} GFLOP/s (`train_steps peak`, as in the core benchmarks: "
          "independent chains of fused multiply-adds as wide as the train step's products, 16 lanes "
          "where the CPU has AVX-512, 8 with AVX2, at the clock the core runs then; "
          "measured after the runs). An estimate: the count includes the first layer's "
          f"input gradient, which the backward pass skips.", "",
          "## Multi-process against single-process", "",
          "Learner updates per second over the training loop (the run's own wall-clock and "
          "update count in `summary.json`), 2 actors against one process. The runs go in "
          f"rounds ({len(results['local'])}), each round `alfd run` (the default window of 1: "
          "each actor in lockstep with the learner), `alfd local`, the first again with "
          "`ALFD_CREDIT_POLL_US=0` (a blocked actor sleeps on its doorbell at once instead of "
          "polling it first), then `alfd run --window 32`, one after the other, every other "
          "round in the reverse order; \"against "
          "local\" divides each round's `alfd run` by that round's `alfd local`, median "
          "(min-max) over the rounds. \"Doorbells\": the time the learner's rings took over "
          "the run (its `ring_s`; a ring that finds the actor asleep wakes the actor's core), "
          "and how many it rang; \"publishing\": the time it took to copy its weights into "
          "shared memory for the actors, after every queue of transitions it drained "
          "(`publish_s`); \"waiting\": the time it waited for transitions "
          "(`idle_running_s`); medians over the rounds. These are what `alfd local` does "
          "not do.", "",
          "| runtime | updates/s | environment steps/s | against local | doorbells | publishing "
          "| waiting |",
          "|---|---:|---:|---:|---:|---:|---:|"]
    loc = results["local"]

    def ratio(rows):
        rs = [r["updates_per_s"] / l["updates_per_s"] for r, l in zip(rows, loc)]
        return f"{med(rs):.2f} ({min(rs):.2f}-{max(rs):.2f})"

    def bells(rows):
        if any(r.get("ring_s") is None for r in rows):
            return ""
        return (f"{med([r['ring_s'] for r in rows]):.2f} s, "
                f"{med([r['rings'] for r in rows]):,.0f} rings")

    def seconds(rows, key):
        if any(r.get(key) is None for r in rows):
            return ""
        return f"{med([r[key] for r in rows]):.2f} s"

    runs = [("`alfd run` (2 actors)", results["actors"]["2"]),
            ("`alfd run`, actors sleep at once", results.get("run_no_poll", [])),
            ("`alfd run --window 32` (2 actors)", results["run_window32"])]
    for label, rows in runs:
        if not rows:
            continue
        L.append(f"| {label} | {med([r['updates_per_s'] for r in rows]):.0f} | "
                 f"{med([r['env_steps_per_s'] for r in rows]):.0f} | {ratio(rows)} | "
                 f"{bells(rows)} | {seconds(rows, 'publish_s')} | {seconds(rows, 'waiting_s')} |")
    L.append(f"| `alfd local` (one process) | {med([r['updates_per_s'] for r in loc]):.0f} | "
             f"{med([r['env_steps_per_s'] for r in loc]):.0f} | 1 | | | |")
    L += ["", "## Actors", "", "On the 2-core machine; medians over the runs.", "",
          "| actors | updates/s | environment steps/s | last-50 mean return | wall-clock |",
          "|---:|---:|---:|---:|---:|"]
    for n, rows in results["actors"].items():
        L.append(f"| {n} | {med([r['updates_per_s'] for r in rows]):.0f} | "
                 f"{med([r['env_steps_per_s'] for r in rows]):.0f} | "
                 f"{med([r['last_50'] for r in rows]):.1f} | {med([r['wall_s'] for r in rows]):.1f} s |")
    rb = results["replay"]
    L += ["", "## Replay memory", "",
          f"A replay buffer of {rb['transitions']:,} CartPole transitions (4 observations, "
          f"{rb['heads']} heads) adds {rb['rss_bytes'] / 2**20:.1f} MiB of resident memory "
          f"({rb['rss_bytes'] / rb['transitions']:.0f} bytes per transition; the layout holds "
          f"{rb['layout_bytes_per_transition']} bytes each): "
          f"`common/core/examples/replay_memory.rs`.", ""]
    with open(os.path.join(out, "summary.md"), "w") as f:
        f.write("\n".join(L))


def main():
    p = argparse.ArgumentParser()
    p.add_argument("--alfd", required=True)
    p.add_argument("--replay-example", required=True)
    p.add_argument("--out", required=True)
    p.add_argument("--train-steps", required=True)
    p.add_argument("--repeats", type=int, default=2)
    p.add_argument("--summary-only", action="store_true",
                   help="re-measure the FMA peak and rewrite summary.md from results.json")
    a = p.parse_args()
    if a.summary_only:
        with open(os.path.join(a.out, "results.json")) as f:
            results = json.load(f)
        results["peak"] = core_peak_flops(a.train_steps)
        write(results, a.out)
        return
    os.makedirs(a.out, exist_ok=True)
    load = os.getloadavg()[0]
    m = host.machine()
    with tempfile.TemporaryDirectory(prefix="alfd-whole-run-") as tmp:
        print("whole_run.py: profiling one run", flush=True)
        prof = profile(a.alfd, tmp)
        print("whole_run.py: alfd run and alfd local, in rounds", flush=True)
        pairs = paired(a.alfd, tmp, a.repeats)
        print("whole_run.py: 1, 4, 8 actors", flush=True)
        actors = actors_sweep(a.alfd, tmp, [1, 4, 8], a.repeats)
        actors[2] = pairs["run"]
        actors = dict(sorted(actors.items()))
    batch = 128
    results = {
        "machine": host.described(m), "date": m["date"], "load_before": load,
        "profile": prof, "actors": {str(k): v for k, v in actors.items()},
        "local": pairs["local"], "run_window32": pairs["run_window32"],
        "run_no_poll": pairs["run_no_poll"],
        "batch": batch, "flops_per_update": flops_per_update(prof["weights"], batch),
        "peak": core_peak_flops(a.train_steps), "replay": replay_bytes(a.replay_example),
    }
    write(results, a.out)
    print(f"whole_run.py: wrote {a.out}/summary.md and results.json", flush=True)


if __name__ == "__main__":
    main()
