"""GeoMDP environments: Gymnasium tasks that declare their Euclidean symmetry.

Importing this package registers the tasks (Gymnasium 1.x has no plugin entry
points), so ``gymnasium.make("GeoMDP/PointMass3D-v0", n_balls=3)`` works after
``import geomdp_envs``, and ``gymnasium.make("geomdp_envs:GeoMDP/PointMass3D-v0")``
works without it.
"""

from __future__ import annotations

import os

# Off-screen rendering on a machine with no display: EGL (Mesa's software
# renderer where there is no GPU). It must be chosen before mujoco is imported.
if "MUJOCO_GL" not in os.environ and not os.environ.get("DISPLAY"):
    os.environ["MUJOCO_GL"] = "egl"

import gymnasium  # noqa: E402

from geomdp_envs import groups  # noqa: E402
from geomdp_envs.augment import augment_transitions, default_augmentation_group  # noqa: E402
from geomdp_envs.check import SymmetryReport, check_symmetry  # noqa: E402
from geomdp_envs.declare import (  # noqa: E402
    Declaration,
    DeclaredEnv,
    declare,
    load_declaration,
    symmetry_of,
)
from geomdp_envs.mujoco_env import GeometricMujocoEnv, PhysicsError, SimState  # noqa: E402
from geomdp_envs.symmetry import Field, Symmetry  # noqa: E402

__all__ = [
    "Declaration", "DeclaredEnv", "Field", "GeometricMujocoEnv", "PhysicsError", "SimState", "Symmetry",
    "SymmetryReport", "TASKS", "augment_transitions", "check_symmetry", "declare",
    "default_augmentation_group", "groups", "load_declaration", "symmetry_of",
]

EPISODE_STEPS = 1000  # dm_control's 20 s at a 0.02 s control step

TASKS = {
    "GeoMDP/PointMass2D-v0": "geomdp_envs.tasks.point_mass_2d:PointMass2DEnv",
    "GeoMDP/PointMass3D-v0": "geomdp_envs.tasks.point_mass_3d:PointMass3DEnv",
    "GeoMDP/Reacher-v0": "geomdp_envs.tasks.reacher:ReacherEnv",
}

for _id, _entry_point in TASKS.items():
    if _id not in gymnasium.registry:
        gymnasium.register(id=_id, entry_point=_entry_point, max_episode_steps=EPISODE_STEPS)
