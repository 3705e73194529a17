"""State access to a declared Gymnasium ``MujocoEnv`` (``DeclaredSimulator``): what a
built-in task offers ``check_symmetry`` -- get, set, sample and transform states,
observe, simulate -- in the declaration's order of fields."""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

import numpy as np

from geomdp_envs.compat import OBSERVE, can_observe, observe, random_state, restore_random_state
from geomdp_envs.declaration import _coverage
from geomdp_envs.mujoco_env import SimState
from geomdp_envs.symmetry import to_action_box

if TYPE_CHECKING:
    from geomdp_envs.declare import DeclaredEnv

WARM_UP_STEPS = 5  # random actions after reset, so that sampled states move


class DeclaredSimulator:
    """State access to a declared Gymnasium ``MujocoEnv``, in declaration order: get, set,
    sample and transform states, observe, simulate (what a built-in task offers
    ``check_symmetry``). Made by ``DeclaredEnv.simulator()``, which checks once that the
    env is a MuJoCo env whose qpos and qvel the declaration covers."""

    def __init__(self, wrapper: DeclaredEnv, mujoco_env: Any) -> None:
        name = wrapper.env_name
        missing = [a for a in ("model", "data", "set_state", "do_simulation") if not hasattr(mujoco_env, a)]
        if not can_observe(mujoco_env):
            missing.append(OBSERVE)
        if missing:
            raise TypeError(f"{name} is not a Gymnasium MujocoEnv (it lacks {', '.join(missing)}): "
                            "check_symmetry needs to set a state g.s in the simulator, which this env "
                            "does not allow")
        if mujoco_env.model.na:
            raise ValueError(f"{name} has {mujoco_env.model.na} actuator activation state(s), "
                             "which a declaration does not cover: check_symmetry cannot move them")
        for vector, size in (("qpos", mujoco_env.model.nq), ("qvel", mujoco_env.model.nv)):
            try:
                _coverage(f"state.{vector}", wrapper.declaration.state.get(vector, ()), int(size))
            except ValueError as err:
                raise ValueError(f"{name}: {err}") from None
        self.wrapper, self.env, self.symmetry = wrapper, mujoco_env, wrapper.symmetry

    def get_state(self) -> SimState:
        """qpos and qvel, plus the simulation time and controls (kept unmoved by g, and
        put back when check_symmetry restores the env)."""
        data = self.env.data
        return SimState(data.qpos.copy(), data.qvel.copy(),
                        {"time": np.array([data.time]), "ctrl": data.ctrl.copy()})

    def set_state(self, state: SimState) -> None:
        """Sets qpos, qvel (and time, controls when given), and clears the solver's warm
        start so that two runs from the same state are the same run."""
        self.env.data.qacc_warmstart[:] = 0
        if "time" in state.task:
            self.env.data.time = float(state.task["time"][0])
        if "ctrl" in state.task:
            self.env.data.ctrl[:] = state.task["ctrl"]
        self.env.set_state(np.asarray(state.qpos, dtype=np.float64),
                           np.asarray(state.qvel, dtype=np.float64))

    def transform_state(self, state: SimState, g: np.ndarray,
                        permutation: np.ndarray | None = None) -> SimState:
        if permutation is not None:
            raise ValueError(f"{self.wrapper.env_name}: a declared env has no interchangeable particles")
        moved = self.wrapper.declaration.transform_state({"qpos": state.qpos, "qvel": state.qvel}, g)
        return SimState(moved["qpos"], moved["qvel"], dict(state.task))

    def sample_state(self, rng: np.random.Generator) -> SimState:
        """A state the env itself reaches: a reset, then a few random actions. The env's
        own random generator is put back, so checking does not change its episodes."""
        saved = random_state(self.env)
        try:
            self.env.reset(seed=int(rng.integers(2**31)))
            for action in self.symmetry.sample_action(rng, WARM_UP_STEPS):
                self.env.step(self._env_action(action))
        finally:
            restore_random_state(self.env, saved)
        return self.get_state()

    def observe(self) -> np.ndarray:
        return self.wrapper.to_declared_observation(np.asarray(observe(self.env), dtype=np.float64))

    def simulate(self, action: np.ndarray) -> tuple[np.ndarray, float]:
        """One step of the bare env (no time limit), an action in ``ACTION_DOMAIN`` scaled
        to the action box: (observation in declaration order, reward)."""
        obs, reward, *_ = self.env.step(self._env_action(action))
        return self.wrapper.to_declared_observation(np.asarray(obs, dtype=np.float64)), float(reward)

    def _env_action(self, action: np.ndarray) -> np.ndarray:
        return self.wrapper.to_env_action(to_action_box(action, self.wrapper.action_space))
