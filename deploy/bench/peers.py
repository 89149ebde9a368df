"""Side-by-side speed of alfd and its Python peers.

Run through deploy/bench/peers.sh, which builds our binaries and prepares the virtual environment.
Every quantity is measured once per round, ours then theirs, for a few rounds, so that a change in
the machine's load falls on both sides; the table shows the medians over the rounds and their
range.

Quantities:
- the learner's train step: the 4-64-64-4 network (K = 2 heads of A = 2 actions), batch 64,
  online forward, target forward, SmoothL1 TD loss masked per head, backward, Adam (ours:
  Criterion's `train_step_k2_a2_b64` in common/core/benches/core.rs; theirs: the same step in PyTorch);
- the actor's act step: one observation through the network, a softmax per head, their
  Jensen-Shannon divergence and the greedy action (ours: `act_step_k2_a2`, which also runs the
  query rule; theirs: PyTorch);
- environment steps per second of CartPole, MountainCar-v0 and Acrobot-v1, a fixed random-looking
  action sequence, reset when an episode ends (ours: common/core/benches/envs.rs; theirs: Gymnasium's
  environments made with `gymnasium.make`, in this process);
- end to end: DQN on CartPole with the paper's settings, environment steps per second of the
  training loop's wall-clock (ours: `alfd local`, whose summary reports that wall-clock; theirs:
  a minimal DQN loop below in PyTorch and Gymnasium).

PyTorch runs on one thread, as our learner does.
"""

import argparse
import copy
import datetime
import json
import math
import os
import platform
import shutil
import statistics
import subprocess
import sys
import tempfile
import time

import gymnasium
import numpy as np
import torch
import torch.nn.functional as F

OBS = 4
HIDDEN = 64
HEADS = 2
ACTIONS = 2
BATCH = 64
GAMMA = 0.99

# The DQN settings of deploy/configs/cartpole-dqn-*.toml, without the expert.
DQN_CONFIG = """\
seed = 0
steps = {steps}

[env]
name = "cartpole"
max_episode_steps = 1000

[agent]
kind = "dqn"
exploration = "epsilon-greedy"
epsilon_start = 1.0
epsilon_end = 0.05
epsilon_decay_steps = 1000.0
gamma = 0.99
learning_rate = 0.001
replay_capacity = 10000
batch_size = 64
target_update_every = 50
updates_per_step = 1
hidden = 64

[query]
mode = "never"
"""

ENVS = [
    # (row label, our Criterion id, Gymnasium id, keyword arguments of gymnasium.make)
    ("CartPole", "envs/env_step_cartpole", "CartPole-v1", {"max_episode_steps": 1_000_000}),
    ("MountainCar-v0", "envs/env_step_mountaincar", "MountainCar-v0", {}),
    ("Acrobot-v1", "envs/env_step_acrobot", "Acrobot-v1", {}),
]


# --- timing -------------------------------------------------------------------------------------


def seconds_per_call(run, seconds, windows=9):
    """Median time of one call of the work `run(n)` does n times, over `windows` windows that
    together last about `seconds` (after a warm-up as long as one window)."""
    n = 1
    while True:
        start = time.perf_counter()
        run(n)
        elapsed = time.perf_counter() - start
        if elapsed > 0.02:
            break
        n *= 2
    n = max(1, int(n * (seconds / windows) / elapsed))
    run(n)
    times = []
    for _ in range(windows):
        start = time.perf_counter()
        run(n)
        times.append((time.perf_counter() - start) / n)
    return statistics.median(times)


class Ours:
    """Our side: the Criterion bench binaries and `alfd`."""

    def __init__(self, args, workdir):
        self.args = args
        self.workdir = workdir
        self.criterion_home = os.path.join(workdir, "criterion")
        self.runs = 0

    def criterion_seconds(self, binary, bench_id):
        """Criterion's median time of one iteration of `bench_id`, in seconds."""
        warm, measure = ("0.3", "1") if self.args.quick else ("1", "3")
        env = dict(os.environ, CRITERION_HOME=self.criterion_home)
        cmd = [binary, "--bench", "--warm-up-time", warm, "--measurement-time", measure,
               "--noplot", "--exact", bench_id]
        subprocess.run(cmd, env=env, check=True, stdout=subprocess.DEVNULL,
                       stderr=subprocess.DEVNULL)
        path = os.path.join(self.criterion_home, bench_id, "new", "estimates.json")
        with open(path) as f:
            return json.load(f)["median"]["point_estimate"] * 1e-9

    def train_step(self):
        return self.criterion_seconds(self.args.core_bench, "train_step_k2_a2_b64")

    def act_step(self):
        return self.criterion_seconds(self.args.core_bench, "act_step_k2_a2")

    def env_steps_per_s(self, bench_id):
        return 1.0 / self.criterion_seconds(self.args.envs_bench, bench_id)

    def dqn_steps_per_s(self, steps):
        config = os.path.join(self.workdir, "dqn.toml")
        with open(config, "w") as f:
            f.write(DQN_CONFIG.format(steps=steps))
        self.runs += 1
        out = os.path.join(self.workdir, f"run-{self.runs}")
        done = subprocess.run([self.args.alfd, "local", "--config", config, "--out", out,
                               "--json", "--quiet"], check=True, capture_output=True, text=True)
        summary = json.loads(done.stdout.strip().splitlines()[-1])
        shutil.rmtree(out, ignore_errors=True)
        return steps / summary["wall_clock_s"]


# --- theirs: PyTorch and Gymnasium --------------------------------------------------------------


def mlp(outputs):
    """The 4-64-64-outputs ReLU network, PyTorch's default initialisation."""
    return torch.nn.Sequential(
        torch.nn.Linear(OBS, HIDDEN), torch.nn.ReLU(),
        torch.nn.Linear(HIDDEN, HIDDEN), torch.nn.ReLU(),
        torch.nn.Linear(HIDDEN, outputs),
    )


def torch_train_step(seconds):
    """Seconds per train step of K = 2 heads, as `nn::train_step`: for head k and sample i,
    y = r + gamma (1 - terminated) max_a Q_target_k(s', a), loss = sum_k sum_i mask_ik
    SmoothL1(Q_k(s_i, a_i), y_ik) / B, then one Adam step. One fixed batch, as in core.rs."""
    gen = torch.Generator().manual_seed(1)
    online = mlp(HEADS * ACTIONS)
    target = copy.deepcopy(online).requires_grad_(False)
    adam = torch.optim.Adam(online.parameters(), lr=1e-3)
    states = torch.rand(BATCH, OBS, generator=gen) * 4 - 2
    next_states = torch.rand(BATCH, OBS, generator=gen) * 4 - 2
    actions = torch.randint(0, ACTIONS, (BATCH,), generator=gen)
    rewards = torch.ones(BATCH)
    terminated = (torch.rand(BATCH, generator=gen) < 0.05).float()
    masks = (torch.rand(BATCH, HEADS, generator=gen) < 0.5).float()
    index = actions.view(BATCH, 1, 1).expand(BATCH, HEADS, 1)

    def run(n):
        for _ in range(n):
            q = online(states).view(BATCH, HEADS, ACTIONS).gather(2, index).squeeze(2)
            with torch.no_grad():
                best_next = target(next_states).view(BATCH, HEADS, ACTIONS).amax(dim=2)
                y = rewards.unsqueeze(1) + GAMMA * (1 - terminated).unsqueeze(1) * best_next
            loss = (F.smooth_l1_loss(q, y, reduction="none") * masks).sum() / BATCH
            adam.zero_grad()
            loss.backward()
            adam.step()

    return seconds_per_call(run, seconds)


def torch_act_step(seconds):
    """Seconds per act step: an observation (a NumPy array, as Gymnasium gives it) through the
    network, a softmax per head, the Jensen-Shannon divergence of the heads' policies
    H(mean_k pi_k) - mean_k H(pi_k), and the greedy action of one head, both as Python numbers."""
    net = mlp(HEADS * ACTIONS)
    rng = np.random.default_rng(2)
    states = rng.uniform(-2, 2, size=(256, OBS)).astype(np.float32)
    temperature = 1.0
    i = 0

    def run(n):
        nonlocal i
        for _ in range(n):
            i = (i + 1) % len(states)
            with torch.no_grad():
                q = net(torch.from_numpy(states[i])).view(HEADS, ACTIONS)
                log_pi = torch.log_softmax(q / temperature, dim=1)
                pi = log_pi.exp()
                mean_entropy = -(pi * log_pi).sum(dim=1).mean()
                mix = pi.mean(dim=0)
                js = -(mix * mix.log()).sum() - mean_entropy
                action = int(q[0].argmax())
                divergence = max(float(js), 0.0)
        return action, divergence

    return seconds_per_call(run, seconds)


def gym_steps_per_s(env_id, kwargs, seconds):
    """Steps per second of a Gymnasium environment made with `gymnasium.make`, through a fixed
    random-looking action sequence, reset (without a new seed) when an episode ends."""
    env = gymnasium.make(env_id, **kwargs)
    rng = np.random.default_rng(7)
    actions = [int(a) for a in rng.integers(0, env.action_space.n, size=4096)]
    env.reset(seed=0)
    i = 0

    def run(n):
        nonlocal i
        step, reset = env.step, env.reset
        for _ in range(n):
            i = (i + 1) % len(actions)
            _, _, terminated, truncated, _ = step(actions[i])
            if terminated or truncated:
                reset()

    per_step = seconds_per_call(run, seconds)
    env.close()
    return 1.0 / per_step


def torch_dqn_steps_per_s(steps, seed=0):
    """A minimal DQN on CartPole with the settings of DQN_CONFIG: 4-64-64-2 network, Adam at
    1e-3, replay of 10,000, batch 64, one update per step once the buffer holds a batch, target
    copied every 50 updates, gamma 0.99, SmoothL1 loss, epsilon 1 -> 0.05 with time constant 1000
    steps. Returns environment steps per second of the loop's wall-clock."""
    torch.manual_seed(seed)
    rng = np.random.default_rng(seed)
    env = gymnasium.make("CartPole-v1", max_episode_steps=1000)
    online = mlp(ACTIONS)
    target = copy.deepcopy(online).requires_grad_(False)
    adam = torch.optim.Adam(online.parameters(), lr=1e-3)
    capacity = 10_000
    buf_obs = np.zeros((capacity, OBS), dtype=np.float32)
    buf_next = np.zeros((capacity, OBS), dtype=np.float32)
    buf_action = np.zeros(capacity, dtype=np.int64)
    buf_reward = np.zeros(capacity, dtype=np.float32)
    buf_terminated = np.zeros(capacity, dtype=np.float32)
    size = 0
    updates = 0

    obs, _ = env.reset(seed=seed)
    start = time.perf_counter()
    for step in range(steps):
        epsilon = 0.05 + 0.95 * math.exp(-step / 1000.0)
        if rng.random() < epsilon:
            action = int(rng.integers(ACTIONS))
        else:
            with torch.no_grad():
                action = int(online(torch.from_numpy(obs)).argmax())
        next_obs, reward, terminated, truncated, _ = env.step(action)
        slot = step % capacity
        buf_obs[slot] = obs
        buf_next[slot] = next_obs
        buf_action[slot] = action
        buf_reward[slot] = reward
        buf_terminated[slot] = float(terminated)
        size = min(size + 1, capacity)
        obs = next_obs
        if terminated or truncated:
            obs, _ = env.reset()
        if size >= BATCH:
            idx = rng.integers(0, size, size=BATCH)
            s = torch.from_numpy(buf_obs[idx])
            a = torch.from_numpy(buf_action[idx])
            r = torch.from_numpy(buf_reward[idx])
            s2 = torch.from_numpy(buf_next[idx])
            done = torch.from_numpy(buf_terminated[idx])
            with torch.no_grad():
                y = r + GAMMA * (1 - done) * target(s2).amax(dim=1)
            q = online(s).gather(1, a.unsqueeze(1)).squeeze(1)
            loss = F.smooth_l1_loss(q, y)
            adam.zero_grad()
            loss.backward()
            adam.step()
            updates += 1
            if updates % 50 == 0:
                target.load_state_dict(online.state_dict())
    elapsed = time.perf_counter() - start
    env.close()
    return steps / elapsed


# --- report -------------------------------------------------------------------------------------


def machine():
    model, cpus = platform.processor() or "?", os.cpu_count()
    try:
        out = subprocess.run(["lscpu"], capture_output=True, text=True, check=True).stdout
        for line in out.splitlines():
            key, _, value = line.partition(":")
            if key.strip() == "Model name":
                model = value.strip()
            elif key.strip() == "CPU(s)":
                cpus = value.strip()
    except (OSError, subprocess.CalledProcessError):
        pass
    return model, cpus


def load_average():
    try:
        with open("/proc/loadavg") as f:
            return " ".join(f.read().split()[:3])
    except OSError:
        return "?"


def rustc_version():
    try:
        return subprocess.run(["rustc", "-V"], capture_output=True, text=True).stdout.strip()
    except OSError:
        return "rustc ?"


def scaled(values, kind):
    """`values` (seconds, or per second) in one unit chosen by their median: the median, its
    range, and the unit."""
    med = statistics.median(values)
    if kind == "time":
        scale, unit = (1e6, "µs") if med < 1e-3 else (1e3, "ms")
    elif med >= 1e6:
        scale, unit = 1e-6, "M/s"
    elif med >= 1e4:
        scale, unit = 1e-3, "k/s"
    else:
        scale, unit = 1.0, "/s"
    digits = 0 if unit == "/s" else 2 if med * scale < 10 else 1 if med * scale < 1000 else 0
    show = lambda v: f"{v * scale:,.{digits}f}"
    text = f"{show(med)}{'' if unit == '/s' else ' '}{unit}"
    if len(values) > 1:
        text += f" ({show(min(values))}-{show(max(values))})"
    return text


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--core-bench", required=True, help="the Criterion binary of core.rs")
    parser.add_argument("--envs-bench", required=True, help="the Criterion binary of envs.rs")
    parser.add_argument("--alfd", required=True, help="the alfd binary")
    parser.add_argument("--quick", action="store_true", help="a short smoke run: one round")
    parser.add_argument("--out", help="a directory to write summary.md and results.json to")
    parser.add_argument("--rounds", type=int, help="rounds of ours-then-theirs (default 5)")
    parser.add_argument("--dqn-steps", type=int,
                        help="environment steps of the end-to-end runs (default 3064: 64 to fill "
                        "a batch, then 3000 with an update each)")
    args = parser.parse_args()
    rounds = args.rounds or (1 if args.quick else 5)
    seconds = 1.0 if args.quick else 3.0
    dqn_steps = args.dqn_steps or (564 if args.quick else 3064)

    torch.set_num_threads(1)
    torch.set_num_interop_threads(1)

    model, cpus = machine()
    load_before = load_average()
    started = time.time()
    workdir = tempfile.mkdtemp(prefix="peers-bench-")
    ours = Ours(args, workdir)

    # (label, kind, our measure, their measure); kind "time" (lower is better) or "rate".
    rows = [
        ("train step, K=2 A=2 batch 64", "time", ours.train_step,
         lambda: torch_train_step(seconds)),
        ("act step, K=2 A=2 (forward, softmax, JS)", "time", ours.act_step,
         lambda: torch_act_step(seconds)),
    ]
    for label, bench_id, gym_id, kwargs in ENVS:
        rows.append((f"{label} env steps/s", "rate",
                     lambda b=bench_id: ours.env_steps_per_s(b),
                     lambda g=gym_id, k=kwargs: gym_steps_per_s(g, k, seconds)))
    rows.append((f"DQN on CartPole, {dqn_steps} steps: env steps/s", "rate",
                 lambda: ours.dqn_steps_per_s(dqn_steps),
                 lambda: torch_dqn_steps_per_s(dqn_steps)))

    results = {label: ([], []) for label, *_ in rows}
    try:
        for r in range(rounds):
            for label, _, measure_ours, measure_theirs in rows:
                print(f"round {r + 1}/{rounds}: {label}", file=sys.stderr, flush=True)
                results[label][0].append(measure_ours())
                results[label][1].append(measure_theirs())
    finally:
        shutil.rmtree(workdir, ignore_errors=True)
    load_after = load_average()
    minutes = (time.time() - started) / 60

    lines = ["# Side by side with PyTorch and Gymnasium", "",
             "Written by `bash deploy/bench/peers.sh`; every number is in `results.json`.", "",
             "## Ratios", "",
             "| quantity | ours | PyTorch / Gymnasium | ratio (ours faster) |",
             "|---|---|---|---|"]
    for label, kind, *_ in rows:
        mine, theirs = results[label]
        ratio = statistics.median(theirs) / statistics.median(mine)
        if kind == "rate":
            ratio = 1.0 / ratio
        lines.append(f"| {label} | {scaled(mine, kind)} | {scaled(theirs, kind)} | "
                     f"{ratio:,.1f}× |")
    versions = (f"{rustc_version()}; Python {platform.python_version()}, torch "
                f"{torch.__version__} ({torch.get_num_threads()} thread), gymnasium "
                f"{gymnasium.__version__}, numpy {np.__version__}")
    date = datetime.datetime.now().astimezone().strftime('%Y-%m-%d %H:%M %Z')
    lines += ["", f"Medians over {rounds} interleaved round(s), range in parentheses; "
              f"{minutes:.1f} min of measuring. Machine: {model}, {cpus} CPU(s); load average "
              f"{load_before} before, {load_after} after. {date}. Versions: {versions}.", ""]
    print("\n".join(lines))
    if args.out:
        os.makedirs(args.out, exist_ok=True)
        with open(os.path.join(args.out, "summary.md"), "w") as f:
            f.write("\n".join(lines))
        with open(os.path.join(args.out, "results.json"), "w") as f:
            json.dump({"rounds": rounds, "date": date, "machine": f"{model}, {cpus} CPU(s)",
                       "load_before": load_before, "load_after": load_after,
                       "versions": versions,
                       "rows": {label: {"kind": kind, "ours": results[label][0],
                                        "theirs": results[label][1]}
                                for label, kind, *_ in rows}}, f, indent=1)

if __name__ == "__main__":
    main()
