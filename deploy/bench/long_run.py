"""Runs `alfd run` for STEPS environment steps and samples, every 2 s, the resident memory of each
of its processes (from /proc) and the size of each file in its run directory; writes
samples.csv and summary.md (see long-run.sh)."""

import argparse
import csv
import json
import os
import subprocess
import time

import host

PERIOD_S = 2.0


def rss_kib(pid):
    try:
        with open(f"/proc/{pid}/status") as f:
            for line in f:
                if line.startswith("VmRSS:"):
                    return int(line.split()[1])
    except OSError:
        pass
    return None


def children(pid):
    """Every descendant of pid, with its command's name."""
    found = {}
    todo = [pid]
    while todo:
        p = todo.pop()
        try:
            with open(f"/proc/{p}/task/{p}/children") as f:
                kids = [int(k) for k in f.read().split()]
        except OSError:
            kids = []
        for k in kids:
            try:
                with open(f"/proc/{k}/cmdline", "rb") as f:
                    argv = f.read().split(b"\0")
            except OSError:
                continue
            name = os.path.basename(argv[0].decode())
            for a in argv[1:]:
                a = a.decode()
                if a.startswith("--actor-id="):
                    name += "-" + a.split("=")[1]
            found[k] = name
            todo.append(k)
    return found


def files(run_dir):
    out = {}
    for root, _, names in os.walk(run_dir):
        for n in names:
            p = os.path.join(root, n)
            try:
                out[os.path.relpath(p, run_dir)] = os.path.getsize(p)
            except OSError:
                pass
    return out


def main():
    p = argparse.ArgumentParser()
    p.add_argument("--alfd", required=True)
    p.add_argument("--steps", type=int, required=True)
    p.add_argument("--run-dir", required=True)
    p.add_argument("--results", required=True)
    a = p.parse_args()
    os.makedirs(a.results, exist_ok=True)
    cmd = [a.alfd, "run", "--quiet", "--json", "--set", f"steps={a.steps}", "--out", a.run_dir]
    started = time.monotonic()
    run = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    rows = []
    while run.poll() is None:
        t = time.monotonic() - started
        procs = {run.pid: "alfd"} | children(run.pid)
        for pid, name in procs.items():
            kib = rss_kib(pid)
            if kib is not None:
                rows.append({"t_s": round(t, 1), "what": name, "kind": "rss_kib", "value": kib})
        for name, size in files(a.run_dir).items():
            rows.append({"t_s": round(t, 1), "what": name, "kind": "bytes", "value": size})
        time.sleep(PERIOD_S)
    out, err = run.communicate()
    wall = time.monotonic() - started
    if run.returncode != 0:
        raise SystemExit(f"alfd run failed ({run.returncode}):\n{err[-2000:]}")
    summary = json.loads(out.strip().splitlines()[-1])
    end_files = files(a.run_dir)
    with open(os.path.join(a.results, "samples.csv"), "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=["t_s", "what", "kind", "value"])
        w.writeheader()
        w.writerows(rows)
    write_summary(a, rows, end_files, summary, wall)


def at_fraction(series, frac, wall):
    """The first sample at or after frac of the run's wall-clock."""
    for t, v in series:
        if t >= frac * wall:
            return v
    return series[-1][1]


def write_summary(a, rows, end_files, summary, wall):
    m = host.machine()
    by = {}
    for r in rows:
        if r["kind"] == "rss_kib":
            by.setdefault(r["what"], []).append((r["t_s"], r["value"]))
    lines = [
        "# A run ten times longer than the preset",
        "",
        "Written by `bash deploy/bench/long-run.sh`; every sample is in `samples.csv`.",
        "",
        "## Run",
        "",
        f"{host.described(m)}, Linux; {m['date']}. `alfd run --set steps={a.steps}` "
        f"(the recommended CartPole-1000 preset, 2 actors, replay capacity 50,000), "
        f"{summary.get('episodes')} episodes, {summary.get('env_steps')} environment steps, "
        f"{wall:.0f} s wall-clock; resident memory and file sizes sampled every {PERIOD_S:.0f} s.",
        "",
        "## Memory",
        "",
        "Resident memory (VmRSS) of each process at a tenth, half and the end of the run, and its "
        "largest sample.",
        "",
        "| process | at 10% | at 50% | at the end | largest | end − 10% |",
        "|---|---:|---:|---:|---:|---:|",
    ]
    for name in sorted(by):
        s = by[name]
        if len(s) < 3:
            continue
        v10, v50, vend = at_fraction(s, 0.1, wall), at_fraction(s, 0.5, wall), s[-1][1]
        mib = lambda k: f"{k / 1024:.1f} MiB"
        lines.append(
            f"| {name} | {mib(v10)} | {mib(v50)} | {mib(vend)} | {mib(max(v for _, v in s))} "
            f"| {(vend - v10) / 1024:+.1f} MiB |"
        )
    lines += [
        "",
        "## Files",
        "",
        "Each file of the run directory at the end, and bytes per episode for the rows and logs, "
        "which grow with the run (`demos.jsonl` stops at the budget, checkpoints and weights are "
        "rewritten whole).",
        "",
        "| file | bytes | bytes per episode |",
        "|---|---:|---:|",
    ]
    episodes = max(1, int(summary.get("episodes") or 1))
    for name in sorted(end_files):
        size = end_files[name]
        per = f"{size / episodes:.0f}" if name.endswith((".csv", ".log")) else ""
        lines.append(f"| {name} | {size:,} | {per} |")
    with open(os.path.join(a.results, "summary.md"), "w") as f:
        f.write("\n".join(lines) + "\n")
    print(f"long_run.py: wrote {a.results}/summary.md and samples.csv", flush=True)


if __name__ == "__main__":
    main()
