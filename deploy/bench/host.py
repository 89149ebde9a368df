"""The machine a benchmark ran on, as the benchmarks of deploy/bench/ record it."""

import datetime
import os
import platform
import resource
import subprocess


def machine():
    """CPU model, cores, memory, Python and the date."""
    model = "unknown"
    with open("/proc/cpuinfo") as f:
        for line in f:
            if line.startswith("model name"):
                model = line.split(":", 1)[1].strip()
                break
    return {
        "cpu": model,
        "cores": os.cpu_count(),
        "memory_gib": round(os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES") / 2**30),
        "python": platform.python_version(),
        "date": datetime.date.today().isoformat(),
    }


def described(m):
    """`AMD EPYC, 2 cores, 24 GiB`."""
    return f"{m['cpu']}, {m['cores']} cores, {m['memory_gib']} GiB"


def cpu_seconds(cmd):
    """Runs `cmd`; its user + system CPU time, and its stdout."""
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    out = subprocess.run(cmd, check=True, capture_output=True, text=True).stdout
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    return (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime), out


def fma_peak(train_steps, rounds):
    """One core's f32 FMA peak now: `train_steps peak ROUNDS` (12 independent chains of fused
    multiply-adds as wide as the train step's products; its first line gives the flops of a
    round, 384 with AVX-512, 192 with AVX2) in flops per second of its CPU time."""
    cpu, out = cpu_seconds([train_steps, "peak", str(rounds)])
    first = out.splitlines()[0].split()
    if first[0] != "flops_per_round" or int(first[1]) <= 0:
        raise RuntimeError(f"train_steps peak printed {out!r}, not its flops per round first")
    return rounds * int(first[1]) / cpu
