"""The machine a benchmark ran on, as the benchmarks of deploy/bench/ record it."""

import datetime
import os
import platform


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
