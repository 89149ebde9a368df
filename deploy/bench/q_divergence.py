"""Q-value divergence of trained CartPole networks (EXPERIMENTS.md, "Session 7").

For each run directory given (one holding `weights.safetensors`, as `alfd local` and `alfd sweep`
write), plays 3 CartPole-1000 episodes in Gymnasium greedily on the mean of the heads' Q-values
and prints the largest Q-value seen and the mean return. With reward 1 per step no true value
exceeds 1 / (1 - gamma) (200 at gamma = 0.995): a larger one is a diverged network.

    bash deploy/bench/peers.sh --quick   # once: installs the virtual environment .venv-bench
    .venv-bench/bin/python deploy/bench/q_divergence.py --gamma 0.995 runs/*/ ...
"""

import argparse
import json
import struct
import sys
from pathlib import Path

import gymnasium as gym
import numpy as np


def load(path):
    """The tensors of a safetensors file (all little-endian f32 here)."""
    with open(path, "rb") as f:
        n = struct.unpack("<Q", f.read(8))[0]
        header = json.loads(f.read(n))
        data = f.read()
    out = {}
    for name, t in header.items():
        if name == "__metadata__":
            continue
        if t["dtype"] != "F32":
            sys.exit(f"{path}: tensor {name} is {t['dtype']}, expected F32")
        lo, hi = t["data_offsets"]
        out[name] = np.frombuffer(data[lo:hi], dtype=np.float32).reshape(t["shape"])
    return out, header.get("__metadata__", {})


def q_values(w, heads, actions, x):
    h = np.maximum(w["torso.0.weight"] @ x + w["torso.0.bias"], 0)
    h = np.maximum(w["torso.1.weight"] @ h + w["torso.1.bias"], 0)
    return (w["heads.weight"] @ h + w["heads.bias"]).reshape(heads, actions)


def probe(path, episodes=3, seed=100):
    w, meta = load(path)
    heads, actions = int(meta.get("heads", 1)), int(meta.get("actions", 2))
    env = gym.make("CartPole-v1", max_episode_steps=1000)
    q_max, returns = -np.inf, []
    for e in range(episodes):
        obs, _ = env.reset(seed=seed + e)
        ret = 0.0
        while True:
            q = q_values(w, heads, actions, obs.astype(np.float32))
            q_max = max(q_max, float(q.max()))
            obs, r, term, trunc, _ = env.step(int(q.mean(axis=0).argmax()))
            ret += r
            if term or trunc:
                break
        returns.append(ret)
    return q_max, float(np.mean(returns))


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--gamma", type=float, default=0.995)
    ap.add_argument("runs", nargs="+", type=Path)
    args = ap.parse_args()
    bound = 1.0 / (1.0 - args.gamma)
    diverged = 0
    print(f"run\tmax Q\tgreedy return (bound on Q: {bound:.0f})")
    for run in args.runs:
        f = run / "weights.safetensors"
        if not f.exists():
            sys.exit(f"{run}: no weights.safetensors")
        q_max, ret = probe(f)
        diverged += q_max > 1.25 * bound
        print(f"{run}\t{q_max:.0f}\t{ret:.0f}")
    print(f"diverged (max Q > 1.25 x bound): {diverged} of {len(args.runs)}")


if __name__ == "__main__":
    main()
