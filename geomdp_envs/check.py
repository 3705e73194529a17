"""Numerical check of a task's symmetry declaration against its simulator.

For random states s, action sequences a_1..a_T (in the declared action domain)
and group elements g, it compares

* obs(g . s)              with  rho_S(g) obs(s)      (the observation map),
* obs after g . a_1..a_T  with  rho_S(g) obs after a_1..a_T  (the dynamics),
* each reward             with  the untransformed one (invariance),

where g . s is the simulator state moved by g (``env.transform_state``; for a
third-party env, the state part of its ``declare`` declaration). A wrong
observation declaration, or a group element the task is not symmetric under,
shows up as a large error, and the report names the field where it is largest,
with the indices it occupies in the env's own observation (``obs[0,2]``).

When the check fails it runs the same trials once more with zero actions (which
every g fixes) to say which part of the declaration the evidence points to:

* obs(g . s) matches but the steps do not: if they agree with zero actions, the
  action declaration; if not, a state the observation does not show or the dynamics;
* obs(g . s) already disagrees: if g . s steps and is rewarded like g applied to
  the untransformed run (compared through the observations of the states
  themselves, without rho_S), the observation declaration; if not, the state
  declaration (how qpos/qvel move), or g is no symmetry of the task.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import gymnasium
import numpy as np

from geomdp_envs import groups
from geomdp_envs.declare import DeclaredSimulator, declared_env, symmetry_of
from geomdp_envs.mujoco_env import GeometricMujocoEnv, SimState
from geomdp_envs.symmetry import Field, Symmetry


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
    # where each field lies in the env's own vectors: label -> "obs[0,2]" / "act[1]"
    observation_index: dict[str, str] = field(default_factory=dict)
    action_index: dict[str, str] = field(default_factory=dict)
    # what the failing check's rerun with zero actions points to (empty when it passed)
    hint: str = ""

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
                " ".join(filter(None, (name, self.observation_index.get(name),
                                       f"{self.field_errors[name]:.2e}")))
                for name in self.failing_fields)
        if self.hint:
            text += f" ({self.hint})"
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
        symmetry: a declaration to check instead of the env's own (for a declared
            env, its fields in the declared env's order).
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
    obs_order, action_order = env_order(base, symmetry)
    observation_index = {f.label: _index_text("obs", obs_order, f) for f in symmetry.observation}
    action_index = {f.label: _index_text("act", action_order, f) for f in symmetry.action}
    saved = base.get_state()
    errors = np.zeros((n_trials, 3))
    coordinate_errors = np.zeros(symmetry.observation_size)
    trials = []
    try:
        for trial in range(n_trials):
            g = elements[trial % len(elements)]
            perm = None
            if permute_particles and symmetry.n_particles > 1:
                perm = rng.permutation(symmetry.n_particles)
            state = base.sample_state(rng)
            actions = symmetry.sample_action(rng, n_steps)
            trials.append((g, perm, state, actions))
            run = _one_trial(base, symmetry, g, perm, state, actions)
            errors[trial] = run.observation[0].max(), run.observation[1:].max(), run.reward
            coordinate_errors = np.maximum(coordinate_errors, run.observation.max(axis=0))
        hint = ""
        if errors.max() > tolerance:
            hint = _diagnose(base, symmetry, trials, errors.max(axis=0), tolerance,
                             [f"{f.label} {action_index[f.label]} {f.rep}" for f in symmetry.action])
    finally:
        base.set_state(saved)
    worst = int(np.argmax(errors.max(axis=1)))
    field_errors = {f.label: float(coordinate_errors[f.start:f.stop].max()) for f in symmetry.observation}
    return SymmetryReport(group, n_trials, tolerance, *errors.max(axis=0).tolist(),
                          worst_element=elements[worst % len(elements)],
                          worst_permutation=trials[worst][1], field_errors=field_errors,
                          observation_index=observation_index, action_index=action_index, hint=hint)


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


def env_order(env: gymnasium.Env | DeclaredSimulator,
              symmetry: Symmetry) -> tuple[np.ndarray, np.ndarray]:
    """For each coordinate of the declared observation and action, its index in the env's
    own vector: a declared env's reordering, the identity for a built-in task."""
    wrapper = env.wrapper if isinstance(env, DeclaredSimulator) else declared_env(env)
    if wrapper is not None:
        return (wrapper.declaration.order("observation", symmetry.observation_size),
                wrapper.declaration.order("action", symmetry.action_size))
    return np.arange(symmetry.observation_size), np.arange(symmetry.action_size)


def declaration_table(env: gymnasium.Env, symmetry: Symmetry | None = None) -> str:
    """``Symmetry.describe()``'s markdown table with one more column: the indices each
    field occupies in the env's own observation or action (``obs[0,2]``), which the
    declared slices (in declaration order) do not show. Needs no state declaration."""
    symmetry = symmetry or symmetry_of(env)
    if symmetry is None:
        raise TypeError(f"{type(env.unwrapped).__name__} declares no symmetry: wrap it with "
                        "geomdp_envs.declare(env, ...)")
    orders = dict(zip(("observation", "action"), env_order(env, symmetry)))
    rows = [f"exact group: {symmetry.exact_group} (of {symmetry.continuous_group})", "",
            "| vector | slice | field | representation | env index |", "|---|---|---|---|---|"]
    for kind, prefix in (("observation", "obs"), ("action", "act")):
        rows += [f"| {kind} | [{f.start}:{f.stop}] | {f.label} | {f.rep} | "
                 f"{_index_text(prefix, orders[kind], f)} |" for f in getattr(symmetry, kind)]
    return "\n".join(rows)


def _index_text(prefix: str, order: np.ndarray, f: Field) -> str:
    return f"{prefix}[{','.join(str(int(i)) for i in order[f.start:f.stop])}]"


@dataclass
class _Run:
    observation: np.ndarray  # |obs(g.s) run - rho_S(g) obs(s) run|, [n_steps + 1, observation_size]
    reward: float            # largest |reward difference|
    state: float = 0.0       # largest |obs of the g.s run - obs(g . s_k)| over steps k >= 1


def _one_trial(env: GeometricMujocoEnv | DeclaredSimulator, symmetry: Symmetry, g: np.ndarray,
               perm: np.ndarray | None, state: SimState, actions: np.ndarray,
               compare_states: bool = False) -> _Run:
    """Runs s with a_1..a_T and g.s with g.a_1..g.a_T. With ``compare_states``, also moves
    each state s_k of the first run by g and compares its observation with the second
    run's: a test of the state transform (and the dynamics) that needs no rho_S."""
    rho_s, rho_a = symmetry.observation_matrix(g), symmetry.action_matrix(g)
    if perm is not None:
        rho_s = symmetry.observation_permutation_matrix(perm) @ rho_s
        rho_a = symmetry.action_permutation_matrix(perm) @ rho_a

    env.set_state(state)
    obs, rewards, states = [env.observe()], [], []
    for a in actions:
        o, r = env.simulate(a)
        obs.append(o)
        rewards.append(r)
        if compare_states:
            states.append(env.get_state())

    env.set_state(env.transform_state(state, g, perm))
    obs_g = [env.observe()]
    rewards_g = []
    for a in actions:
        o, r = env.simulate(rho_a @ a)
        obs_g.append(o)
        rewards_g.append(r)

    run = _Run(np.abs(np.stack(obs_g) - np.stack(obs) @ rho_s.T),
               float(np.abs(np.subtract(rewards_g, rewards)).max()))
    if compare_states:
        moved = []
        for s in states:
            env.set_state(env.transform_state(s, g, perm))
            moved.append(env.observe())
        run.state = float(np.abs(np.stack(obs_g[1:]) - np.stack(moved)).max())
    return run


def _diagnose(env: GeometricMujocoEnv | DeclaredSimulator, symmetry: Symmetry, trials: list,
              errors: np.ndarray, tolerance: float, action_fields: list[str]) -> str:
    """Reruns the failing check's trials with zero actions and says what the evidence
    points to (see the module's docstring); ``action_fields`` describe the action's fields."""
    start_error, next_error, _ = errors
    if max(start_error, next_error) <= tolerance:
        return ""  # only the rewards differ
    zero = [_one_trial(env, symmetry, g, perm, state, np.zeros_like(actions), compare_states=True)
            for g, perm, state, actions in trials]
    zero_next = max(float(run.observation[1:].max()) for run in zero)
    zero_state = max(run.state for run in zero)
    zero_reward = max(run.reward for run in zero)
    state_declaration = ("the state declaration (how its qpos/qvel fields move under g)"
                         if isinstance(env, DeclaredSimulator)
                         else "the task's transform_state (how it moves the simulator by g)")
    if start_error <= tolerance:
        if zero_next <= tolerance:
            return ("obs(g.s) matches, the steps after it do not, and with zero actions (which "
                    "every g fixes) they do: the likely cause is the action declaration, fields "
                    + ", ".join(action_fields))
        return ("obs(g.s) matches, the steps after it do not, even with zero actions (which every "
                "g fixes): not the action declaration, but dynamics that break the symmetry, or "
                f"a state the observation does not show that {state_declaration} gets wrong")
    compared = "like g applied to the run from s (zero actions, compared without rho_S)"
    if zero_state <= tolerance and zero_reward <= tolerance:
        return (f"obs(g.s) already disagrees, while g.s steps and is rewarded {compared}: the "
                "likely cause is the observation declaration, a rep or the indices (swapped "
                "components?) of the fields above")
    if zero_state > tolerance:
        rewarded = " and is not rewarded" if zero_reward > tolerance else ""
        return (f"obs(g.s) already disagrees, and g.s does not step{rewarded} {compared}: the "
                f"likely cause is {state_declaration}, unless g is no symmetry of the dynamics")
    return (f"obs(g.s) already disagrees, and g.s steps but is not rewarded {compared}: either "
            f"{state_declaration} moves parts the reward relates by different elements (an arm "
            "one way, its target another), or g is no symmetry of the reward")
