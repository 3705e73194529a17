"""The environments of a run: the ``env`` options, the Gymnasium env they make, and that
env wrapped for TorchRL with TD-MPC's action repeat."""

from __future__ import annotations

import typing
from dataclasses import dataclass, field
from typing import Any

import gymnasium
import numpy as np
from torchrl.envs import GymWrapper, TransformedEnv
from torchrl.envs.transforms import FrameSkipTransform

import geomdp_envs  # noqa: F401  (registers the tasks)
from agents.options import OptionError, check, from_dict, option
from geomdp_envs.declare import declare

TASK_ENVS = ("pointmass2d", "pointmass3d", "reacher")


@dataclass
class EnvOptions:
    """Which env (``id``), its action repeat, the symmetry declaration of a third-party env
    (``symmetry``: a shipped name, a YAML path or the mapping itself; see
    ``geomdp_envs.declare``), whether that declaration is checked against the simulator
    before training (``check_symmetry``), and the keyword arguments of ``gymnasium.make``
    (every other key of the ``env`` section)."""

    KEY: typing.ClassVar[str] = "env"
    id: str  # no default: a config without one is an error, not PointMass2D
    name: str = ""
    action_repeat: int = option(1, low=1)
    symmetry: dict[str, Any] | str | None = None
    check_symmetry: bool = True
    kwargs: dict[str, Any] = field(default_factory=dict)

    def __post_init__(self) -> None:
        check(self)

    @classmethod
    def from_section(cls, section: dict[str, Any]) -> EnvOptions:
        meta = {k: v for k, v in section.items()
                if k in ("name", "id", "action_repeat", "symmetry", "check_symmetry")}
        return from_dict(cls, {**meta, "kwargs": {k: v for k, v in section.items() if k not in meta}})


def make_gym_env(env: EnvOptions, render_mode: str | None = None) -> gymnasium.Env:
    """The Gymnasium env of the ``env`` options, with its symmetry declaration attached when
    ``env.symmetry`` gives one; its errors (bad kwargs, a bad declaration) become
    OptionErrors, float64 observations become float32 (the networks' dtype), and its
    actions are rescaled to [-1, 1] (TD-MPC's action domain) when they are not already."""
    if env.id not in gymnasium.registry:
        raise OptionError(f"unknown environment {env.id!r}: use env=<one of "
                          f"{', '.join(TASK_ENVS)}> or env=<a registered Gymnasium id>")
    kwargs = dict(env.kwargs) | ({"render_mode": render_mode} if render_mode else {})
    try:
        gym_env = gymnasium.make(env.id, **kwargs)
    except (ValueError, TypeError, OSError) as err:  # OSError: a missing xml_file
        raise OptionError(str(err)) from None
    if not isinstance(gym_env.action_space, gymnasium.spaces.Box):
        raise OptionError(f"{env.id} has a {type(gym_env.action_space).__name__} action space; "
                          "TD-MPC needs a Box")
    if env.symmetry is not None:
        try:
            gym_env = declare(gym_env, env.symmetry)
        except (ValueError, TypeError) as err:
            raise OptionError(f"env.symmetry: {err}") from None
    space = gym_env.observation_space
    if isinstance(space, gymnasium.spaces.Box) and space.dtype == np.float64:  # MuJoCo's (Reacher-v5)
        single = gymnasium.spaces.Box(space.low.astype(np.float32), space.high.astype(np.float32),
                                      dtype=np.float32)
        gym_env = gymnasium.wrappers.TransformObservation(
            gym_env, lambda obs: np.asarray(obs, dtype=np.float32), single)
    low, high = gym_env.action_space.low, gym_env.action_space.high
    if not (np.all(low == -1) and np.all(high == 1)):
        gym_env = gymnasium.wrappers.RescaleAction(gym_env, np.float32(-1), np.float32(1))  # no cast warning
    return gym_env


def torchrl_env(gym_env: gymnasium.Env, action_repeat: int) -> TransformedEnv:
    """``gym_env`` for TorchRL, with TD-MPC's action repeat (the caller keeps ``gym_env``
    to render it)."""
    return TransformedEnv(GymWrapper(gym_env), FrameSkipTransform(action_repeat))
