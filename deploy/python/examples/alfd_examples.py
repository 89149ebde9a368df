"""Example external demonstrators for `--expert python:alfd_examples:FUNCTION` (the adapter
finds this directory by itself). A demonstrator is any function of the observation (a NumPy
float32 array) that returns a discrete action."""


def acrobot_pump(obs):
    """Acrobot-v1: torque against the first link's angular velocity pumps energy into the swing
    until the tip clears the bar (the same rule alfd's conformance suite uses)."""
    return 0 if obs[4] > 0.0 else 2


def cartpole_balance(obs):
    """CartPole-v1: push towards where the pole falls (angle plus a share of its velocity)."""
    return 1 if obs[2] + 0.5 * obs[3] > 0.0 else 0


def cartpole_slow(obs):
    """cartpole_balance taking 15 ms an answer, as a slow policy or a remote service would: with
    `--query-timeout-ms` near or below that, some answers come after their actor stopped
    waiting (the run counts them in `answers_late` and keeps their demonstrations)."""
    import time

    time.sleep(0.015)
    return cartpole_balance(obs)


# --- Bring your own environment: a Gymnasium environment of your own, registered in a module.
# A config names it as "MODULE:ID" (gymnasium.make imports MODULE first):
#     [env]
#     name = "gymnasium"
#     id = "alfd_examples:AlfdCorridor-v0"
#     kwargs = { width = 6 }

import gymnasium as gym
import numpy as np


class Corridor(gym.Env):
    """A corridor of `width` cells: start in the first, reach the last (action 1 moves right,
    0 left); -1 per step. The observation is the position one-hot (`width` values), so `width`
    above alfd's MAX_OBS_DIM (64) is refused at start-up."""

    def __init__(self, width=5):
        self.width = int(width)
        self.action_space = gym.spaces.Discrete(2)
        self.observation_space = gym.spaces.Box(0.0, 1.0, (self.width,), np.float32)
        self.pos = 0

    def _obs(self):
        o = np.zeros(self.width, dtype=np.float32)
        o[self.pos] = 1.0
        return o

    def reset(self, *, seed=None, options=None):
        super().reset(seed=seed)
        self.pos = 0
        return self._obs(), {}

    def step(self, action):
        self.pos = min(self.width - 1, max(0, self.pos + (1 if int(action) == 1 else -1)))
        return self._obs(), -1.0, self.pos == self.width - 1, False, {}


gym.register(id="AlfdCorridor-v0", entry_point=Corridor, max_episode_steps=50)


def corridor_right(obs):
    """AlfdCorridor-v0: always right, the shortest way to the end."""
    return 1
