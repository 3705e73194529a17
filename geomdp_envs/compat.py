"""Gymnasium internals, behind one small adapter each (as ``agents.compat`` does for
torch, TorchRL and escnn; geomdp_envs does not import ``agents``, so its own lives here).

Each function says which private attribute it touches and why no public API of the
pinned gymnasium does the job; ``tests/test_compat.py`` checks each one against the
installed version, so an upgrade that moves an internal fails there, by name.
"""

from __future__ import annotations

from typing import Any

import gymnasium
import numpy as np

# The method of a Gymnasium MuJoCo env that computes its observation from the
# simulator's current state (``observe``); named in declare's errors.
OBSERVE = "_get_obs"


def can_observe(env: gymnasium.Env) -> bool:
    """Whether ``env`` (unwrapped) computes its observation from the simulator's
    current state the way Gymnasium's MuJoCo envs do (see ``observe``)."""
    return callable(getattr(env, OBSERVE, None))


def observe(env: gymnasium.Env) -> Any:
    """``env``'s observation of the simulator's current state, without stepping it.

    Private: ``_get_obs``, the method every Gymnasium MuJoCo env (``Reacher-v5``,
    ``InvertedPendulum-v5``, ...) defines and calls from ``step`` and ``reset_model``.
    ``MujocoEnv`` has no public method that observes without stepping or resetting.
    """
    return env._get_obs()


def random_state(env: gymnasium.Env) -> tuple[np.random.Generator, int | None]:
    """``env``'s random generator and the seed it records (``np_random_seed``), for
    ``restore_random_state``. Public: the ``np_random`` and ``np_random_seed`` properties."""
    return env.np_random, env.np_random_seed


def restore_random_state(env: gymnasium.Env, state: tuple[np.random.Generator, int | None]) -> None:
    """Put back what ``random_state(env)`` returned: the generator and the recorded seed.

    Private: ``Env._np_random_seed``. The public ``np_random`` setter records the seed
    as -1 (unknown), and ``np_random_seed`` is read-only; reseeding through
    ``reset(seed=...)`` would restart the generator and reset the env.
    """
    generator, seed = state
    env.np_random = generator
    env._np_random_seed = seed
