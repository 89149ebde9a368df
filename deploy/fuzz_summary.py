"""results/fuzz/summary.md from a libFuzzer log of deploy/fuzz.sh: its arguments are the log,
the seconds asked for and the fuzzer's exit status."""

import re
import sys

sys.path.insert(0, "deploy/bench")
import host  # noqa: E402

log, seconds, status = open(sys.argv[1]).read(), sys.argv[2], int(sys.argv[3])
stats = dict(re.findall(r"^stat::(\w+):\s+(\d+)", log, re.M))
cov = re.findall(r"cov: (\d+) ft: (\d+) corp: (\d+)/", log)
edges, features, corpus = cov[-1] if cov else ("?", "?", "?")
m = host.machine()
print("# Fuzzing a bridge's intake\n")
print("Written by `bash deploy/fuzz.sh`.\n")
print("## Last run\n")
print(f"{host.described(m)}; {m['date']}; `bash deploy/fuzz.sh {seconds}`.\n")
print("| inputs executed | per second | code edges reached | corpus | findings |")
print("|---:|---:|---:|---:|---|")
executed = int(stats.get("number_of_executed_units", 0))
rate = int(stats.get("average_exec_per_sec", 0))
finding = "none" if status == 0 else f"the fuzzer stopped with status {status}: see its artifacts"
print(f"| {executed:,} | {rate:,} | {edges} | {corpus} | {finding} |")
