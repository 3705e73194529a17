"""dm_control pieces reused as they are: model files, assets and the reward helper.

Using dm_control's own XML and ``rewards.tolerance`` (rather than copies) is
what makes the GeoMDP tasks match dm_control's to the bit. The files are read
from the installed package without importing ``dm_control.suite``: that
import sets up dm_control's renderer, which loads Mesa's LLVM and makes a
later ``import triton`` (done by torch/tensordict) crash.
"""

from __future__ import annotations

import functools
import importlib.resources

import mujoco
import numpy as np
from dm_control.utils.rewards import tolerance

__all__ = ["load_suite_model", "model_from_xml", "tolerance", "control_reward"]

_SUITE = importlib.resources.files("dm_control") / "suite"


@functools.cache
def _assets() -> dict[str, bytes]:
    """dm_control's shared includes (skybox, visual, materials), keyed as MJCF names them."""
    return {f"./common/{name}": (_SUITE / "common" / name).read_bytes()
            for name in ("materials.xml", "skybox.xml", "visual.xml")}


def model_from_xml(xml: str) -> mujoco.MjModel:
    """Compile an MJCF string that may include dm_control's common assets."""
    return mujoco.MjModel.from_xml_string(xml, _assets())


def load_suite_model(filename: str) -> mujoco.MjModel:
    """A dm_control suite model, e.g. ``point_mass.xml``."""
    return model_from_xml((_SUITE / filename).read_text())


def control_reward(control: np.ndarray) -> np.ndarray:
    """point_mass's "small control" factor in [0.8, 1]: (4 + mean(1 - u_i^2)) / 5.

    dm_control's quadratic tolerance is 1 - u^2 inside |u| <= 1, so the mean is
    1 - |u|^2 / n: rotation-invariant for actions in the unit ball. Reduces the
    last axis, so a [n_balls, 3] control gives one factor per ball.
    """
    per_coordinate = tolerance(control, margin=1, value_at_margin=0, sigmoid="quadratic")
    return (np.mean(per_coordinate, axis=-1) + 4) / 5
