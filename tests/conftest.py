import os

os.environ.setdefault("MUJOCO_GL", "egl")

import pytest  # noqa: E402

import geomdp_envs  # noqa: E402,F401  (registers the tasks)
from geomdp_envs.mujoco_env import load_triton_before_mesa  # noqa: E402

# The fidelity tests import dm_control.suite, which loads Mesa: triton first.
load_triton_before_mesa()

# Every task configuration the suite offers, as gymnasium.make arguments.
TASK_CONFIGS = [
    pytest.param(("GeoMDP/PointMass2D-v0", {}), id="pointmass2d"),
    pytest.param(("GeoMDP/PointMass3D-v0", {}), id="pointmass3d"),
    pytest.param(("GeoMDP/PointMass3D-v0", {"n_balls": 3, "target_size": 0.02}), id="pointmass3d-3balls"),
    pytest.param(("GeoMDP/PointMass3D-v0", {"walls": True}), id="pointmass3d-walls"),
    pytest.param(("GeoMDP/Reacher-v0", {"difficulty": "easy", "frame": "local"}), id="reacher-easy-local"),
    pytest.param(("GeoMDP/Reacher-v0", {"difficulty": "hard", "frame": "global"}), id="reacher-hard-global"),
]
