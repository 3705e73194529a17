"""Numerical check of a task's symmetry declaration against its simulator.

For random states s, action sequences a_1..a_T (in the declared action domain)
and group elements g, it compares

* obs(g . s)              with  rho_S(g) obs(s)      (the observation map),
* obs after g . a_1..a_T  with  rho_S(g) obs after a_1..a_T  (the dynamics),
* each reward             with  the untransformed one (invariance),

where g . s is the simulator state moved by g (``env.transform_state``), which
is independent of the declaration. A wrong declaration, or a group element the
task is not symmetric under, shows up as a large error.
"""

from __future__ import annotations

from dataclasses import dataclass

import gymnasium
import numpy as np

from geomdp_envs import groups
from geomdp_envs.mujoco_env import GeometricMujocoEnv
from geomdp_envs.symmetry import Symmetry


@dataclass
class SymmetryReport:
    """Largest errors over all trials, and where they occurred."""

    group: str
    n_trials: int
    tolerance: float
    max_observation_error: float
    max_next_observation_error: float
    max_reward_error: float
    worst_element: np.ndarray
    worst_permutation: np.ndarray | None

    @property
    def max_error(self) -> float:
        return max(self.max_observation_error, self.max_next_observation_error,
                   self.max_reward_error)

    @property
    def passed(self) -> bool:
        return self.max_error <= self.tolerance

    def __str__(self) -> str:
        verdict = "PASS" if self.passed else "FAIL"
        return (f"{verdict} {self.group}: {self.n_trials} trials, max |error| "
                f"obs {self.max_observation_error:.2e}, next obs "
                f"{self.max_next_observation_error:.2e}, reward {self.max_reward_error:.2e} "
                f"(tolerance {self.tolerance:.0e})")


def check_symmetry(
    env: gymnasium.Env,
    group: str | None = None,
    elements: np.ndarray | None = None,
    n_trials: int = 64,
    n_steps: int = 3,
    seed: int = 0,
    symmetry: Symmetry | None = None,
    permute_particles: bool = True,
    tolerance: float = 1e-6,
) -> SymmetryReport:
    """Check ``env``'s declared symmetry numerically; returns the largest errors.

    Args:
        env: a GeoMDP env (wrappers are looked through).
        group: name of the group to sample elements from (default: the task's
            exact group); any group of ``geomdp_envs.groups``, e.g. ``"O(2)"``.
        elements: explicit orthogonal matrices [k, d, d] to use instead.
        n_trials: random (state, action sequence, element) triples.
        n_steps: control steps compared after the transformed start.
        symmetry: a declaration to check instead of the env's own.
        permute_particles: also relabel interchangeable particles at random.
        tolerance: largest absolute error that counts as a pass.
    """
    base = env.unwrapped
    if not isinstance(base, GeometricMujocoEnv):
        raise TypeError(f"{type(base).__name__} is not a GeoMDP env: it declares no symmetry")
    symmetry = symmetry or base.symmetry
    rng = np.random.default_rng(seed)
    if elements is None:
        group = group or symmetry.exact_group
        if groups.group_dim(group) != symmetry.dim:
            raise ValueError(f"group {group} acts on R^{groups.group_dim(group)}, "
                             f"the task on R^{symmetry.dim}")
        elements = groups.sample(group, rng, n_trials)
    else:
        elements = np.stack([groups.as_orthogonal(g, symmetry.dim) for g in elements])
        group = group or f"{len(elements)} given elements"
    saved = base.get_state()
    errors = np.zeros((n_trials, 3))
    perms = []
    try:
        for trial in range(n_trials):
            g = elements[trial % len(elements)]
            perm = None
            if permute_particles and symmetry.n_particles > 1:
                perm = rng.permutation(symmetry.n_particles)
            perms.append(perm)
            errors[trial] = _one_trial(base, symmetry, g, perm, rng, n_steps)
    finally:
        base.set_state(saved)
    worst = int(np.argmax(errors.max(axis=1)))
    return SymmetryReport(group, n_trials, tolerance, *errors.max(axis=0).tolist(),
                          worst_element=elements[worst % len(elements)],
                          worst_permutation=perms[worst])


def _one_trial(env: GeometricMujocoEnv, symmetry: Symmetry, g: np.ndarray,
               perm: np.ndarray | None, rng: np.random.Generator, n_steps: int) -> np.ndarray:
    """Max errors (observation, next observations, rewards) for one triple."""
    rho_s, rho_a = symmetry.observation_matrix(g), symmetry.action_matrix(g)
    if perm is not None:
        rho_s = symmetry.observation_permutation_matrix(perm) @ rho_s
        rho_a = symmetry.action_permutation_matrix(perm) @ rho_a
    state = env.sample_state(rng)
    actions = symmetry.sample_action(rng, n_steps)

    env.set_state(state)
    obs = [env.observe()]
    rewards = []
    for a in actions:
        o, r = env.simulate(a)
        obs.append(o)
        rewards.append(r)

    env.set_state(env.transform_state(state, g, perm))
    obs_g = [env.observe()]
    rewards_g = []
    for a in actions:
        o, r = env.simulate(rho_a @ a)
        obs_g.append(o)
        rewards_g.append(r)

    predicted = np.stack(obs) @ rho_s.T
    obs_error = np.abs(np.stack(obs_g) - predicted)
    return np.array([obs_error[0].max(), obs_error[1:].max(),
                     np.abs(np.subtract(rewards_g, rewards)).max()])
