"""PointMass3D: N point masses in space, each pushed by a 3D force towards the origin.

Each ball is dm_control's point mass lifted to 3D: mass 0.3, three slide joints
with damping 1, motors with gear 0.1, timestep 0.02 s, contacts off, and here
gravity off, so with N = 1 it is point_mass with a third axis. The model is
generated for any N.

Reward: dm_control's point_mass reward per ball, averaged over the balls,

    r = mean_i  tolerance(|p_i|, (0, target_size), margin=target_size)
                * (4 + mean_k tolerance(u_ik, margin=1, quadratic)) / 5,

so each ball earns up to 1/N. Both factors depend only on |p_i| and (for u_i in
the unit ball) |u_i|, so the reward is O(3)- and permutation-invariant.

At most ``MAX_BALLS`` = 1000 balls: 1000 take about 300 MB and 3 ms a step;
10000 spend a minute compiling and then exhaust MuJoCo's memory arena.

Without walls (default) O(3) is exact, and so are its octahedral and
icosahedral subgroups; relabelling the balls is a symmetry too. ``walls=True``
limits every joint to point_mass's +-0.29, a cube whose exact group is the full
octahedral group (48 signed permutations). Initial positions are uniform in
the ball of radius 0.29 (rotation-invariant in distribution, inside the cube),
initial velocities zero as in point_mass.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from geomdp_envs import dmc
from geomdp_envs.mujoco_env import (
    GeometricMujocoEnv,
    SimState,
    is_real_number,
    positive_int,
    unknown_kwargs_error,
)
from geomdp_envs.symmetry import Symmetry, layout

WALL = 0.29
MAX_BALLS = 1000
INITIAL_RADIUS = 0.29
_BALL_COLORS = ["0.9 0.4 0.2 1", "0.2 0.6 0.9 1", "0.3 0.8 0.3 1", "0.9 0.8 0.2 1",
                "0.7 0.3 0.8 1", "0.9 0.9 0.9 1"]
_VALID_ARGS = ["n_balls", "target_size", "walls", "render_mode", "width", "height"]


def model_xml(n_balls: int, target_size: float, walls: bool) -> str:
    """MJCF for ``n_balls`` point masses; dm_control's point_mass parameters."""
    limits = f'limited="true" range="-{WALL} {WALL}"' if walls else 'limited="false"'
    bodies, motors = [], []
    for i in range(n_balls):
        color = _BALL_COLORS[i % len(_BALL_COLORS)]
        joints = "".join(f'<joint name="ball{i}_{a}" axis="{v}"/>'
                         for a, v in zip("xyz", ("1 0 0", "0 1 0", "0 0 1")))
        bodies.append(f'<body name="ball{i}">{joints}'
                      f'<geom name="ball{i}" type="sphere" size=".01" mass=".3" rgba="{color}"/>'
                      "</body>")
        motors += [f'<motor name="ball{i}_{a}" joint="ball{i}_{a}"/>' for a in "xyz"]
    return f"""
<mujoco model="GeoMDP point masses in 3D">
  <include file="./common/skybox.xml"/>
  <include file="./common/visual.xml"/>
  <include file="./common/materials.xml"/>
  <option timestep="0.02" gravity="0 0 0"><flag contact="disable"/></option>
  <default>
    <joint type="slide" damping="1" {limits}/>
    <motor gear=".1" ctrlrange="-1 1" ctrllimited="true"/>
  </default>
  <worldbody>
    <light name="light" pos="0 0 1.5" dir="0 0 -1"/>
    <camera name="fixed" pos="0.75 -0.75 0.6" xyaxes="1 1 0 -0.6 0.6 1.5"/>
    <geom name="floor" type="plane" pos="0 0 -0.35" size=".4 .4 .1" material="grid"/>
    <geom name="target" type="sphere" pos="0 0 0" size="{target_size}" material="target"/>
    {"".join(bodies)}
  </worldbody>
  <actuator>{"".join(motors)}</actuator>
</mujoco>"""


def make_symmetry(n_balls: int, walls: bool) -> Symmetry:
    obs = [("position", "vector", i) for i in range(n_balls)]
    obs += [("velocity", "vector", i) for i in range(n_balls)]
    return Symmetry(
        dim=3,
        continuous_group="O(3)",
        exact_group="full_octahedral" if walls else "O(3)",
        observation=layout(3, obs),
        action=layout(3, [("force", "vector", i) for i in range(n_balls)]),
        n_particles=n_balls,
        notes=("Walls at +-0.29 on every axis leave the cube's group exact."
               if walls else "No walls, gravity or contacts: O(3) is exact.")
              + " Balls are interchangeable (permutations act on the particle index).",
    )


class PointMass3DEnv(GeometricMujocoEnv):
    """Move ``n_balls`` point masses in 3D to the target at the origin."""

    def __init__(self, n_balls: int = 1, target_size: float = 0.03, walls: bool = False,
                 render_mode: str | None = None, width: int = 240, height: int = 240,
                 **unknown: Any) -> None:
        if unknown:
            raise unknown_kwargs_error("PointMass3D", unknown, _VALID_ARGS)
        n_balls = positive_int("PointMass3D", "n_balls", n_balls)
        if n_balls > MAX_BALLS:
            raise ValueError(f"PointMass3D: n_balls={n_balls} is above MAX_BALLS = {MAX_BALLS} "
                             "(10000 balls take a minute to compile, then exhaust MuJoCo's memory)")
        if (not is_real_number(target_size) or not math.isfinite(target_size)
                or target_size <= 0):
            raise ValueError(f"PointMass3D: target_size must be a positive number "
                             f"(default 0.03, the paper's small target 0.02), got {target_size!r}")
        if not isinstance(walls, (bool, np.bool_)):
            raise ValueError(f"PointMass3D: walls must be True or False, got {walls!r}")
        self.n_balls, self.target_size, self.walls = n_balls, float(target_size), bool(walls)
        model = dmc.model_from_xml(model_xml(n_balls, self.target_size, self.walls))
        super().__init__(model, make_symmetry(n_balls, self.walls), render_mode, width, height,
                         camera="fixed")

    def _positions(self, qpos: np.ndarray) -> np.ndarray:
        return qpos.reshape(self.n_balls, 3)

    def _initialize_episode(self, rng: np.random.Generator) -> None:
        direction = rng.normal(size=(self.n_balls, 3))
        direction /= np.linalg.norm(direction, axis=1, keepdims=True)
        radius = INITIAL_RADIUS * rng.uniform(size=(self.n_balls, 1)) ** (1 / 3)
        self.data.qpos[:] = (direction * radius).ravel()

    def _observation(self) -> np.ndarray:
        return np.concatenate([self.data.qpos, self.data.qvel])

    def distances_to_target(self) -> np.ndarray:
        return np.linalg.norm(self._positions(self.data.qpos), axis=1)

    def _reward(self) -> float:
        distances = self.distances_to_target()
        near = dmc.tolerance(distances, bounds=(0, self.target_size), margin=self.target_size)
        small_control = dmc.control_reward(self.data.ctrl.reshape(self.n_balls, 3))
        return float(np.mean(near * small_control))

    def transform_state(self, state: SimState, g: np.ndarray,
                        permutation: np.ndarray | None = None) -> SimState:
        perm = np.arange(self.n_balls) if permutation is None else np.asarray(permutation)
        out = []
        for vector in (state.qpos, state.qvel):
            moved = np.empty((self.n_balls, 3))
            moved[perm] = vector.reshape(self.n_balls, 3) @ g.T
            out.append(moved.ravel())
        return SimState(*out)

    def sample_state(self, rng: np.random.Generator) -> SimState:
        if self.walls:
            qpos = rng.uniform(-WALL, WALL, size=3 * self.n_balls)
        else:
            qpos = rng.normal(scale=0.2, size=3 * self.n_balls)
        return SimState(qpos, rng.normal(scale=0.5, size=3 * self.n_balls))
