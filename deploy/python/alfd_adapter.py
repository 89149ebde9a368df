"""alfd's Python adapter: serves a Gymnasium environment, or an external demonstrator, to the
alfd processes over iceoryx2 (the `remote/<name>` services of common/wire/src/remote.rs).

    alfd_adapter.py env    --run-id R --name env-0 --schema S --id Acrobot-v1 [--kwargs JSON]
    alfd_adapter.py env    --check --id Acrobot-v1 [--kwargs JSON] [--max-episode-steps N]
    alfd_adapter.py expert --run-id R --name expert-1 --schema S --policy python:MODULE:FUNCTION
    alfd_adapter.py expert ... --policy sb3:ALGO:PATH.zip   (Stable-Baselines3, if installed)

An environment must have a `Discrete` action space and a one-dimensional `Box` observation of at
most MAX_OBS_DIM values, or a `Discrete` observation of at most MAX_OBS_DIM states, which the agent
(and an external demonstrator) sees one-hot encoded; any other space is refused at start-up (exit
code 2, naming the space).
`--check` only makes the environment and prints its spec as JSON (the launcher's probe).
The alfd processes start the adapters; a person does not need to.
"""

import argparse
import ctypes
import importlib
import json
import os
import signal
import sys

# Mirrors of common/wire/src/remote.rs (checked there: sizes 568 and 712).
MAX_REMOTE_VALUES = 64
MAX_OBS_DIM = MAX_REMOTE_VALUES
REMOTE_MESSAGE_LEN = 128
ROLE_TOOL = 5

OPEN, RESET, STEP, GET_STATE, SET_STATE, CLOSE, ACT = 1, 2, 3, 4, 5, 6, 7
OK, FAILED = 0, 1

# remote_limits in remote.rs: every side builds the services with these settings.
MAX_SERVERS = 1
MAX_CLIENTS = 16
MAX_NODES = 32
MAX_ACTIVE_REQUESTS_PER_CLIENT = 2
MAX_RESPONSE_BUFFER_SIZE = 2
MAX_LISTENERS = 16
MAX_NOTIFIERS = 16
EVENT_ID_MAX_VALUE = 255

EXIT_BAD_INPUT = 2


class Header(ctypes.Structure):
    _fields_ = [
        ("schema", ctypes.c_uint32),
        ("role", ctypes.c_uint16),
        ("id", ctypes.c_uint16),
        ("seq", ctypes.c_uint64),
    ]


class RemoteRequest(ctypes.Structure):
    _fields_ = [
        ("header", Header),
        ("kind", ctypes.c_uint32),
        ("session", ctypes.c_uint32),
        ("action", ctypes.c_uint32),
        ("has_seed", ctypes.c_uint32),
        ("seed", ctypes.c_uint64),
        ("max_episode_steps", ctypes.c_uint64),
        ("len", ctypes.c_uint32),
        ("_pad", ctypes.c_uint32),
        ("values", ctypes.c_double * MAX_REMOTE_VALUES),
    ]

    @staticmethod
    def type_name():
        return "alfd.RemoteRequest"


class RemoteResponse(ctypes.Structure):
    _fields_ = [
        ("header", Header),
        ("request_seq", ctypes.c_uint64),
        ("kind", ctypes.c_uint32),
        ("status", ctypes.c_uint32),
        ("session", ctypes.c_uint32),
        ("action", ctypes.c_uint32),
        ("obs_dim", ctypes.c_uint32),
        ("terminated", ctypes.c_uint32),
        ("truncated", ctypes.c_uint32),
        ("len", ctypes.c_uint32),
        ("max_episode_steps", ctypes.c_uint64),
        ("reward", ctypes.c_double),
        ("values", ctypes.c_double * MAX_REMOTE_VALUES),
        ("message", ctypes.c_char * REMOTE_MESSAGE_LEN),
    ]

    @staticmethod
    def type_name():
        return "alfd.RemoteResponse"


assert ctypes.sizeof(RemoteRequest) == 568 and ctypes.sizeof(RemoteResponse) == 712


class BadInput(Exception):
    """Refused at start-up: exit code 2."""


# --------------------------------------------------------------------------------------------
# The environment
# --------------------------------------------------------------------------------------------


def make_env(env_id, kwargs, max_episode_steps):
    """`gymnasium.make` with the spaces checked; BadInput names a space alfd cannot carry."""
    import gymnasium as gym
    import numpy as np

    try:
        env = gym.make(
            env_id,
            max_episode_steps=max_episode_steps if max_episode_steps > 0 else None,
            **kwargs,
        )
    except Exception as e:  # unknown id, bad kwargs, a missing extra
        raise BadInput(f"gymnasium.make({env_id!r}, **{kwargs!r}) failed: {e}") from e
    act, obs = env.action_space, env.observation_space
    if not isinstance(act, gym.spaces.Discrete):
        raise BadInput(
            f"{env_id}: the action space {act} is not Discrete; alfd's agents choose among "
            "discrete actions"
        )
    if int(act.start) != 0:
        raise BadInput(f"{env_id}: the action space {act} does not start at 0")
    if isinstance(obs, gym.spaces.Discrete):
        if not 0 < int(obs.n) <= MAX_OBS_DIM:
            raise BadInput(
                f"{env_id}: the observation space {obs} has {int(obs.n)} states; one-hot, the "
                f"wire carries 1 to MAX_OBS_DIM = {MAX_OBS_DIM}"
            )
        return env
    if not isinstance(obs, gym.spaces.Box) or len(obs.shape) != 1:
        raise BadInput(
            f"{env_id}: the observation space {obs} is neither a one-dimensional Box nor Discrete"
        )
    if obs.shape[0] > MAX_OBS_DIM or obs.shape[0] == 0:
        raise BadInput(
            f"{env_id}: the observation space {obs} has {obs.shape[0]} values; the wire "
            f"carries 1 to MAX_OBS_DIM = {MAX_OBS_DIM}"
        )
    if not np.issubdtype(obs.dtype, np.floating) and not np.issubdtype(obs.dtype, np.integer):
        raise BadInput(f"{env_id}: the observation space {obs} is not numeric")
    return env


def obs_dim_of(space):
    """Values the agent sees of an observation of `space` (a Discrete one one-hot)."""
    n = getattr(space, "n", None)
    return int(n) if n is not None else int(space.shape[0])


def encode(space, obs):
    """An observation as the agent sees it: a Discrete state one-hot, anything else as it is."""
    n = getattr(space, "n", None)
    if n is None:
        return obs
    one_hot = [0.0] * int(n)
    one_hot[int(obs) - int(space.start)] = 1.0
    return one_hot


def spec_of(env):
    limit = env.spec.max_episode_steps if env.spec is not None else None
    return {
        "obs_dim": obs_dim_of(env.observation_space),
        "num_actions": int(env.action_space.n),
        "max_episode_steps": int(limit or 0),
    }


class EnvServer:
    """Sessions of one environment id: each OPEN makes a fresh environment."""

    def __init__(self, env_id, kwargs):
        self.env_id, self.kwargs = env_id, kwargs
        self.sessions = {}
        self.next_session = 1

    def handle(self, req, resp):
        kind = req.kind
        if kind == OPEN:
            env = make_env(self.env_id, self.kwargs, int(req.max_episode_steps))
            session = self.next_session
            self.next_session += 1
            self.sessions[session] = {"env": env, "seeded": False}
            spec = spec_of(env)
            resp.session = session
            resp.obs_dim = spec["obs_dim"]
            resp.action = spec["num_actions"]
            resp.max_episode_steps = spec["max_episode_steps"]
            return
        s = self.sessions.get(req.session)
        if s is None:
            raise ValueError(f"no session {req.session}")
        env = s["env"]
        if kind == RESET:
            # A session's first reset without a seed uses seed 0 (alfd's Env contract).
            if req.has_seed:
                seed = int(req.seed)
            elif not s["seeded"]:
                seed = 0
            else:
                seed = None
            s["seeded"] = True
            obs, _info = env.reset(seed=seed)
            put_values(resp, encode(env.observation_space, obs))
        elif kind == STEP:
            obs, reward, terminated, truncated, _info = env.step(int(req.action))
            put_values(resp, encode(env.observation_space, obs))
            resp.reward = float(reward)
            resp.terminated = int(bool(terminated))
            resp.truncated = int(bool(truncated))
        elif kind == GET_STATE:
            put_values(resp, internal_state(env))
        elif kind == SET_STATE:
            import numpy as np

            current = internal_state(env)
            n = int(req.len)
            if n != len(current):
                raise ValueError(f"a state of {n} values, the environment's has {len(current)}")
            env.unwrapped.state = np.array(req.values[:n], dtype=np.float64).reshape(
                np.shape(env.unwrapped.state)
            )
        elif kind == CLOSE:
            env.close()
            del self.sessions[req.session]
        else:
            raise ValueError(f"unknown request kind {kind}")


def internal_state(env):
    import numpy as np

    state = getattr(env.unwrapped, "state", None)
    if state is None:
        raise ValueError(f"{env.spec.id if env.spec else env}: has no `state` attribute")
    flat = np.asarray(state, dtype=np.float64).ravel()
    if len(flat) > MAX_REMOTE_VALUES:
        raise ValueError(f"an internal state of {len(flat)} values (at most {MAX_REMOTE_VALUES})")
    return flat


def put_values(resp, values):
    flat = [float(v) for v in __import__("numpy").asarray(values, dtype="float64").ravel()]
    if len(flat) > MAX_REMOTE_VALUES:
        raise ValueError(f"{len(flat)} values, at most {MAX_REMOTE_VALUES}")
    for i, v in enumerate(flat):
        resp.values[i] = v
    resp.len = len(flat)


# --------------------------------------------------------------------------------------------
# The demonstrator
# --------------------------------------------------------------------------------------------


def load_policy(spec):
    """`python:MODULE:FUNCTION` (a function of the observation) or `sb3:ALGO:PATH`."""
    kind, _, rest = spec.partition(":")
    if kind == "python":
        module, _, function = rest.partition(":")
        if not module or not function:
            raise BadInput(f"--policy {spec}: expected python:MODULE:FUNCTION")
        try:
            f = getattr(importlib.import_module(module), function)
        except (ImportError, AttributeError) as e:
            raise BadInput(f"--policy {spec}: {e}") from e
        return f
    if kind == "sb3":
        algo, _, path = rest.partition(":")
        try:
            import stable_baselines3 as sb3
        except ImportError as e:
            raise BadInput(
                f"--policy {spec}: stable-baselines3 is not installed in this environment "
                "(pip install stable-baselines3 into the adapter's .venv)"
            ) from e
        cls = getattr(sb3, algo.upper(), None)
        if cls is None or not path:
            raise BadInput(f"--policy {spec}: expected sb3:ALGO:PATH.zip with ALGO one of dqn, ppo, a2c")
        try:
            model = cls.load(path, device="cpu")
        except Exception as e:
            raise BadInput(f"--policy {spec}: cannot load {path}: {e}") from e
        return lambda obs: model.predict(obs, deterministic=True)[0]
    raise BadInput(f"--policy {spec}: expected python:MODULE:FUNCTION or sb3:ALGO:PATH")


class ExpertServer:
    def __init__(self, policy):
        self.policy = policy

    def handle(self, req, resp):
        import numpy as np

        if req.kind != ACT:
            raise ValueError(f"an expert answers ACT requests, not kind {req.kind}")
        obs = np.array(req.values[: int(req.len)], dtype=np.float32)
        action = np.asarray(self.policy(obs)).ravel()
        if action.size != 1:
            raise ValueError(f"the policy returned {action.size} values, expected one action")
        a = int(action[0])
        if a < 0:
            raise ValueError(f"the policy returned action {a}")
        resp.action = a


# --------------------------------------------------------------------------------------------
# Serving
# --------------------------------------------------------------------------------------------


def serve(run_id, name, schema, server, parent=None):
    import iceoryx2 as iox2

    iox2.set_log_level_from_env_or(iox2.LogLevel.Warn)
    stop = {"now": False}

    def on_signal(_sig, _frame):
        stop["now"] = True

    signal.signal(signal.SIGTERM, on_signal)
    signal.signal(signal.SIGINT, on_signal)
    cfg = iox2.config.default()
    cfg.global_cfg.prefix = iox2.FileName.new(f"alfd_{run_id}_")
    node = (
        iox2.NodeBuilder.new()
        .name(iox2.NodeName.new(f"adapter-{name}"))
        .config(cfg)
        .signal_handling_mode(iox2.SignalHandlingMode.Disabled)
        .create(iox2.ServiceType.Ipc)
    )
    base = f"alfd/{run_id}/remote/{name}"
    service = (
        node.service_builder(iox2.ServiceName.new(base))
        .request_response(RemoteRequest, RemoteResponse)
        .max_servers(MAX_SERVERS)
        .max_clients(MAX_CLIENTS)
        .max_nodes(MAX_NODES)
        .max_active_requests_per_client(MAX_ACTIVE_REQUESTS_PER_CLIENT)
        .max_response_buffer_size(MAX_RESPONSE_BUFFER_SIZE)
        .enable_safe_overflow_for_requests(True)
        .enable_safe_overflow_for_responses(True)
        .open_or_create()
    )

    def event(topic):
        return (
            node.service_builder(iox2.ServiceName.new(f"{base}/{topic}"))
            .event()
            .max_listeners(MAX_LISTENERS)
            .max_notifiers(MAX_NOTIFIERS)
            .max_nodes(MAX_NODES)
            .event_id_max_value(EVENT_ID_MAX_VALUE)
            .open_or_create()
        )

    requests = event("request").listener_builder().create()
    reply = event("reply").notifier_builder().create()
    srv = service.server_builder().create()
    # The process that started it (`--parent`; else the parent now, which is that process only
    # if it has not died during this start-up): once it is gone, so is this adapter.
    if parent is None:
        parent = os.getppid()
    seq = 0
    print(f"alfd_adapter: serving {base}", file=sys.stderr, flush=True)
    while not stop["now"]:
        try:
            requests.timed_wait(iox2.Duration.from_millis(200))
        except iox2.ListenerWaitError:
            pass  # a signal cut the wait short: SIGTERM sets `stop`, anything else goes on
        answered = False
        while True:
            active = srv.receive()
            if active is None:
                break
            req = active.payload().contents
            resp = RemoteResponse()
            resp.header.schema = schema
            resp.header.role = ROLE_TOOL
            resp.header.seq = seq
            seq += 1
            resp.request_seq = req.header.seq
            resp.kind = req.kind
            resp.session = req.session
            if req.header.schema != schema:
                resp.status = FAILED
                resp.message = (
                    f"schema version {req.header.schema}, the adapter speaks {schema}"
                ).encode()[: REMOTE_MESSAGE_LEN - 1]
            else:
                try:
                    server.handle(req, resp)
                    resp.status = OK
                except Exception as e:  # answered, not fatal: the client names it
                    resp.status = FAILED
                    resp.message = f"{type(e).__name__}: {e}".encode()[: REMOTE_MESSAGE_LEN - 1]
            active.send_copy(resp)
            del active
            answered = True
        if answered:
            reply.notify()
        if os.getppid() != parent:
            print("alfd_adapter: the process that started it has gone", file=sys.stderr)
            break
    print("alfd_adapter: stopping", file=sys.stderr, flush=True)


def main(argv=None):
    p = argparse.ArgumentParser(prog="alfd_adapter.py")
    sub = p.add_subparsers(dest="mode", required=True)
    for mode in ("env", "expert"):
        s = sub.add_parser(mode)
        s.add_argument("--run-id")
        s.add_argument("--name")
        s.add_argument("--schema", type=int)
        s.add_argument("--parent", type=int, help="the pid of the process that started it")
    e = sub.choices["env"]
    e.add_argument("--id", required=True)
    e.add_argument("--kwargs", default="{}")
    e.add_argument("--max-episode-steps", type=int, default=0)
    e.add_argument("--check", action="store_true")
    x = sub.choices["expert"]
    x.add_argument("--policy", required=True)
    args = p.parse_args(argv)
    # Example controllers ship beside this file; the working directory is searched too.
    here = os.path.dirname(os.path.abspath(__file__))
    sys.path[:0] = [os.path.join(here, "examples"), os.getcwd()]
    try:
        if args.mode == "env":
            try:
                kwargs = json.loads(args.kwargs)
            except json.JSONDecodeError as err:
                raise BadInput(f"--kwargs: not JSON: {err}") from err
            if not isinstance(kwargs, dict):
                raise BadInput("--kwargs: expected a JSON object")
            env = make_env(args.id, kwargs, args.max_episode_steps)
            if args.check:
                print(json.dumps(spec_of(env)))
                return 0
            env.close()
            server = EnvServer(args.id, kwargs)
        else:
            server = ExpertServer(load_policy(args.policy))
        if args.run_id is None or args.name is None or args.schema is None:
            raise BadInput("--run-id, --name and --schema are needed to serve")
    except BadInput as err:
        print(f"alfd_adapter: error: {err}", file=sys.stderr)
        return EXIT_BAD_INPUT
    serve(args.run_id, args.name, args.schema, server, args.parent)
    return 0


if __name__ == "__main__":
    sys.exit(main())
