"""Reacher: dm_control's two-link planar ``reacher``, with local or global features.

Same model file, initial-state and target distributions, sparse reward,
target sizes (easy 0.05, hard 0.015) and 1000-step episodes as dm_control.
dm_control observes the joint angles themselves; here they are replaced by
their cosines and sines, as in the paper:

* ``frame="local"``: (cos q1, sin q1, cos q2, sin q2, dq1, dq2, to_target x, y),
  the second link relative to the first;
* ``frame="global"``: (cos q1, sin q1, cos(q1+q2), sin(q1+q2), dq1, dq2,
  to_target x, y), the second link's direction in the world frame.

What is true under O(2) (declared below, checked by ``check_symmetry``): the
arm's direction and the vector to the target rotate and reflect as vectors;
the relative angle q2, both joint velocities and both torques are invariant
under rotations but change sign under reflections ("sign" fields). So cos q2
is trivial and sin q2 is a sign field. The paper declares the whole of
(cos q2, sin q2) and the torques trivial, which is exact under SO(2) only.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from geomdp_envs import dmc
from geomdp_envs.mujoco_env import GeometricMujocoEnv, SimState, unknown_kwargs_error
from geomdp_envs.symmetry import Symmetry, layout

TARGET_SIZES = {"easy": 0.05, "hard": 0.015}
FRAMES = ("local", "global")
_VALID_ARGS = ["difficulty", "frame", "render_mode", "width", "height"]

_VELOCITIES_AND_TARGET = [("shoulder_velocity", "sign"), ("wrist_velocity", "sign"),
                          ("to_target", "vector")]
SYMMETRIES = {
    "local": Symmetry(
        dim=2, continuous_group="O(2)", exact_group="O(2)",
        observation=layout(2, [("arm_direction", "vector"), ("wrist_cos", "trivial"),
                               ("wrist_sin", "sign")] + _VELOCITIES_AND_TARGET),
        action=layout(2, [("shoulder_torque", "sign"), ("wrist_torque", "sign")]),
        notes="Second link relative to the first: its angle is invariant under rotations "
              "and changes sign under reflections.",
    ),
    "global": Symmetry(
        dim=2, continuous_group="O(2)", exact_group="O(2)",
        observation=layout(2, [("arm_direction", "vector"), ("hand_direction", "vector")]
                           + _VELOCITIES_AND_TARGET),
        action=layout(2, [("shoulder_torque", "sign"), ("wrist_torque", "sign")]),
        notes="Second link's direction in the world frame: a vector.",
    ),
}


class ReacherEnv(GeometricMujocoEnv):
    """Bring the tip of a two-link planar arm into a random target."""

    def __init__(self, difficulty: str = "easy", frame: str = "local",
                 render_mode: str | None = None, width: int = 240, height: int = 240,
                 **unknown: Any) -> None:
        if unknown:
            raise unknown_kwargs_error("Reacher", unknown, _VALID_ARGS)
        if difficulty not in TARGET_SIZES:
            raise ValueError(f"Reacher: difficulty={difficulty!r}; valid: 'easy', 'hard'")
        if frame not in FRAMES:
            raise ValueError(f"Reacher: frame={frame!r}; valid: 'local', 'global'")
        self.difficulty, self.frame = difficulty, frame
        model = dmc.load_suite_model("reacher.xml")
        model.geom("target").size[0] = TARGET_SIZES[difficulty]
        super().__init__(model, SYMMETRIES[frame], render_mode, width, height, camera="fixed")
        self._wrist_range = model.jnt_range[1].copy()
        self._radii = TARGET_SIZES[difficulty] + float(model.geom("finger").size[0])

    def _initialize_episode(self, rng: np.random.Generator) -> None:
        self.data.qpos[:] = [rng.uniform(-np.pi, np.pi), rng.uniform(*self._wrist_range)]
        angle, radius = rng.uniform(0, 2 * np.pi), rng.uniform(0.05, 0.20)
        self._set_task_state({"target": radius * np.array([np.sin(angle), np.cos(angle)])})

    def _to_target(self) -> np.ndarray:
        return self.data.geom("target").xpos[:2] - self.data.geom("finger").xpos[:2]

    def _observation(self) -> np.ndarray:
        q1, q2 = self.data.qpos
        second = q2 if self.frame == "local" else q1 + q2
        return np.concatenate([[np.cos(q1), np.sin(q1), np.cos(second), np.sin(second)],
                               self.data.qvel, self._to_target()])

    def distances_to_target(self) -> np.ndarray:
        """From the finger's centre to the target's (reward 1 within their radii's sum)."""
        return np.array([np.linalg.norm(self._to_target())])

    def _reward(self) -> float:
        return float(dmc.tolerance(self.distances_to_target()[0], (0, self._radii)))

    def _task_state(self) -> dict[str, np.ndarray]:
        return {"target": self.model.geom("target").pos[:2].copy()}

    def _set_task_state(self, task: dict[str, np.ndarray]) -> None:
        self.model.geom("target").pos[:2] = task["target"]

    def transform_state(self, state: SimState, g: np.ndarray,
                        permutation: np.ndarray | None = None) -> SimState:
        if permutation is not None:
            raise ValueError("Reacher has no permutation symmetry")
        det = np.sign(np.linalg.det(g))
        q1, q2 = state.qpos
        arm = g @ np.array([np.cos(q1), np.sin(q1)])
        qpos = np.array([np.arctan2(arm[1], arm[0]), det * q2])
        return SimState(qpos, det * state.qvel, {"target": g @ state.task["target"]})

    def sample_state(self, rng: np.random.Generator) -> SimState:
        angle, radius = rng.uniform(0, 2 * np.pi), rng.uniform(0.05, 0.20)
        return SimState(np.array([rng.uniform(-np.pi, np.pi), rng.uniform(*self._wrist_range)]),
                        rng.normal(scale=2.0, size=2),
                        {"target": radius * np.array([np.sin(angle), np.cos(angle)])})
