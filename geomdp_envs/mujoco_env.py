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
import contextlib
import copy
import importlib.util
import numbers
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


class PhysicsError(RuntimeError):
    """The simulation diverged (NaN, inf or a value beyond MuJoCo's 1e10 in the
    state or its acceleration), as dm_control's PhysicsError: the state is
    meaningless until the env is reset (or given a state with ``set_state``).
    ``details`` holds MuJoCo's warnings."""

    def __init__(self, message: str, details: str = "") -> None:
        super().__init__(message)
        self.details = details

    def __reduce__(self) -> tuple[type, tuple[str, str]]:  # keep details through pickle
        return type(self), (self.args[0], self.details)


def is_real_number(value: Any) -> bool:
    """A Python or numpy int or float; not a bool, whose True is no size or count."""
    return isinstance(value, numbers.Real) and not isinstance(value, (bool, np.bool_))


def positive_int(env_name: str, name: str, value: Any) -> int:
    """``value`` as an int if it is an integer >= 1 (numpy ints too), else a ValueError."""
    if not (is_real_number(value) and isinstance(value, numbers.Integral)) or value < 1:
        raise ValueError(f"{env_name}: {name} must be an integer >= 1, got {value!r}")
    return int(value)


class GeometricMujocoEnv(gymnasium.Env[np.ndarray, np.ndarray]):
    """A Gymnasium env over a MuJoCo model, with a symmetry declaration."""

    metadata = {"render_modes": ["rgb_array"], "render_fps": 50}
    symmetry: Symmetry

    def __init__(self, model: mujoco.MjModel, symmetry: Symmetry, render_mode: str | None,
                 width: int, height: int, camera: str | int) -> None:
        if render_mode not in (None, "rgb_array"):
            raise ValueError(f"render_mode={render_mode!r}; valid: None, 'rgb_array'")
        self._render_size = (positive_int(self._name, "height", height),
                             positive_int(self._name, "width", width))
        # The offscreen framebuffer must hold the image (dm_control's is 640 x 480).
        model.vis.global_.offheight = max(model.vis.global_.offheight, self._render_size[0])
        model.vis.global_.offwidth = max(model.vis.global_.offwidth, self._render_size[1])
        # A diverged simulation raises PhysicsError instead of being silently
        # moved back to the origin, which is what MuJoCo's auto-reset does.
        model.opt.disableflags |= mujoco.mjtDisableBit.mjDSBL_AUTORESET
        self.model = model
        self.data = mujoco.MjData(model)
        self.symmetry = symmetry
        self.render_mode = render_mode
        self._camera = camera
        self._renderer: mujoco.Renderer | None = None
        self.observation_space = spaces.Box(
            -np.inf, np.inf, shape=(symmetry.observation_size,), dtype=np.float32)
        self.action_space = spaces.Box(-1.0, 1.0, shape=(model.nu,), dtype=np.float32)
        if symmetry.action_size != model.nu:
            raise AssertionError("symmetry declaration does not match the model's actuators")
        self.metadata = dict(self.metadata, render_fps=round(1.0 / self.control_timestep))

    @property
    def _name(self) -> str:
        """The task's name for error messages: ``PointMass3D`` for ``PointMass3DEnv``."""
        return type(self).__name__.removesuffix("Env")

    def __getstate__(self) -> dict[str, Any]:
        """Everything but the renderer, for pickle and copy.deepcopy: its GL context
        cannot be copied, and a copy makes its own on its first ``render()``."""
        state = self.__dict__.copy()
        state["_renderer"] = None
        return state

    # --- hooks for subclasses ------------------------------------------------
    def _initialize_episode(self, rng: np.random.Generator) -> None:
        """Set the initial state (positions, task parameters) after mj_resetData."""
        raise NotImplementedError

    def _observation(self) -> np.ndarray:
        """The observation in float64 (cast to float32 at the API boundary)."""
        raise NotImplementedError

    def _reward(self) -> float:
        raise NotImplementedError

    def distances_to_target(self) -> np.ndarray:
        """How far each body that earns reward (the mass, the finger, every ball) is from
        where it earns it: the reward's own distances, shape (bodies,). ``reset`` and
        ``step`` return them as ``info["distance_to_target"]``."""
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
        return self._observation().astype(np.float32), self._info()

    def step(self, action: np.ndarray) -> tuple[np.ndarray, float, bool, bool, dict[str, Any]]:
        self.data.ctrl[:] = self._validated_action(action)
        self._physics_step()
        obs = self._observation().astype(np.float32)
        return obs, float(self._reward()), False, False, self._info()

    def _info(self) -> dict[str, Any]:
        return {"distance_to_target": self.distances_to_target()}

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
        """Move the simulator to ``state``; a malformed or non-finite state raises a
        ValueError naming the bad field and leaves the current state as it was."""
        if not all(hasattr(state, name) for name in ("qpos", "qvel", "task")):
            raise ValueError(f"{self._name}: set_state: state must be a SimState (qpos, qvel, "
                             f"task) as get_state() returns, got {type(state).__name__}")
        qpos = self._checked_vector("state.qpos", state.qpos, (self.model.nq,))
        qvel = self._checked_vector("state.qvel", state.qvel, (self.model.nv,))
        task = self._checked_task(state.task)
        saved = self.get_state()
        self._write_state(qpos, qvel, task)
        try:
            self._forward()
        except PhysicsError as err:
            self._write_state(saved.qpos, saved.qvel, saved.task)
            with contextlib.suppress(PhysicsError):
                self._forward()
            raise ValueError(f"{self._name}: set_state: MuJoCo rejects the state "
                             f"({err.details})") from None

    def _write_state(self, qpos: np.ndarray, qvel: np.ndarray, task: dict[str, np.ndarray]) -> None:
        self.data.qpos[:] = qpos
        self.data.qvel[:] = qvel
        self._set_task_state(task)

    def observe(self) -> np.ndarray:
        """The current observation in float64."""
        return self._observation()

    def simulate(self, action: np.ndarray) -> tuple[np.ndarray, float]:
        """One control step without episode bookkeeping: (float64 observation, reward)."""
        self.data.ctrl[:] = self._validated_action(action)
        self._physics_step()
        return self._observation(), float(self._reward())

    # --- internals -----------------------------------------------------------
    def _checked_task(self, task: Any) -> dict[str, np.ndarray]:
        """``task`` checked against the keys and shapes of this task's parameters."""
        expected = self._task_state()
        valid = ", ".join(repr(key) for key in expected) or "none (an empty dict)"
        if not isinstance(task, dict):
            raise ValueError(f"{self._name}: set_state: state.task must be a dict, got "
                             f"{type(task).__name__}; expected keys: {valid}")
        missing = [key for key in expected if key not in task]
        unknown = [key for key in task if key not in expected]
        if missing or unknown:
            what = (f"is missing {', '.join(map(repr, missing))}" if missing
                    else f"has unknown {', '.join(map(repr, unknown))}")
            raise ValueError(f"{self._name}: set_state: state.task {what}; expected keys: {valid}")
        return {key: self._checked_vector(f"state.task[{key!r}]", task[key], expected[key].shape)
                for key in expected}

    def _checked_vector(self, label: str, value: Any, shape: tuple[int, ...]) -> np.ndarray:
        """``value`` as a float64 array of ``shape`` whose entries MuJoCo accepts:
        finite and within 1e10 (mjMAXVAL; beyond it MuJoCo treats the state as diverged)."""
        try:
            array = np.asarray(value, dtype=np.float64)
        except (TypeError, ValueError):
            raise ValueError(f"{self._name}: set_state: {label} must be an array of numbers, "
                             f"got {value!r}") from None
        if array.shape != shape:
            raise ValueError(f"{self._name}: set_state: {label} has shape {array.shape}, "
                             f"expected {shape}")
        bad = ~(np.abs(array) <= mujoco.mjMAXVAL)  # also true for NaN
        if bad.any():
            index = np.flatnonzero(bad)
            raise ValueError(f"{self._name}: set_state: {label} has NaN, inf or |x| > "
                             f"{mujoco.mjMAXVAL:.0e} at index {index[:5].tolist()}: "
                             f"{array.ravel()[index[:5]].tolist()}")
        return array

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
        warnings_before = self.data.warning.number.tobytes()
        messages: list[str] = []
        previous = mujoco.get_mju_user_warning()
        mujoco.set_mju_user_warning(messages.append)
        self.model.opt.disableflags |= mujoco.mjtDisableBit.mjDSBL_ACTUATION
        try:
            mujoco.mj_forward(self.model, self.data)
        finally:
            self.model.opt.disableflags &= ~int(mujoco.mjtDisableBit.mjDSBL_ACTUATION)
            mujoco.set_mju_user_warning(previous)
        if messages or self.data.warning.number.tobytes() != warnings_before:
            raise self._physics_error(warnings_before, messages)

    def _physics_step(self) -> None:
        # MuJoCo's own warning handler prints and writes MUJOCO_LOG.TXT into the
        # working directory; here a warning becomes a PhysicsError instead, as in
        # dm_control (which checks the same counters, data.warning, after a step).
        warnings_before = self.data.warning.number.tobytes()
        messages: list[str] = []
        previous = mujoco.get_mju_user_warning()
        mujoco.set_mju_user_warning(messages.append)
        try:
            if self.model.opt.integrator == mujoco.mjtIntegrator.mjINT_RK4:
                mujoco.mj_step(self.model, self.data)
            else:
                mujoco.mj_step2(self.model, self.data)
            mujoco.mj_step1(self.model, self.data)
        finally:
            mujoco.set_mju_user_warning(previous)
        if messages or self.data.warning.number.tobytes() != warnings_before:
            raise self._physics_error(warnings_before, messages)

    def _physics_error(self, warnings_before: bytes, messages: list[str]) -> PhysicsError:
        before = np.frombuffer(warnings_before, dtype=self.data.warning.number.dtype)
        new = np.flatnonzero(self.data.warning.number > before)
        details = [mujoco.mju_warningText(int(i), int(self.data.warning.lastinfo[i])) for i in new]
        details = "; ".join(d.removesuffix(" The simulation is unstable.").rstrip(".")
                            for d in details or messages)
        return PhysicsError(f"{self._name}: the simulation diverged at t={self.data.time:.4f} s "
                            f"({details}); call reset() or set_state() before stepping again",
                            details)


def load_triton_before_mesa() -> None:
    """Import triton (shipped with CUDA builds of torch) before Mesa's GL is loaded.

    Mesa's software renderer and triton each bring their own LLVM; loading
    triton's after Mesa's crashes the process (seen with torch 2.14.1 and Mesa
    22.3: render a frame, then import tensordict -> segfault). In the other
    order both work.
    """
    if importlib.util.find_spec("triton") is not None:
        import triton  # noqa: F401
