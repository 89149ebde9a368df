"""Wall-clock to a greedy evaluation of at least 475 on CartPole-v1: alfd against
Stable-Baselines3's DQN with rl-zoo's CartPole-v1 settings, seeds interleaved in one sitting.

Ours: `alfd local` with the recommended CartPole preset on CartPole-v1's 500-step episodes,
evaluated greedily every 5 episodes over 10 episodes; the clock runs from the process's start
to the end of the episode whose evaluation first reaches 475 (the run is made once whole to find
that episode's environment step, then again, timed, cut there; `ours` says why). Twice: as the preset asks the expert (its demonstrations count; the evaluation is the
learner's own greedy play), and with `query.rule = "never"` (no demonstrations: the same kind of
learner as the peer). Theirs: `DQN("MlpPolicy", ...)` with rl-zoo's hyperparameters
(`hyperparams/dqn.yml`: learning rate 2.3e-3, batch 64, buffer 100,000, learning starts 1,000,
gamma 0.99, target update every 10, train frequency 256 with 128 gradient steps, exploration
fraction 0.16 to 0.04, two hidden layers of 256), evaluated by `EvalCallback` every 1,000
environment steps over 10 deterministic episodes and stopped by
`StopTrainingOnRewardThreshold(475)`; the clock runs from building the model to the stop.
A run that does not get there within its budget (ours 50,000 steps, theirs 100,000) counts as
not reached.
"""

import argparse
import csv
import json
import os
import statistics
import subprocess
import sys
import tempfile
import time

THRESHOLD = 475.0
PRESET = "deploy/configs/recommended/cartpole.toml"
OUR_SETS = ["env.max_episode_steps=500", "evaluation.every=5", "evaluation.episodes=10"]
VARIANTS = {
    "alfd (preset, asks the expert)": [],
    "alfd (no demonstrations)": ["query.rule=\"never\"", "budget.total=0"],
}
THEIR_STEPS = 100_000


def first_at_threshold(path):
    """(episode, environment steps so far) of the first evaluation of at least THRESHOLD in an
    episodes.csv, or None."""
    with open(path, newline="") as f:
        for row in csv.DictReader(f):
            if row["eval_return"] and float(row["eval_return"]) >= THRESHOLD:
                return int(row["episode"]), int(row["total_steps"])
    return None


def local(alfd, sets, out):
    """Runs `alfd local` on the preset with `sets`; its wall-clock in seconds."""
    cmd = [alfd, "local", "--config", PRESET, "--out", out, "--quiet"]
    for s in OUR_SETS + sets:
        cmd += ["--set", s]
    start = time.perf_counter()
    done = subprocess.run(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
    took = time.perf_counter() - start
    if done.returncode != 0:
        sys.exit(f"solve.py: {' '.join(cmd)} failed: {done.stderr}")
    return took


def ours(alfd, sets, seed, workdir):
    """Seconds of `alfd local` from its start to its first evaluation >= THRESHOLD (None if its
    50,000 steps end first), and the episode it came at. `alfd local` writes `episodes.csv` at its
    end, so the run is made twice: once whole, to find the environment steps N at the end of
    that evaluation's episode, then again, timed, with `steps = N` (the same seed plays the same
    episodes, so it ends with that evaluation, which is checked)."""
    tag = "-".join(sets).replace("=", "").replace('"', "") or "preset"
    probe = os.path.join(workdir, f"probe-{seed}-{tag}")
    local(alfd, sets + [f"seed={seed}"], probe)
    found = first_at_threshold(os.path.join(probe, "episodes.csv"))
    if found is None:
        return None, None
    episode, steps = found
    timed = os.path.join(workdir, f"timed-{seed}-{tag}")
    took = local(alfd, sets + [f"seed={seed}", f"steps={steps}"], timed)
    if first_at_threshold(os.path.join(timed, "episodes.csv")) != found:
        sys.exit(f"solve.py: the run cut at {steps} steps did not end with the evaluation of "
                 f"episode {episode} ({timed})")
    return took, episode


def theirs(seed):
    """Seconds from building SB3's DQN to its first evaluation >= THRESHOLD (None if not within
    THEIR_STEPS), and the environment steps it took."""
    import gymnasium
    import torch
    from stable_baselines3 import DQN
    from stable_baselines3.common.callbacks import EvalCallback, StopTrainingOnRewardThreshold
    from stable_baselines3.common.monitor import Monitor

    torch.set_num_threads(1)
    start = time.perf_counter()
    env = gymnasium.make("CartPole-v1")
    model = DQN("MlpPolicy", env, learning_rate=2.3e-3, batch_size=64, buffer_size=100_000,
                learning_starts=1000, gamma=0.99, target_update_interval=10, train_freq=256,
                gradient_steps=128, exploration_fraction=0.16, exploration_final_eps=0.04,
                policy_kwargs=dict(net_arch=[256, 256]), seed=seed, verbose=0)
    stop = StopTrainingOnRewardThreshold(reward_threshold=THRESHOLD, verbose=0)
    evaluate = EvalCallback(Monitor(gymnasium.make("CartPole-v1")), eval_freq=1000, n_eval_episodes=10,
                            deterministic=True, callback_on_new_best=stop, verbose=0)
    model.learn(total_timesteps=THEIR_STEPS, callback=evaluate)
    took = time.perf_counter() - start
    reached = evaluate.best_mean_reward >= THRESHOLD
    return (took if reached else None), model.num_timesteps


def seconds(xs):
    got = [x for x in xs if x is not None]
    if not got:
        return f"not reached (0 of {len(xs)})"
    text = f"{statistics.median(got):.1f} s ({min(got):.1f}-{max(got):.1f})"
    if len(got) < len(xs):
        text += f", {len(got)} of {len(xs)} reached"
    return text


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--alfd", required=True)
    parser.add_argument("--seeds", type=int, default=3)
    parser.add_argument("--out", help="a directory to write solve.md and solve.json to")
    args = parser.parse_args()
    sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
    from host import described, machine

    workdir = tempfile.mkdtemp(prefix="solve-bench-")
    load_before = os.getloadavg()[0]
    results = {name: [] for name in VARIANTS}
    results["Stable-Baselines3 DQN (rl-zoo settings)"] = []
    detail = []
    for seed in range(args.seeds):
        for name, sets in VARIANTS.items():
            print(f"solve.py: seed {seed}: {name}", file=sys.stderr, flush=True)
            took, episode = ours(args.alfd, sets, seed, workdir)
            results[name].append(took)
            detail.append({"who": name, "seed": seed, "seconds": took, "episode": episode})
        print(f"solve.py: seed {seed}: Stable-Baselines3", file=sys.stderr, flush=True)
        took, steps = theirs(seed)
        results["Stable-Baselines3 DQN (rl-zoo settings)"].append(took)
        detail.append({"who": "sb3", "seed": seed, "seconds": took, "env_steps": steps})
    load_after = os.getloadavg()[0]

    peer = [x for x in results["Stable-Baselines3 DQN (rl-zoo settings)"] if x is not None]
    lines = [
        "## Wall-clock to a greedy evaluation of 475 on CartPole-v1",
        "",
        "Written by `bash deploy/bench/peers.sh` (`deploy/bench/solve.py`, whose docstring says "
        "how each side is run and timed); every run is in `solve.json`.",
        "",
        f"| learner | wall-clock to ≥ {THRESHOLD:.0f}, median (min-max) over seeds 0-{args.seeds - 1} "
        "| peer / ours |",
        "|---|---|---:|",
    ]
    for name, xs in results.items():
        got = [x for x in xs if x is not None]
        ratio = ""
        if peer and got and not name.startswith("Stable"):
            ratio = f"{statistics.median(peer) / statistics.median(got):.1f}×"
        lines.append(f"| {name} | {seconds(xs)} | {ratio} |")
    lines += ["", f"Machine: {described(machine())}; load average {load_before:.2f} before, "
              f"{load_after:.2f} after; {time.strftime('%Y-%m-%d')}.", ""]
    print("\n".join(lines))
    if args.out:
        os.makedirs(args.out, exist_ok=True)
        with open(os.path.join(args.out, "solve.md"), "w") as f:
            f.write("\n".join(lines))
        with open(os.path.join(args.out, "solve.json"), "w") as f:
            json.dump({"threshold": THRESHOLD, "runs": detail}, f, indent=1)


if __name__ == "__main__":
    main()
