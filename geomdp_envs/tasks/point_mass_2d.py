"""PointMass2D: dm_control's ``point_mass`` (easy), with its symmetry declared.

Same model file, initial-state distribution, observation (position, velocity),
reward and 1000-step episodes as dm_control. The slide joints are limited to
+-0.29: these walls leave only the square's group D4 exact (x/y sign flips and
the swap of x and y); a rotation by another angle maps a state near a wall to
one whose wall is elsewhere. Away from the walls O(2) holds. dm_control's
"hard" variant re-randomises the actuator directions every episode and so has
no symmetry; it is not offered.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from geomdp_envs import dmc
from geomdp_envs.mujoco_env import GeometricMujocoEnv, SimState, unknown_kwargs_error
from geomdp_envs.symmetry import Symmetry, layout

SYMMETRY = Symmetry(
    dim=2,
    continuous_group="O(2)",
    exact_group="D4",
    observation=layout(2, [("position", "vector"), ("velocity", "vector")]),
    action=layout(2, [("force", "vector")]),
    notes="The joint limits at +-0.29 (the walls) make D4 exact; O(2) holds only while "
          "the mass stays clear of the walls.",
)


class PointMass2DEnv(GeometricMujocoEnv):
    """Move a planar point mass to the target at the origin."""

    def __init__(self, render_mode: str | None = None, width: int = 240, height: int = 240,
                 **unknown: Any) -> None:
        if unknown:
            raise unknown_kwargs_error("PointMass2D", unknown, ["render_mode", "width", "height"])
        model = dmc.load_suite_model("point_mass.xml")
        super().__init__(model, SYMMETRY, render_mode, width, height, camera="fixed")
        self._limit = model.jnt_range[:, 1].copy()
        self._target_size = float(model.geom("target").size[0])

    def _initialize_episode(self, rng: np.random.Generator) -> None:
        self.data.qpos[:] = rng.uniform(-self._limit, self._limit)

    def _observation(self) -> np.ndarray:
        return np.concatenate([self.data.qpos, self.data.qvel])

    def distances_to_target(self) -> np.ndarray:
        return np.array([np.linalg.norm(self.data.geom("target").xpos
                                        - self.data.geom("pointmass").xpos)])

    def _reward(self) -> float:
        distance = self.distances_to_target()[0]
        near_target = dmc.tolerance(distance, bounds=(0, self._target_size),
                                    margin=self._target_size)
        return float(near_target * dmc.control_reward(self.data.ctrl))

    def transform_state(self, state: SimState, g: np.ndarray,
                        permutation: np.ndarray | None = None) -> SimState:
        if permutation is not None:
            raise ValueError("PointMass2D has a single mass: no permutation symmetry")
        return SimState(g @ state.qpos, g @ state.qvel)

    def sample_state(self, rng: np.random.Generator) -> SimState:
        return SimState(rng.uniform(-self._limit, self._limit), rng.normal(scale=0.5, size=2))
