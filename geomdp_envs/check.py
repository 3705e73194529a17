"""Numerical check of a task's symmetry declaration against its simulator.

For random states s, action sequences a_1..a_T (in the declared action domain)
and group elements g, it compares

* obs(g . s)              with  rho_S(g) obs(s)      (the observation map),
* obs after g . a_1..a_T  with  rho_S(g) obs after a_1..a_T  (the dynamics),
* each reward             with  the untransformed one (invariance),

where g . s is the simulator state moved by g (``env.transform_state``; for a
third-party env, the state part of its ``declare`` declaration). A wrong
observation declaration, or a group element the task is not symmetric under,
shows up as a large error, and the report names the field where it is largest.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import gymnasium
import numpy as np

from geomdp_envs import groups
from geomdp_envs.declare import DeclaredSimulator, declared_env
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
    # largest error of each observation field (its label), over the start and later steps
    field_errors: dict[str, float] = field(default_factory=dict)

    @property
    def max_error(self) -> float:
        return max(self.max_observation_error, self.max_next_observation_error,
                   self.max_reward_error)

    @property
    def passed(self) -> bool:
        return self.max_error <= self.tolerance

    @property
    def failing_fields(self) -> list[str]:
        """Observation fields whose error exceeds the tolerance, worst first."""
        bad = [name for name, err in self.field_errors.items() if err > self.tolerance]
        return sorted(bad, key=lambda name: -self.field_errors[name])

    def __str__(self) -> str:
        verdict = "PASS" if self.passed else "FAIL"
        text = (f"{verdict} {self.group}: {self.n_trials} trials, max |error| "
                f"obs {self.max_observation_error:.2e}, next obs "
                f"{self.max_next_observation_error:.2e}, reward {self.max_reward_error:.2e} "
                f"(tolerance {self.tolerance:.0e})")
        if self.failing_fields:
            text += "; fields over tolerance: " + ", ".join(
                f"{name} {self.field_errors[name]:.2e}" for name in self.failing_fields)
        if self.max_observation_error <= self.tolerance < self.max_next_observation_error:
            text += (" (obs(g.s) matches, the steps after it do not: the action declaration, a "
                     "state the observation does not show, or the dynamics break the symmetry)")
        return text


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
        env: a GeoMDP env, or a third-party MuJoCo env wrapped by ``geomdp_envs.declare``
            with a state declaration (wrappers are looked through).
        group: name of the group to sample elements from (default: the task's
            exact group); any group of ``geomdp_envs.groups``, e.g. ``"O(2)"``.
        elements: explicit orthogonal matrices [k, d, d] to use instead.
        n_trials: random (state, action sequence, element) triples.
        n_steps: control steps compared after the transformed start.
        symmetry: a declaration to check instead of the env's own.
        permute_particles: also relabel interchangeable particles at random.
        tolerance: largest absolute error that counts as a pass.
    """
    if n_trials < 1 or n_steps < 1:
        raise ValueError(f"n_trials and n_steps must be at least 1, got {n_trials} and {n_steps}")
    base = simulator_of(env)
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
    coordinate_errors = np.zeros(symmetry.observation_size)
    perms = []
    try:
        for trial in range(n_trials):
            g = elements[trial % len(elements)]
            perm = None
            if permute_particles and symmetry.n_particles > 1:
                perm = rng.permutation(symmetry.n_particles)
            perms.append(perm)
            obs_error, errors[trial, 2] = _one_trial(base, symmetry, g, perm, rng, n_steps)
            errors[trial, :2] = obs_error[0].max(), obs_error[1:].max()
            coordinate_errors = np.maximum(coordinate_errors, obs_error.max(axis=0))
    finally:
        base.set_state(saved)
    worst = int(np.argmax(errors.max(axis=1)))
    field_errors = {f.label: float(coordinate_errors[f.start:f.stop].max()) for f in symmetry.observation}
    return SymmetryReport(group, n_trials, tolerance, *errors.max(axis=0).tolist(),
                          worst_element=elements[worst % len(elements)],
                          worst_permutation=perms[worst], field_errors=field_errors)


def simulator_of(env: gymnasium.Env) -> GeometricMujocoEnv | DeclaredSimulator:
    """What check_symmetry moves: the built-in task, or a declared env's simulator (which
    raises a clear error when the env's state cannot be set), looking through wrappers."""
    if isinstance(env.unwrapped, GeometricMujocoEnv):
        return env.unwrapped
    wrapper = declared_env(env)
    if wrapper is None:
        raise TypeError(f"{type(env.unwrapped).__name__} declares no symmetry: wrap it with "
                        "geomdp_envs.declare(env, ...) (see README, 'Bring your own task')")
    return wrapper.simulator()


def _one_trial(env: GeometricMujocoEnv | DeclaredSimulator, symmetry: Symmetry, g: np.ndarray,
               perm: np.ndarray | None, rng: np.random.Generator,
               n_steps: int) -> tuple[np.ndarray, float]:
    """Errors for one triple: |observation error| [n_steps + 1, observation_size] and the
    largest reward error."""
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
    return obs_error, float(np.abs(np.subtract(rewards_g, rewards)).max())
