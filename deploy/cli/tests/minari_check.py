"""The Minari side of alfd's Minari round trip (deploy/cli/tests/minari.rs), run with the pinned
`minari` package of the project's .venv. MINARI_DATASETS_PATH names the datasets' root.

  python minari_check.py load ID     # prints what minari.load_dataset(ID) reads, as JSON
  python minari_check.py write ID N  # writes N CartPole-v1 episodes of a weak expert as ID
"""

import json
import sys

import gymnasium as gym
import minari
import numpy as np
from minari.data_collector.episode_buffer import EpisodeBuffer


def load(dataset_id):
    ds = minari.load_dataset(dataset_id)
    episodes = list(ds.iterate_episodes())
    env = ds.recover_environment()
    print(json.dumps({
        "total_episodes": ds.total_episodes,
        "total_steps": int(ds.total_steps),
        "lengths": [int(len(e.actions)) for e in episodes],
        "demonstrated": [int(np.sum(e.infos["demonstrated"])) for e in episodes],
        "first_observations": np.asarray(episodes[0].observations[:3]).tolist(),
        "first_actions": np.asarray(episodes[0].actions[:3]).tolist(),
        "terminations": [bool(e.terminations[-1]) for e in episodes],
        "truncations": [bool(e.truncations[-1]) for e in episodes],
        "env_id": env.spec.id,
        "max_episode_steps": env.spec.max_episode_steps,
        "observation_shape": list(ds.observation_space.shape),
        "actions": int(ds.action_space.n),
    }))


def write(dataset_id, n):
    """A weak expert: push toward the side the pole leans to, ignoring the cart."""
    env = gym.make("CartPole-v1")
    buffers = []
    for seed in range(n):
        obs, _ = env.reset(seed=seed)
        o, a, r, term, trunc = [obs], [], [], [], []
        done = False
        while not done:
            action = int(obs[2] > 0)
            obs, reward, terminated, truncated, _ = env.step(action)
            o.append(obs), a.append(action), r.append(reward)
            term.append(terminated), trunc.append(truncated)
            done = terminated or truncated
        buffers.append(EpisodeBuffer(
            observations=np.array(o), actions=np.array(a), rewards=np.array(r),
            terminations=np.array(term), truncations=np.array(trunc)))
    ds = minari.create_dataset_from_buffers(
        dataset_id, buffers, env=env, algorithm_name="pole-angle", author="alfd tests",
        data_format="arrow")
    print(json.dumps({"total_episodes": ds.total_episodes, "total_steps": int(ds.total_steps)}))


if __name__ == "__main__":
    import warnings
    warnings.simplefilter("ignore")
    if sys.argv[1] == "load":
        load(sys.argv[2])
    else:
        write(sys.argv[2], int(sys.argv[3]))
