"""The long chaos run's summary (deploy/chaos/long.sh): reads ROOT/chaos-S/{chaos.json,
summary.json} and ROOT/control-S/summary.json for every seed S, writes OUT/runs.csv (one row per
seed) and OUT/summary.md (faults by kind, invariants, last-50 mean return with and without
faults, with 95% percentile-bootstrap intervals over the seeds)."""

import csv
import datetime
import json
import os
import random
import sys


def load(path):
    try:
        with open(path) as f:
            return json.load(f)
    except (OSError, ValueError):
        return None


def interval(xs, rng, n=10000):
    if not xs:
        return float("nan"), float("nan"), float("nan")
    means = sorted(sum(rng.choice(xs) for _ in xs) / len(xs) for _ in range(n))
    return sum(xs) / len(xs), means[int(0.025 * n)], means[int(0.975 * n) - 1]


def main(root, out):
    seeds = sorted(
        int(d.split("-")[1]) for d in os.listdir(root) if d.startswith("chaos-") and d[6:].isdigit()
    )
    rows, kinds, held, broken = [], {}, 0, {}
    for s in seeds:
        report = load(f"{root}/chaos-{s}/chaos.json")
        faulted = load(f"{root}/chaos-{s}/summary.json") or {}
        control = load(f"{root}/control-{s}/summary.json") or {}
        if report is None:
            broken.setdefault("no chaos.json (the chaos command itself failed)", []).append(s)
            continue
        for e in report["events"]:
            f = e["fault"]
            kind = f if isinstance(f, str) else next(iter(f))
            done = e["carried_out"]
            k = kinds.setdefault(kind, [0, 0])
            k[0] += 1
            k[1] += done
        bad = [v["name"] for v in report["invariants"] if not v["ok"]]
        held += not bad
        for name in bad:
            broken.setdefault(name, []).append(s)
        rows.append({
            "seed": s,
            "faults": len(report["events"]),
            "launches": report["launches"],
            "invariants_broken": " ".join(bad),
            "last50_chaos": faulted.get("mean_return_last_50"),
            "last50_control": control.get("mean_return_last_50"),
        })
    os.makedirs(out, exist_ok=True)
    with open(f"{out}/runs.csv", "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=list(rows[0]) if rows else ["seed"])
        w.writeheader()
        w.writerows(rows)
    rng = random.Random(20261202)
    chaos = [r["last50_chaos"] for r in rows if r["last50_chaos"] is not None]
    control = [r["last50_control"] for r in rows if r["last50_control"] is not None]
    mc, lc, hc = interval(chaos, rng)
    mk, lk, hk = interval(control, rng)
    total = sum(k[0] for k in kinds.values())
    lines = [
        "# Long chaos run",
        "",
        "Written by `deploy/chaos/summary.py` (from `bash deploy/chaos/long.sh`); one row per seed "
        "in `runs.csv`.",
        "",
        "## Run",
        "",
        f"{datetime.date.today().isoformat()}, the 2-core machine: {len(seeds)} seeded `alfd chaos` "
        f"runs of the recommended CartPole preset back to back (50,000 steps each, 2 actors, a "
        f"fault every 3 s on average, swaps among cartpole-500, cartpole-1000 and "
        f"cartpole-perfect, the run directories on a 512 MB tmpfs), {total} faults in all, each "
        "run beside the same run (same config seed) without faults.",
        "",
        "## Faults",
        "",
        "| fault | drawn | carried out |",
        "|---|---:|---:|",
    ]
    for kind in sorted(kinds):
        lines.append(f"| {kind} | {kinds[kind][0]} | {kinds[kind][1]} |")
    lines += [
        "",
        "\"Carried out\" leaves out a fault that found no process to hit (one restarting), a swap "
        "while another was under way and a launcher kill before the first learner checkpoint; a "
        "swap counts when `alfd swap-expert` was started.",
    ]
    lines += [
        "",
        "## Invariants",
        "",
        f"Every invariant held in {held} of {len(rows)} runs.",
        "",
        "| invariant broken | seeds |",
        "|---|---|",
    ]
    for name in sorted(broken):
        lines.append(f"| {name} | {', '.join(map(str, broken[name]))} |")
    if not broken:
        lines.append("| (none) | |")
    lines += [
        "",
        "## Learning",
        "",
        "Mean return of the last 50 episodes, the mean over seeds with its 95% percentile-bootstrap "
        "interval.",
        "",
        "| runs | under faults | without faults |",
        "|---:|---:|---:|",
        f"| {len(rows)} | {mc:.1f} [{lc:.1f}, {hc:.1f}] | {mk:.1f} [{lk:.1f}, {hk:.1f}] |",
    ]
    with open(f"{out}/summary.md", "w") as f:
        f.write("\n".join(lines) + "\n")
    print(f"summary.py: wrote {out}/summary.md and runs.csv")


if __name__ == "__main__":
    main(sys.argv[1], sys.argv[2])
