"""Q-value divergence of trained networks (EXPERIMENTS.md, "Session 7").

For each run directory given (one holding `weights.safetensors`, as `alfd local` and `alfd sweep`
write), plays 3 episodes in Gymnasium greedily on the mean of the heads' Q-values and prints the
largest and smallest Q-value seen and the mean return. Rewards lie in [r_min, r_max] per step, so
every true value lies in [r_min, r_max] / (1 - gamma) (CartPole-1000 at gamma = 0.995: [0, 200];
MountainCar and Acrobot at 0.99: [-100, 0]); a network whose Q-values leave that range by more
than a quarter of its width has diverged.

    bash deploy/bench/peers.sh --quick   # once: installs the virtual environment .venv-bench
    .venv-bench/bin/python deploy/bench/q_divergence.py runs/*/ ...

The environment and gamma are read from each run's `config.toml`.
"""

import argparse
import json
import struct
import sys
import tomllib
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


# Gymnasium id, episode limit and per-step reward range of each environment, as alfd runs them.
ENVS = {
    "cartpole": ("CartPole-v1", 1000, (0.0, 1.0)),
    "mountaincar": ("MountainCar-v0", 200, (-1.0, 0.0)),
    "acrobot": ("Acrobot-v1", 500, (-1.0, 0.0)),
}


def probe(path, env_name, episodes=3, seed=100):
    w, meta = load(path)
    heads, actions = int(meta.get("heads", 1)), int(meta.get("actions", 2))
    gym_id, limit, _ = ENVS[env_name]
    env = gym.make(gym_id, max_episode_steps=limit)
    q_max, q_min, returns = -np.inf, np.inf, []
    for e in range(episodes):
        obs, _ = env.reset(seed=seed + e)
        ret = 0.0
        while True:
            q = q_values(w, heads, actions, obs.astype(np.float32))
            q_max, q_min = max(q_max, float(q.max())), min(q_min, float(q.min()))
            obs, r, term, trunc, _ = env.step(int(q.mean(axis=0).argmax()))
            ret += r
            if term or trunc:
                break
        returns.append(ret)
    return q_max, q_min, float(np.mean(returns))


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("runs", nargs="+", type=Path)
    args = ap.parse_args()
    diverged = 0
    print("run\tmax Q\tmin Q\tgreedy return\ttrue values in")
    for run in args.runs:
        f, c = run / "weights.safetensors", run / "config.toml"
        if not (f.exists() and c.exists()):
            sys.exit(f"{run}: no weights.safetensors and config.toml (not a neural run directory)")
        config = tomllib.loads(c.read_text())
        env_name = config["env"]["name"]
        if env_name not in ENVS:
            sys.exit(f"{run}: environment {env_name!r}; this script knows {', '.join(sorted(ENVS))}")
        gamma = config["agent"]["gamma"]
        r_min, r_max = ENVS[env_name][2]
        lo, hi = r_min / (1.0 - gamma), r_max / (1.0 - gamma)
        slack = 0.25 * (hi - lo)
        q_max, q_min, ret = probe(f, env_name)
        bad = q_max > hi + slack or q_min < lo - slack
        diverged += bad
        print(f"{run}\t{q_max:.0f}\t{q_min:.0f}\t{ret:.0f}\t[{lo:.0f}, {hi:.0f}]{' diverged' if bad else ''}")
    print(f"diverged (Q beyond the true range by more than a quarter of its width): {diverged} of {len(args.runs)}")


if __name__ == "__main__":
    main()
