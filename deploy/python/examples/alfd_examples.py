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
