"""Gymnasium stepping in-process, the same loop as `alfd-bench-remote` (actions
(i*7 + i//3) % n, reset on episode end): the baseline of the remote adapter's steps/s.

    .venv/bin/python deploy/python/bench_inprocess.py [ENV_ID] [STEPS]
"""

import json
import sys
import time

import gymnasium as gym

env_id = sys.argv[1] if len(sys.argv) > 1 else "CartPole-v1"
steps = int(sys.argv[2]) if len(sys.argv) > 2 else 20000
env = gym.make(env_id)
n = int(env.action_space.n)
env.reset(seed=0)
episodes = 0
start = time.perf_counter()
for i in range(steps):
    _obs, _r, terminated, truncated, _ = env.step((i * 7 + i // 3) % n)
    if terminated or truncated:
        env.reset()
        episodes += 1
secs = time.perf_counter() - start
print(json.dumps({"bench": "gymnasium_in_process", "env": env_id, "steps": steps,
                  "episodes": episodes, "seconds": secs, "steps_per_s": steps / secs}))
