"""Does a run learn its experts' ranking? Reads a several-experts sweep's `experts.csv` files
and writes `ranking.md` and `ranking.csv` (python3 ranking.py SWEEP_OUT PREFIX RESULTS_DIR).

The true ranking is `alfd expert eval`'s: PREFIX-good > PREFIX-fair > PREFIX-poor. A run ranks
its experts right "after at most 50 answers each" when the qualities each expert had after its
min(50, all its) answers are in that order, strictly. For `good-turns-poor` (the good expert
answers as the poor one after its 25th answer) the ranking has recovered once the changed
expert's quality falls below the fair one's: the answers it gave after the change until then,
counted in the runs that ranked it above the fair one at the change (the others have nothing to
recover).
Only methods in which all three experts answered are counted.
"""
import csv
import sys
from pathlib import Path

AT = 50
TURN = 25


def rows_of(path):
    with open(path, newline="") as f:
        return [dict(r, step=int(r["step"]), answers=int(r["answers"]), quality=float(r["quality"]))
                for r in csv.DictReader(f)]


def ranked_right(rows, order):
    final = {}
    for r in rows:
        final[r["expert"]] = r["answers"]
    if any(e not in final for e in order):
        return None
    at = {e: min(AT, final[e]) for e in order}
    q = {r["expert"]: r["quality"] for r in rows if r["answers"] == at[r["expert"]]}
    return all(q[a] > q[b] for a, b in zip(order, order[1:])), at


def recovery(rows, good, fair):
    """Whether `good` ranked above `fair` at its TURN-th answer (the change), and the answers it
    gave after the change until its quality fell below fair's (None: never)."""
    fair_q, above = None, False
    for r in rows:
        if r["expert"] == fair:
            fair_q = r["quality"]
        elif r["expert"] == good and r["answers"] == TURN:
            above = fair_q is not None and r["quality"] > fair_q
        elif r["expert"] == good and r["answers"] > TURN and fair_q is not None:
            if r["quality"] < fair_q:
                return above, r["answers"] - TURN
    return above, None


def main():
    out, prefix, results = Path(sys.argv[1]), sys.argv[2], Path(sys.argv[3])
    order = [f"{prefix}-good", f"{prefix}-fair", f"{prefix}-poor"]
    lines = ["method,seed,ranked_right,answers_good,answers_fair,answers_poor,recovered_after"]
    summary = []
    for method in sorted(p for p in (out / "runs").iterdir() if p.is_dir()):
        right, seeds, recovered, turned = 0, 0, [], method.name.startswith("good-turns-poor")
        for run in sorted(method.iterdir(), key=lambda p: int(p.name)):
            path = run / "experts.csv"
            if not path.is_file():
                continue
            rows = rows_of(path)
            r = ranked_right(rows, order)
            if r is None:
                continue
            ok, at = r
            above, rec = recovery(rows, order[0], order[1]) if turned else (False, None)
            seeds += 1
            right += ok and not turned
            if above:
                recovered.append(rec)
            lines.append(",".join(str(v) for v in [method.name, run.name, str(ok).lower(),
                                                    *at.values(), "" if rec is None else rec]))
        if seeds:
            summary.append((method.name, seeds, right, recovered if turned else None))
    results.mkdir(parents=True, exist_ok=True)
    (results / "ranking.csv").write_text("\n".join(lines) + "\n")
    md = [f"# Does the run learn its experts' ranking? ({prefix})", "",
          f"Written by `deploy/experiments/experts/ranking.py` from `{out.name}`'s `experts.csv` files; "
          "per run in `ranking.csv`.", "",
          f"True ranking (`alfd expert eval`): {' > '.join(order)}. \"ranked right\": the qualities "
          f"after each expert's min({AT}, all its) answers are in that order.", "",
          "| method | runs | ranked right | good above fair at the change | of those, recovered within 100 answers | median answers to recover |",
          "|---|---:|---:|---:|---:|---:|"]
    for name, seeds, right, rec in summary:
        if rec is None:
            md.append(f"| {name} | {seeds} | {right} of {seeds} | – | – | – |")
        else:
            got = sorted(r for r in rec if r is not None)
            within = sum(1 for r in got if r <= 100)
            # The median over the runs that had something to recover, a run that never did
            # counted as longer than any.
            med = got[len(rec) // 2] if len(got) > len(rec) // 2 else "not reached"
            md.append(f"| {name} | {seeds} | – | {len(rec)} of {seeds} | {within} of {len(rec)} | {med} |")
    (results / "ranking.md").write_text("\n".join(md) + "\n")
    print("\n".join(md))


if __name__ == "__main__":
    main()
