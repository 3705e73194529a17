"""Base class of the GeoMDP tasks: a MuJoCo model stepped exactly as dm_control does.

dm_control's ``Physics.step`` (its default "legacy" step) finishes the pending
step with ``mj_step2`` and then runs ``mj_step1`` so that positions and
velocities are up to date for observations. Doing the same here reproduces
dm_control's trajectories bit for bit while skipping its per-step overhead.

Subclasses provide the model, the episode initialisation, the observation, the
reward, a ``Symmetry`` declaration, and how a group element acts on the
simulator state (``transform_state``), which is what ``check_symmetry`` needs.
"""

from __future__ import annotations

import atexit
import copy
import importlib.util
from dataclasses import dataclass, field
from typing import Any

import gymnasium
import mujoco
import numpy as np
from gymnasium import spaces

from geomdp_envs.symmetry import Symmetry


@dataclass
class SimState:
    """Everything that determines the future of an episode: joint positions and
    velocities plus task parameters (e.g. Reacher's target position)."""

    qpos: np.ndarray
    qvel: np.ndarray
    task: dict[str, np.ndarray] = field(default_factory=dict)

    def copy(self) -> SimState:
        return copy.deepcopy(self)


class UnknownArgumentError(ValueError, TypeError):
    """An unknown keyword argument: a ValueError, and a TypeError as Python raises
    for unexpected keywords (TorchRL's GymEnv relies on that to drop its
    ``frameskip`` probe)."""


def unknown_kwargs_error(env_name: str, unknown: dict[str, Any],
                         valid: list[str]) -> UnknownArgumentError:
    names = ", ".join(repr(name) for name in sorted(unknown))
    return UnknownArgumentError(f"{env_name}: unexpected keyword argument {names}; "
                                "valid arguments: " + ", ".join(valid))


class GeometricMujocoEnv(gymnasium.Env[np.ndarray, np.ndarray]):
    """A Gymnasium env over a MuJoCo model, with a symmetry declaration."""

    metadata = {"render_modes": ["rgb_array"], "render_fps": 50}
    symmetry: Symmetry

    def __init__(self, model: mujoco.MjModel, symmetry: Symmetry, render_mode: str | None,
                 width: int, height: int, camera: str | int) -> None:
        if render_mode not in (None, "rgb_array"):
            raise ValueError(f"render_mode={render_mode!r}; valid: None, 'rgb_array'")
        self.model = model
        self.data = mujoco.MjData(model)
        self.symmetry = symmetry
        self.render_mode = render_mode
        self._render_size = (int(height), int(width))
        self._camera = camera
        self._renderer: mujoco.Renderer | None = None
        self.observation_space = spaces.Box(
            -np.inf, np.inf, shape=(symmetry.observation_size,), dtype=np.float32)
        self.action_space = spaces.Box(-1.0, 1.0, shape=(model.nu,), dtype=np.float32)
        if symmetry.action_size != model.nu:
            raise AssertionError("symmetry declaration does not match the model's actuators")
        self.metadata = dict(self.metadata, render_fps=round(1.0 / self.control_timestep))

    # --- hooks for subclasses ------------------------------------------------
    def _initialize_episode(self, rng: np.random.Generator) -> None:
        """Set the initial state (positions, task parameters) after mj_resetData."""
        raise NotImplementedError

    def _observation(self) -> np.ndarray:
        """The observation in float64 (cast to float32 at the API boundary)."""
        raise NotImplementedError

    def _reward(self) -> float:
        raise NotImplementedError

    def _set_task_state(self, task: dict[str, np.ndarray]) -> None:
        """Write task parameters (e.g. a target position) into the model."""

    def _task_state(self) -> dict[str, np.ndarray]:
        return {}

    def transform_state(self, state: SimState, g: np.ndarray,
                        permutation: np.ndarray | None = None) -> SimState:
        """The simulator state g . s (and with particles relabelled by ``permutation``)."""
        raise NotImplementedError

    def sample_state(self, rng: np.random.Generator) -> SimState:
        """A random state for symmetry checks: wider than the initial distribution
        (non-zero velocities, positions up to the walls)."""
        raise NotImplementedError

    # --- Gymnasium API -------------------------------------------------------
    @property
    def control_timestep(self) -> float:
        return float(self.model.opt.timestep)

    def reset(self, *, seed: int | None = None,
              options: dict[str, Any] | None = None) -> tuple[np.ndarray, dict[str, Any]]:
        super().reset(seed=seed)
        mujoco.mj_resetData(self.model, self.data)
        self._initialize_episode(self.np_random)
        self._forward()
        return self._observation().astype(np.float32), {}

    def step(self, action: np.ndarray) -> tuple[np.ndarray, float, bool, bool, dict[str, Any]]:
        self.data.ctrl[:] = self._validated_action(action)
        self._physics_step()
        obs = self._observation().astype(np.float32)
        return obs, float(self._reward()), False, False, {}

    def render(self) -> np.ndarray | None:
        if self.render_mode is None:
            gymnasium.logger.warn("render() called without render_mode='rgb_array'")
            return None
        if self._renderer is None:
            load_triton_before_mesa()
            self._renderer = mujoco.Renderer(self.model, *self._render_size)
            atexit.register(self.close)  # free the GL context while OpenGL is still loaded
        self._renderer.update_scene(self.data, camera=self._camera)
        return self._renderer.render()

    def close(self) -> None:
        if self._renderer is not None:
            self._renderer.close()
            self._renderer = None

    # --- state access, used by check_symmetry and by planners -----------------
    def get_state(self) -> SimState:
        return SimState(self.data.qpos.copy(), self.data.qvel.copy(), self._task_state())

    def set_state(self, state: SimState) -> None:
        self.data.qpos[:] = state.qpos
        self.data.qvel[:] = state.qvel
        self._set_task_state(state.task)
        self._forward()

    def observe(self) -> np.ndarray:
        """The current observation in float64."""
        return self._observation()

    def simulate(self, action: np.ndarray) -> tuple[np.ndarray, float]:
        """One control step without episode bookkeeping: (float64 observation, reward)."""
        self.data.ctrl[:] = self._validated_action(action)
        self._physics_step()
        return self._observation(), float(self._reward())

    # --- internals -----------------------------------------------------------
    def _validated_action(self, action: Any) -> np.ndarray:
        try:
            action = np.asarray(action, dtype=np.float64)
        except (TypeError, ValueError) as err:
            raise ValueError(f"action must be an array of {self.model.nu} numbers: {err}") from None
        if action.shape != (self.model.nu,):
            raise ValueError(f"action has shape {action.shape}, expected ({self.model.nu},)")
        if not np.all(np.isfinite(action)):
            raise ValueError(f"action contains NaN or inf: {action.tolist()}")
        return action

    def _forward(self) -> None:
        # As dm_control's after_reset: recompute derived quantities with the
        # actuators off, since there is no meaningful control yet.
        self.model.opt.disableflags |= mujoco.mjtDisableBit.mjDSBL_ACTUATION
        try:
            mujoco.mj_forward(self.model, self.data)
        finally:
            self.model.opt.disableflags &= ~int(mujoco.mjtDisableBit.mjDSBL_ACTUATION)

    def _physics_step(self) -> None:
        if self.model.opt.integrator == mujoco.mjtIntegrator.mjINT_RK4:
            mujoco.mj_step(self.model, self.data)
        else:
            mujoco.mj_step2(self.model, self.data)
        mujoco.mj_step1(self.model, self.data)


def load_triton_before_mesa() -> None:
    """Import triton (shipped with CUDA builds of torch) before Mesa's GL is loaded.

    Mesa's software renderer and triton each bring their own LLVM; loading
    triton's after Mesa's crashes the process (seen with torch 2.14.1 and Mesa
    22.3: render a frame, then import tensordict -> segfault). In the other
    order both work.
    """
    if importlib.util.find_spec("triton") is not None:
        import triton  # noqa: F401
