"""The environments of a run: a Gymnasium env from the ``env`` options, wrapped for
TorchRL with TD-MPC's action repeat."""

from __future__ import annotations

import gymnasium
import numpy as np
from torchrl.envs import GymWrapper, TransformedEnv
from torchrl.envs.transforms import FrameSkipTransform

import geomdp_envs  # noqa: F401  (registers the tasks)
from agents.options import OptionError
from geomdp_envs.symmetry import Symmetry

TASK_ENVS = ("pointmass2d", "pointmass3d", "reacher")


def make_gym_env(env_id: str, kwargs: dict, render_mode: str | None = None) -> gymnasium.Env:
    """The Gymnasium env ``env_id``; its errors (bad kwargs) become OptionErrors, and its
    actions are rescaled to [-1, 1] (TD-MPC's action domain) when they are not already."""
    if env_id not in gymnasium.registry:
        raise OptionError(f"unknown environment {env_id!r}: use env=<one of "
                          f"{', '.join(TASK_ENVS)}> or env=<a registered Gymnasium id>")
    kwargs = dict(kwargs) | ({"render_mode": render_mode} if render_mode else {})
    try:
        env = gymnasium.make(env_id, **kwargs)
    except (ValueError, TypeError) as err:
        raise OptionError(str(err)) from None
    if not isinstance(env.action_space, gymnasium.spaces.Box):
        raise OptionError(f"{env_id} has a {type(env.action_space).__name__} action space; "
                          "TD-MPC needs a Box")
    if not (np.all(env.action_space.low == -1) and np.all(env.action_space.high == 1)):
        env = gymnasium.wrappers.RescaleAction(env, -1.0, 1.0)
    return env


def declared_symmetry(env: gymnasium.Env) -> Symmetry | None:
    """The task's symmetry declaration, if it makes one."""
    return getattr(env.unwrapped, "symmetry", None)


def torchrl_env(gym_env: gymnasium.Env, action_repeat: int) -> TransformedEnv:
    """``gym_env`` for TorchRL, with TD-MPC's action repeat (the caller keeps ``gym_env``
    to render it)."""
    return TransformedEnv(GymWrapper(gym_env), FrameSkipTransform(action_repeat))
