"""dm_control pieces reused as they are: model files, assets and the reward helper.

Using dm_control's own XML and ``rewards.tolerance`` (rather than copies) is
what makes the GeoMDP tasks match dm_control's to the bit.
"""

from __future__ import annotations

import mujoco
import numpy as np
from dm_control.suite import common
from dm_control.utils.rewards import tolerance

__all__ = ["ASSETS", "load_suite_model", "model_from_xml", "tolerance", "control_reward"]

ASSETS = common.ASSETS


def model_from_xml(xml: str) -> mujoco.MjModel:
    """Compile an MJCF string that may include dm_control's common assets."""
    return mujoco.MjModel.from_xml_string(xml, ASSETS)


def load_suite_model(filename: str) -> mujoco.MjModel:
    """A dm_control suite model, e.g. ``point_mass.xml``."""
    return model_from_xml(common.read_model(filename))


def control_reward(control: np.ndarray) -> np.ndarray:
    """point_mass's "small control" factor in [0.8, 1]: (4 + mean(1 - u_i^2)) / 5.

    dm_control's quadratic tolerance is 1 - u^2 inside |u| <= 1, so the mean is
    1 - |u|^2 / n: rotation-invariant for actions in the unit ball. Reduces the
    last axis, so a [n_balls, 3] control gives one factor per ball.
    """
    per_coordinate = tolerance(control, margin=1, value_at_margin=0, sigmoid="quadratic")
    return (np.mean(per_coordinate, axis=-1) + 4) / 5
