"""Declare the symmetry of a third-party environment (bring your own task).

A built-in GeoMDP task lays its fields out one after another. A third-party env
rarely does: Gymnasium's ``Reacher-v5`` observes ``cos q1, cos q2, sin q1, sin q2,
...``, so the vector ``(cos q1, sin q1)`` sits at indices 0 and 2. A
``Declaration`` names each field by the indices it occupies; ``declare`` wraps the
env in a ``DeclaredEnv`` that reorders observations (and actions) into the
declaration's order, so that everything downstream (the ``Symmetry`` it exposes,
augmentation, the equivariant agent) sees contiguous fields as for a built-in task.

To be checked against its simulator (``check_symmetry``), a declaration also says
how the physical state moves: which of MuJoCo's ``qpos`` and ``qvel`` entries are
vectors, signs, planar orientation angles. The declaration itself (parsing, checks,
YAML) is ``geomdp_envs.declaration``; the state access the checker uses,
``geomdp_envs.declared_simulator``; this module is the wrapper and ``declare``.
"""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path
from typing import Any

import gymnasium
import numpy as np
from gymnasium import spaces

from geomdp_envs.declaration import (  # noqa: F401  (re-exported: the declaration API lives here too)
    REQUIRED_KEYS,
    SHIPPED,
    STATE_REPRESENTATIONS,
    STATE_VECTORS,
    Declaration,
    IndexedField,
    load_declaration,
    shipped_declarations,
)
from geomdp_envs.declared_simulator import DeclaredSimulator
from geomdp_envs.symmetry import Symmetry

# The wrappers gymnasium.make adds, which change no observation or action: the checker
# steps the bare env, so any other wrapper under ``declare`` would go unchecked.
BOOKKEEPING_WRAPPERS = (gymnasium.wrappers.TimeLimit, gymnasium.wrappers.OrderEnforcing,
                        gymnasium.wrappers.PassiveEnvChecker)



def _box(space: spaces.Space, order: np.ndarray, kind: str) -> spaces.Box:
    if not isinstance(space, spaces.Box) or len(space.shape) != 1:
        raise ValueError(f"{kind} space {space} is not a flat Box: a declaration indexes a vector")
    return spaces.Box(space.low[order], space.high[order], dtype=space.dtype)


class DeclaredEnv(gymnasium.Wrapper):
    """A third-party env with a symmetry declaration, its vectors in declaration order.

    The agent sends actions in declaration order and receives observations in it;
    ``symmetry`` describes those reordered vectors. For a MuJoCo env whose state
    the declaration covers, ``simulator()`` gives the state access ``check_symmetry``
    uses (get/set/sample/transform state, observe, simulate), as the built-in tasks do.
    """

    def __init__(self, env: gymnasium.Env, declaration: Declaration) -> None:
        super().__init__(env)
        self.declaration = declaration
        name = env.spec.id if env.spec is not None else type(env.unwrapped).__name__
        self.env_name = name
        obs_space, act_space = env.observation_space, env.action_space
        obs_size = _box(obs_space, np.arange(obs_space.shape[0] if obs_space.shape else 0),
                        "observation").shape[0]
        act_size = _box(act_space, np.arange(act_space.shape[0] if act_space.shape else 0),
                        "action").shape[0]
        try:
            self.symmetry = declaration.symmetry(obs_size, act_size)
        except ValueError as err:
            raise ValueError(f"{name}: {err}") from None
        self._obs_order = declaration.order("observation", obs_size)
        self._action_order = declaration.order("action", act_size)
        self.observation_space = _box(obs_space, self._obs_order, "observation")
        self.action_space = _box(act_space, self._action_order, "action")
        self._check_action_bounds()

    def _check_action_bounds(self) -> None:
        """The group must map the action box to itself after Gymnasium's rescaling:
        signed fields need bounds symmetric about 0, vector fields one bound for all."""
        low, high = self.action_space.low, self.action_space.high
        for f in self.symmetry.action:
            lo, hi = low[f.start:f.stop], high[f.start:f.stop]
            if f.rep != "trivial" and not np.allclose(lo, -hi):
                raise ValueError(f"{self.env_name}: action field {f.name!r} is {f.rep} but its bounds "
                                 f"[{lo.tolist()}, {hi.tolist()}] are not symmetric about 0")
            if f.size > 1 and not (np.allclose(lo, lo[0]) and np.allclose(hi, hi[0])):
                raise ValueError(f"{self.env_name}: action field {f.name!r} is a {f.rep} but its "
                                 "coordinates have different bounds")

    # --- reordering ---------------------------------------------------------------
    def to_declared_observation(self, observation: np.ndarray) -> np.ndarray:
        """The env's observation in declaration order."""
        return np.asarray(observation)[..., self._obs_order]

    def to_env_action(self, action: np.ndarray) -> np.ndarray:
        """An action in declaration order, as the env takes it."""
        action = np.asarray(action)
        out = np.empty_like(action)
        out[..., self._action_order] = action
        return out

    def reset(self, **kwargs: Any) -> tuple[np.ndarray, dict[str, Any]]:
        obs, info = self.env.reset(**kwargs)
        return self.to_declared_observation(obs), info

    def step(self, action: np.ndarray) -> tuple[np.ndarray, float, bool, bool, dict[str, Any]]:
        obs, reward, terminated, truncated, info = self.env.step(self.to_env_action(action))
        return self.to_declared_observation(obs), reward, terminated, truncated, info

    # --- state access for check_symmetry ----------------------------------------------
    def simulator(self) -> DeclaredSimulator:
        """The env's simulator seen through the declaration, which ``check_symmetry`` moves
        by g; raises a one-line error when the declaration or the env does not allow it."""
        if self.declaration.state is None:
            raise ValueError(f"{self.env_name}: the declaration has no state, so check_symmetry cannot "
                             "move the simulator by g: declare how qpos and qvel transform "
                             "(state={'qpos': [...], 'qvel': [...]})")
        inner = self.env
        while isinstance(inner, gymnasium.Wrapper):
            if not isinstance(inner, BOOKKEEPING_WRAPPERS):
                raise ValueError(f"{self.env_name}: {type(inner).__name__} sits between declare() and "
                                 "the env, and check_symmetry steps the bare env, so it would check "
                                 "something else than what the agent sees: apply it outside declare()")
            inner = inner.env
        return DeclaredSimulator(self, self.env.unwrapped)


def declare(env: gymnasium.Env, declaration: str | Path | Mapping[str, Any] | Declaration | None = None,
            **fields: Any) -> DeclaredEnv:
    """``env`` with a symmetry declaration: a ``Declaration``, a shipped name or YAML path,
    plain data, or its keys as keyword arguments (``dim=``, ``continuous_group=``,
    ``exact_group=``, ``observation=``, ``action=``, and optionally ``state=``, ``notes=``);
    every key but ``state`` and ``notes`` must be given.

    >>> env = declare(gymnasium.make("Reacher-v5"), "reacher_v5")
    >>> env.symmetry.observation[0]  # Field('shoulder', 'vector', 0, 2): indices 0 and 2
    """
    if declaration is not None and fields:
        raise TypeError("declare: give a declaration or its fields as keywords, not both")
    if declaration is None:
        declaration = Declaration.from_dict(fields)
    if symmetry_of(env) is not None:
        raise ValueError(f"{env.unwrapped} declares a symmetry already; declare() is for envs that do not")
    return DeclaredEnv(env, load_declaration(declaration))


def symmetry_of(env: gymnasium.Env) -> Symmetry | None:
    """The symmetry an env declares (a built-in task's, or a ``declare`` wrapper's), looking
    through wrappers; None if it declares none."""
    current = env
    while True:
        if isinstance(current, DeclaredEnv):
            return current.symmetry
        if not isinstance(current, gymnasium.Wrapper):
            return getattr(current, "symmetry", None)
        current = current.env


def declared_env(env: gymnasium.Env) -> DeclaredEnv | None:
    """The ``declare`` wrapper inside ``env``'s wrappers, if there is one."""
    current = env
    while isinstance(current, gymnasium.Wrapper):
        if isinstance(current, DeclaredEnv):
            return current
        current = current.env
    return None
