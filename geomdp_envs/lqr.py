"""The linearised view of a Geometric MDP: steerable A, B, K, P, and an LQR oracle.

For s' = T(s, a) with T(g.s, g.a) = g.T(s, a), differentiating gives (the
paper's Theorem 3)

    A(g.s, g.a) = D_g(s') A(s, a) D_g(s)^-1,    B(g.s, g.a) = D_g(s') B(s, a) rho_A(g)^-1,

where D_g(s) is the Jacobian of the group action on the simulator state (the
matrix rho_S(g) when it acts linearly, as on point masses; +-I on Reacher's
joint angles). At a fixed point of G (the target at the origin) A and B are
G-equivariant maps, and so are the LQR gain K (rho_S -> rho_A) and value
matrix P for a G-invariant cost. ``linearize`` uses MuJoCo's finite-difference
transition derivatives, ``lqr`` the discrete algebraic Riccati equation.
"""

from __future__ import annotations

from dataclasses import dataclass

import gymnasium
import mujoco
import numpy as np
import scipy.linalg

from geomdp_envs import groups
from geomdp_envs.mujoco_env import GeometricMujocoEnv, SimState


def linearize(env: GeometricMujocoEnv, state: SimState,
              action: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(A, B) of one control step at (state, action), in (qpos, qvel) coordinates."""
    env.set_state(state)
    env.data.ctrl[:] = action
    nv, nu = env.model.nv, env.model.nu
    a, b = np.zeros((2 * nv, 2 * nv)), np.zeros((2 * nv, nu))
    mujoco.mjd_transitionFD(env.model, env.data, 1e-6, True, a, b, None, None)
    return a, b


def _flat(state: SimState) -> np.ndarray:
    return np.concatenate([state.qpos, state.qvel])


def state_jacobian(env: GeometricMujocoEnv, state: SimState, g: np.ndarray,
                   eps: float = 1e-6) -> np.ndarray:
    """D_g(s): the Jacobian of s -> g.s in (qpos, qvel) coordinates (central differences)."""
    x = _flat(state)
    nq = len(state.qpos)
    columns = []
    for i in range(len(x)):
        moved = []
        for sign in (1, -1):
            y = x.copy()
            y[i] += sign * eps
            moved.append(_flat(env.transform_state(SimState(y[:nq], y[nq:], state.task), g)))
        columns.append((moved[0] - moved[1]) / (2 * eps))
    return np.stack(columns, axis=1)


@dataclass
class SteerabilityReport:
    max_a_error: float
    max_b_error: float
    n_trials: int

    @property
    def max_error(self) -> float:
        return max(self.max_a_error, self.max_b_error)


def check_linearization(env: gymnasium.Env, group: str | None = None, n_trials: int = 16,
                        seed: int = 0) -> SteerabilityReport:
    """Theorem 3 at random pairs (s, a), (g.s, g.a): largest |A(g.s) - D A(s) D^-1|, same for B."""
    base = env.unwrapped
    sym = base.symmetry
    rng = np.random.default_rng(seed)
    saved = base.get_state()
    errors = np.zeros((n_trials, 2))
    try:
        for trial, g in enumerate(groups.sample(group or sym.exact_group, rng, n_trials)):
            state, action = base.sample_state(rng), sym.sample_action(rng)
            a1, b1 = linearize(base, state, action)
            base.set_state(state)
            base.simulate(action)
            next_state = base.get_state()
            d_s, d_next = state_jacobian(base, state, g), state_jacobian(base, next_state, g)
            a2, b2 = linearize(base, base.transform_state(state, g), sym.action_matrix(g) @ action)
            scale = max(1.0, np.abs(a1).max())
            errors[trial] = [
                np.abs(a2 - d_next @ a1 @ np.linalg.inv(d_s)).max() / scale,
                np.abs(b2 - d_next @ b1 @ np.linalg.inv(sym.action_matrix(g))).max() / scale,
            ]
    finally:
        base.set_state(saved)
    return SteerabilityReport(*errors.max(axis=0), n_trials)


def lqr(a: np.ndarray, b: np.ndarray, q: np.ndarray, r: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Infinite-horizon discrete LQR: gain K (u = -K x) and value matrix P."""
    p = scipy.linalg.solve_discrete_are(a, b, q, r)
    k = np.linalg.solve(r + b.T @ p @ b, b.T @ p @ a)
    return k, p


def origin_state(env: GeometricMujocoEnv) -> SimState:
    """The state at rest on the target (a fixed point of every group element)."""
    state = env.get_state()
    return SimState(np.zeros_like(state.qpos), np.zeros_like(state.qvel), state.task)


class LQRPolicy:
    """u = -K s for the model linearised at the target, with an invariant cost
    (position weight, velocity weight, control weight), saturated into the unit
    ball per vector field so that the policy stays equivariant.

    The default weights were the best of a 27-point grid (position 1/10/100,
    velocity 0/0.1/1, control 0.01/0.1/1) on PointMass2D seeds 100-102: a stiff
    controller whose saturation does the rest.
    """

    def __init__(self, env: gymnasium.Env, position_weight: float = 100.0,
                 velocity_weight: float = 0.0, control_weight: float = 0.01) -> None:
        self.env = env.unwrapped
        nq = self.env.model.nq
        a, b = linearize(self.env, origin_state(self.env), np.zeros(self.env.model.nu))
        self.q = np.diag([position_weight] * nq + [velocity_weight] * nq)
        self.r = control_weight * np.eye(self.env.model.nu)
        self.a, self.b = a, b
        self.k, self.p = lqr(a, b, self.q, self.r)

    def __call__(self, obs: np.ndarray) -> np.ndarray:
        u = -self.k @ np.asarray(obs, dtype=np.float64)
        out = np.empty_like(u)
        for f in self.env.symmetry.action:
            v = u[f.start:f.stop]
            out[f.start:f.stop] = v / max(1.0, np.linalg.norm(v))
        return out.astype(np.float32)


def evaluate_policy(env: gymnasium.Env, policy: LQRPolicy, seeds: range) -> tuple[float, float]:
    """Mean and standard deviation of the return over one episode per seed."""
    returns = []
    for seed in seeds:
        obs, _ = env.reset(seed=seed)
        total, done = 0.0, False
        while not done:
            obs, reward, terminated, truncated, _ = env.step(policy(obs))
            total += reward
            done = terminated or truncated
        returns.append(total)
    return float(np.mean(returns)), float(np.std(returns))
