"""The runtime's speed, written to results/runtime/ (results.json, summary.md) for BENCHMARKS.md:
the wire between two processes on shared memory and across hosts over zenoh on loopback
(`alfd-bench-ipc`), Gymnasium environments and an external expert through the Python adapter
beside Gymnasium in-process (`alfd-bench-remote`, `deploy/python/bench_inprocess.py`), and the cost
of a checkpoint (the two measurements run as ignored tests). Rounds are interleaved; the summary
gives medians with the range over the rounds.

    python3 deploy/bench/runtime.py --bin target/release --python .venv/bin/python \
        --out results/runtime [--rounds 3] [--scale 0.3] [--summary-only]
"""

import argparse
import json
import os
import subprocess

import host

ENVS = ["CartPole-v1", "Acrobot-v1"]


def run_json(cmd, env=None):
    """The JSON lines a command prints on stdout."""
    out = subprocess.run(cmd, check=True, capture_output=True, text=True, env=env).stdout
    return [json.loads(l) for l in out.splitlines() if l.startswith("{")]


def ipc(bin_dir, scale, zenoh):
    env = dict(os.environ, ALFD_BENCH_SCALE=str(scale))
    cmd = [os.path.join(bin_dir, "alfd-bench-ipc")] + (["--zenoh"] if zenoh else [])
    return run_json(cmd, env)[-1]


def python_steps(bin_dir, python, steps):
    rows = {}
    for env_id in ENVS:
        (inproc,) = run_json([python, "deploy/python/bench_inprocess.py", env_id, str(steps)])
        lines = run_json([os.path.join(bin_dir, "alfd-bench-remote"), env_id, str(steps), "2000"])
        remote = next(l for l in lines if l["bench"] == "remote_env")
        expert = next(l for l in lines if l["bench"] == "external_expert_round_trip_us")
        rows[env_id] = {"in_process": inproc["steps_per_s"], "adapter": remote["steps_per_s"],
                        "expert_us": expert}
    return rows


def checkpoint_costs():
    """The `BENCH {json}` lines the two ignored checkpoint tests print."""
    found = {}
    for cmd in (["cargo", "test", "--release", "--quiet", "-p", "alfd-deploy", "--bin", "alfd",
                 "--", "--ignored", "--nocapture", "checkpoint_size"],
                ["cargo", "test", "--release", "--quiet", "-p", "alfd-learner", "--",
                 "--ignored", "--nocapture", "learner_checkpoint_cost"]):
        p = subprocess.run(cmd, check=True, capture_output=True, text=True)
        for line in (p.stdout + p.stderr).splitlines():
            if line.startswith("BENCH "):
                m = json.loads(line[len("BENCH "):])
                found[m["bench"]] = m
    return found


def med(xs):
    xs = sorted(xs)
    n = len(xs)
    return xs[n // 2] if n % 2 else (xs[n // 2 - 1] + xs[n // 2]) / 2


def mr(xs, fmt):
    """`median (low-high)` of `xs`, each formatted by `fmt`."""
    return f"{fmt(med(xs))} ({fmt(min(xs))}-{fmt(max(xs))})"


def us(x):
    return f"{x:,.1f} µs" if x < 100 else f"{x:,.0f} µs"


def rate(x):
    return f"{x / 1e6:.2f} M/s" if x >= 1e6 else f"{x / 1e3:,.1f} k/s"


def write(r, out):
    with open(os.path.join(out, "results.json"), "w") as f:
        json.dump(r, f, indent=1)
    shm, zen = r["shm"], r["zenoh"]
    col = lambda rows, bench, key: [x[bench][key] for x in rows]
    L = ["# The runtime's speed", "",
         "Written by `bash deploy/bench/runtime.sh`; every number is in `results.json`.", "",
         "## Machine", "",
         f"{r['machine']}; {r['date']}; load average {r['load_before']:.2f} before. "
         f"{r['rounds']} interleaved rounds; medians, the range over the rounds in parentheses. "
         f"Release build; iceoryx2 0.10 (shared memory), zenoh 1.10 (TCP on 127.0.0.1).", "",
         "## Wire", "",
         "`alfd-bench-ipc` (it starts a copy of itself as the peer process), "
         f"`ALFD_BENCH_SCALE={r['scale']}`:", "",
         "| what | how | result |", "|---|---|---|",
         f"| expert query round trip, polling | `QueryRequest` → `QueryResponse`, both sides "
         f"busy-poll | p50 {mr(col(shm, 'query-poll', 'p50_us'), us)}, p99 "
         f"{mr(col(shm, 'query-poll', 'p99_us'), us)} |",
         f"| expert query round trip, blocking | as the actor and the expert do: the expert's "
         f"doorbell rung, both sleep in a WaitSet | p50 {mr(col(shm, 'query-block', 'p50_us'), us)}, "
         f"p99 {mr(col(shm, 'query-block', 'p99_us'), us)} |",
         f"| transitions, actor → learner | batches of {shm[0]['transitions']['batch']} under the "
         f"credit protocol (window {shm[0]['transitions']['window']}) | "
         f"{mr(col(shm, 'transitions', 'transitions_per_s'), rate)} |",
         f"| weight broadcast, K = 2 network | 4,740 `f32`, latency from publishing to a copy in "
         f"hand | p50 {mr(col(shm, 'weights', 'p50_us'), us)}, p99 "
         f"{mr(col(shm, 'weights', 'p99_us'), us)} |", "",
         "## Across hosts", "",
         "`alfd-bench-ipc --zenoh`: the actor side in a mirror (its own run id), the expert or "
         "learner side behind a hub, the two bridges joined over zenoh on 127.0.0.1, as `alfd run "
         "--listen` and `alfd join` are (plain TCP: the transport, not the TLS handshake, is "
         "measured).", "",
         "| what | shared memory | zenoh, loopback |", "|---|---|---|",
         f"| expert query round trip, blocking | p50 {mr(col(shm, 'query-block', 'p50_us'), us)}, "
         f"p99 {mr(col(shm, 'query-block', 'p99_us'), us)} | p50 "
         f"{mr(col(zen, 'query-block', 'p50_us'), us)}, p99 "
         f"{mr(col(zen, 'query-block', 'p99_us'), us)} |",
         f"| transitions, actor → learner | {mr(col(shm, 'transitions', 'transitions_per_s'), rate)} "
         f"| {mr(col(zen, 'transitions', 'transitions_per_s'), rate)} |", "",
         "## Environments and experts in Python", "",
         f"Per round and environment: Gymnasium stepping in-process "
         f"(`deploy/python/bench_inprocess.py`, `env.step` in a Python loop), then the same loop "
         f"through the adapter (`alfd-bench-remote`: `RemoteEnv::step` from Rust, a request and "
         f"its response over iceoryx2, the adapter calling `env.step`), {r['python_steps']:,} "
         f"steps each; then 2,000 queries to an external expert "
         f"(`python:alfd_examples:cartpole_balance`).", "",
         "| environment | Gymnasium in-process | through the adapter | external expert round trip "
         "(p50 / p99) |", "|---|---:|---:|---:|"]
    for env_id in ENVS:
        rows = [x[env_id] for x in r["python"]]
        L.append(f"| {env_id} | {mr([x['in_process'] for x in rows], rate)} | "
                 f"{mr([x['adapter'] for x in rows], rate)} | "
                 f"{us(med([x['expert_us']['median'] for x in rows]))} / "
                 f"{us(med([x['expert_us']['p99'] for x in rows]))} |")
    c = r["checkpoints"]
    run, lrn = c["checkpoint_bin"], c["learner_ckpt"]
    L += ["", "## Checkpoints", "",
          "Measured by two ignored tests (`cargo test --release -p alfd-deploy --bin alfd -- "
          "--ignored checkpoint_size`, `cargo test --release -p alfd-learner -- --ignored "
          "learner_checkpoint_cost`), each writing the state ten times and reading it back ten "
          "times; medians (min-max).", "",
          "| file | state | size | write | read + check + decode |", "|---|---|---:|---:|---:|",
          f"| `checkpoint.bin` (`alfd local`) | a `cartpole-bdqn-krr` run stopped when its "
          f"{run['transitions']:,}-transition buffer is full | {run['bytes']:,} B | {run['write_ms_median']:.2f} "
          f"ms ({run['write_ms_min']:.2f}-{run['write_ms_max']:.2f}) | "
          f"{run['read_ms_median']:.2f} ms |",
          f"| `learner.ckpt` (`alfd run`) | the recommended CartPole preset's learner with a full "
          f"{lrn['transitions']:,}-transition buffer | {lrn['bytes']:,} B | {lrn['write_ms_median']:.2f} ms "
          f"({lrn['write_ms_min']:.2f}-{lrn['write_ms_max']:.2f}) | "
          f"{lrn['read_ms_median']:.2f} ms |", "",
          "A write is: encode (postcard, header, FNV-1a checksum), a temporary file, fsync, "
          "rename, fsync of the directory; `learner.ckpt`'s also takes the learner's snapshot "
          "first, `checkpoint.bin`'s starts from one.", ""]
    with open(os.path.join(out, "summary.md"), "w") as f:
        f.write("\n".join(L))


def flat(prefix, value):
    """(name, number) for every number under `value`, names joined with `/`."""
    if isinstance(value, dict):
        for k, v in value.items():
            yield from flat(f"{prefix}/{k}" if prefix else k, v)
    elif isinstance(value, (int, float)) and not isinstance(value, bool):
        yield prefix, value


def write_runs(r, out):
    """runs.csv: one row per round, transport and measured number (what the medians come from)."""
    with open(os.path.join(out, "runs.csv"), "w") as f:
        f.write("round,part,measure,value\n")
        for part in ("shm", "zenoh", "python"):
            for i, rnd in enumerate(r[part]):
                for name, v in flat("", rnd):
                    f.write(f"{i + 1},{part},{name},{v!r}\n")


def main():
    p = argparse.ArgumentParser()
    p.add_argument("--bin", required=True, help="the release directory with the bench binaries")
    p.add_argument("--python", required=True, help="the project's Python with gymnasium")
    p.add_argument("--out", required=True)
    p.add_argument("--rounds", type=int, default=3)
    p.add_argument("--scale", type=float, default=0.3, help="ALFD_BENCH_SCALE of alfd-bench-ipc")
    p.add_argument("--python-steps", type=int, default=20000)
    p.add_argument("--summary-only", action="store_true",
                   help="rewrite summary.md and runs.csv from results.json")
    a = p.parse_args()
    if a.summary_only:
        with open(os.path.join(a.out, "results.json")) as f:
            r = json.load(f)
        write(r, a.out)
        write_runs(r, a.out)
        return
    os.makedirs(a.out, exist_ok=True)
    load = os.getloadavg()[0]
    m = host.machine()
    r = {"machine": host.described(m), "date": m["date"], "load_before": load,
         "rounds": a.rounds, "scale": a.scale, "python_steps": a.python_steps,
         "shm": [], "zenoh": [], "python": []}
    print("runtime.py: checkpoints", flush=True)
    r["checkpoints"] = checkpoint_costs()
    for i in range(a.rounds):
        print(f"runtime.py: round {i + 1}/{a.rounds}", flush=True)
        r["shm"].append(ipc(a.bin, a.scale, zenoh=False))
        r["zenoh"].append(ipc(a.bin, a.scale, zenoh=True))
        r["python"].append(python_steps(a.bin, a.python, a.python_steps))
    write(r, a.out)
    write_runs(r, a.out)


if __name__ == "__main__":
    main()
