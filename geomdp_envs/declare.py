"""Declare the symmetry of a third-party environment (bring your own task).

A built-in GeoMDP task lays its fields out one after another. A third-party env
rarely does: Gymnasium's ``Reacher-v5`` observes ``cos q1, cos q2, sin q1, sin q2,
...``, so the vector ``(cos q1, sin q1)`` sits at indices 0 and 2. A
``Declaration`` names each field by the indices it occupies; ``declare`` wraps the
env in a ``DeclaredEnv`` that reorders observations (and actions) into the
declaration's order, so that everything downstream (the ``Symmetry`` it exposes,
augmentation, the equivariant agent) sees contiguous fields as for a built-in task.

To be checked against its simulator (``check_symmetry``), a declaration also says
how the physical state moves: which of MuJoCo's ``qpos`` and ``qvel`` entries are
vectors, signs, planar orientation angles. Declarations are plain data and load
from YAML (``load_declaration("reacher_v5")`` reads a shipped one, or give a path).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from importlib import resources
from pathlib import Path
from typing import Any

import gymnasium
import numpy as np
import yaml
from gymnasium import spaces

from geomdp_envs import groups
from geomdp_envs.mujoco_env import SimState
from geomdp_envs.symmetry import (
    REPRESENTATIONS,
    Symmetry,
    check_groups,
    layout,
    rep_matrix,
    rep_size,
    to_action_box,
)

# A planar orientation angle phi (an absolute hinge about the plane's normal): g moves
# it to the angle of g (cos phi, sin phi). Only the state has these; observations show
# an angle as a vector (cos, sin) or not at all.
STATE_REPRESENTATIONS = REPRESENTATIONS + ("angle",)
STATE_VECTORS = ("qpos", "qvel")
SHIPPED = resources.files("geomdp_envs") / "declarations"
WARM_UP_STEPS = 5  # random actions after reset, so that sampled states move
# The wrappers gymnasium.make adds, which change no observation or action: the checker
# steps the bare env, so any other wrapper under ``declare`` would go unchecked.
BOOKKEEPING_WRAPPERS = (gymnasium.wrappers.TimeLimit, gymnasium.wrappers.OrderEnforcing,
                        gymnasium.wrappers.PassiveEnvChecker)


@dataclass(frozen=True)
class IndexedField:
    """A field at arbitrary ``index`` positions of a vector (one per coordinate)."""

    name: str
    rep: str
    index: tuple[int, ...]

    @classmethod
    def parse(cls, entry: Any, kind: str) -> IndexedField:
        """From ``{name, rep, index}`` or ``(name, rep, index)``; ``index`` an int or list."""
        if isinstance(entry, IndexedField):
            return entry
        if isinstance(entry, Mapping):
            unknown = set(entry) - {"name", "rep", "index"}
            if unknown or not {"name", "rep", "index"} <= set(entry):
                raise ValueError(f"{kind} field {dict(entry)!r}: needs exactly the keys name, rep, index")
            name, rep, index = entry["name"], entry["rep"], entry["index"]
        elif isinstance(entry, Sequence) and not isinstance(entry, str) and len(entry) == 3:
            name, rep, index = entry
        else:
            raise ValueError(f"{kind} field {entry!r}: write it as {{name, rep, index}} or "
                             "(name, rep, index)")
        if not isinstance(name, str) or not isinstance(rep, str):
            raise ValueError(f"{kind} field {entry!r}: name and rep must be strings")
        items = [index] if isinstance(index, int) else index
        if (not isinstance(items, Sequence) or isinstance(items, str) or not items
                or not all(isinstance(i, int) and not isinstance(i, bool) for i in items)):
            raise ValueError(f"{kind} field {name!r}: index must be an int or a non-empty list of "
                             f"ints, got {index!r}")
        return cls(name, rep, tuple(items))


def _parse_fields(entries: Any, kind: str) -> tuple[IndexedField, ...]:
    if entries is None or isinstance(entries, (str, Mapping)) or not isinstance(entries, Sequence):
        raise ValueError(f"{kind}: expected a list of fields, got {type(entries).__name__}")
    return tuple(IndexedField.parse(e, kind) for e in entries)


@dataclass(frozen=True)
class Declaration:
    """How O(d) acts on an env's observation, action and (optionally) MuJoCo state.

    ``state`` maps ``qpos`` and ``qvel`` to their fields; without it the declaration
    can train an agent but ``check_symmetry`` cannot test it.
    """

    dim: int
    continuous_group: str
    exact_group: str
    observation: tuple[IndexedField, ...]
    action: tuple[IndexedField, ...]
    state: dict[str, tuple[IndexedField, ...]] | None = None
    notes: str = ""

    def __post_init__(self) -> None:
        if not isinstance(self.dim, int) or isinstance(self.dim, bool) or self.dim not in (2, 3):
            raise ValueError(f"declaration: dim must be 2 or 3, got {self.dim!r}")
        for key in ("continuous_group", "exact_group"):
            if not isinstance(getattr(self, key), str):
                raise ValueError(f"declaration: {key} must be a group name such as O(2), "
                                 f"got {getattr(self, key)!r}")
        check_groups(self.dim, self.continuous_group, self.exact_group)
        # fields given as tuples or dicts (building a Declaration directly) are parsed here
        for kind in ("observation", "action"):
            object.__setattr__(self, kind, _parse_fields(getattr(self, kind), kind))
            self._check_fields(kind, getattr(self, kind), REPRESENTATIONS)
        if self.state is not None:
            if not isinstance(self.state, Mapping):
                raise ValueError("declaration: state must map qpos and qvel to their fields")
            unknown = set(self.state) - set(STATE_VECTORS)
            if unknown:
                raise ValueError(f"state: unknown vector(s) {sorted(unknown)}; valid: "
                                 f"{', '.join(STATE_VECTORS)}")
            state = {name: _parse_fields(fields, f"state.{name}") for name, fields in self.state.items()}
            object.__setattr__(self, "state", state)
            for name, fields in state.items():
                self._check_fields(f"state.{name}", fields, STATE_REPRESENTATIONS)

    def _check_fields(self, kind: str, fields: tuple[IndexedField, ...], reps: tuple[str, ...]) -> None:
        names = [f.name for f in fields]
        repeated = sorted({n for n in names if names.count(n) > 1})
        if repeated:
            raise ValueError(f"{kind}: field name(s) {repeated} used twice; each field needs its own "
                             "name (the check reports errors by name)")
        for f in fields:
            if f.rep not in reps:
                raise ValueError(f"{kind} field {f.name!r}: unknown representation {f.rep!r}; "
                                 f"valid: {', '.join(reps)}")
            size = 1 if f.rep == "angle" else rep_size(f.rep, self.dim)
            if f.rep == "angle" and self.dim != 2:
                raise ValueError(f"{kind} field {f.name!r}: an angle is planar (dim 2)")
            if len(f.index) != size:
                raise ValueError(f"{kind} field {f.name!r}: a {f.rep} of R^{self.dim} has {size} "
                                 f"coordinate(s), the index lists {len(f.index)}")

    # --- plain data ---------------------------------------------------------------
    @classmethod
    def from_dict(cls, data: Mapping[str, Any]) -> Declaration:
        """From plain data (as YAML holds it); unknown keys are an error."""
        data = dict(data)
        allowed = {"dim", "continuous_group", "exact_group", "observation", "action", "state", "notes"}
        unknown = set(data) - allowed
        if unknown:
            raise ValueError(f"declaration: unknown key(s) {sorted(unknown)}; "
                             f"valid: {', '.join(sorted(allowed))}")
        missing = {"dim", "continuous_group", "observation", "action"} - set(data)
        if missing:
            raise ValueError(f"declaration: missing key(s) {sorted(missing)}")
        return cls(dim=data["dim"], continuous_group=data["continuous_group"],
                   exact_group=data.get("exact_group", data["continuous_group"]),
                   observation=data["observation"], action=data["action"], state=data.get("state"),
                   notes=str(data.get("notes", "")))

    def to_dict(self) -> dict[str, Any]:
        """Plain data that ``from_dict`` (and YAML) reads back."""

        def plain(fields: tuple[IndexedField, ...]) -> list[dict[str, Any]]:
            return [{"name": f.name, "rep": f.rep, "index": list(f.index)} for f in fields]

        out = {"dim": self.dim, "continuous_group": self.continuous_group,
               "exact_group": self.exact_group, "observation": plain(self.observation),
               "action": plain(self.action)}
        if self.state is not None:
            out["state"] = {k: plain(v) for k, v in self.state.items()}
        if self.notes:
            out["notes"] = self.notes
        return out

    # --- the contiguous layout the agent sees -------------------------------------------
    def order(self, kind: str, size: int) -> np.ndarray:
        """Indices of the env's ``kind`` vector in declaration order (a permutation of
        range(size)), or an error naming the indices left out, repeated or out of range."""
        fields = self.observation if kind == "observation" else self.action
        return _coverage(kind, fields, size)

    def symmetry(self, observation_size: int, action_size: int) -> Symmetry:
        """The declaration as a ``Symmetry`` on the reordered vectors."""
        self.order("observation", observation_size)
        self.order("action", action_size)

        return Symmetry(self.dim, self.continuous_group, self.exact_group,
                        layout(self.dim, [(f.name, f.rep) for f in self.observation]),
                        layout(self.dim, [(f.name, f.rep) for f in self.action]), notes=self.notes)

    def transform_state(self, vectors: dict[str, np.ndarray], g: np.ndarray) -> dict[str, np.ndarray]:
        """g applied to ``{"qpos": ..., "qvel": ...}`` field by field."""
        if self.state is None:
            raise ValueError("this declaration has no state: declare how qpos and qvel move "
                             "(state={'qpos': [...], 'qvel': [...]}) to check it against the simulator")
        g = groups.as_orthogonal(g, self.dim)
        out = {name: np.array(v, dtype=np.float64) for name, v in vectors.items()}
        for name, fields in self.state.items():
            for f in fields:
                index = list(f.index)
                if f.rep == "angle":
                    phi = vectors[name][index[0]]
                    moved = g @ np.array([np.cos(phi), np.sin(phi)])
                    out[name][index[0]] = np.arctan2(moved[1], moved[0])
                else:
                    out[name][index] = rep_matrix(f.rep, g) @ vectors[name][index]
        return out


def _coverage(kind: str, fields: tuple[IndexedField, ...], size: int) -> np.ndarray:
    order = np.array([i for f in fields for i in f.index], dtype=np.int64)
    bad = sorted({int(i) for i in order if not 0 <= i < size})
    if bad:
        raise ValueError(f"{kind} indices {bad} are out of range for a vector of size {size}")
    repeated = sorted({int(i) for i in order if (order == i).sum() > 1})
    if repeated:
        raise ValueError(f"{kind} indices {repeated} belong to more than one field")
    missing = sorted(set(range(size)) - set(order.tolist()))
    if missing:
        raise ValueError(f"{kind} indices {missing} belong to no field: declare every coordinate "
                         "(an invariant one as rep: trivial)")
    return order


def shipped_declarations() -> tuple[str, ...]:
    """Names of the declarations that ship with geomdp_envs."""
    return tuple(sorted(p.name[: -len(".yaml")] for p in SHIPPED.iterdir() if p.name.endswith(".yaml")))


def load_declaration(source: str | Path | Mapping[str, Any] | Declaration) -> Declaration:
    """A declaration from a shipped name (``reacher_v5``), a YAML file, or plain data."""
    if isinstance(source, Declaration):
        return source
    if isinstance(source, Mapping):
        return Declaration.from_dict(source)
    text = str(source)
    if text in shipped_declarations():
        path = SHIPPED / f"{text}.yaml"
    elif Path(text).is_file():
        path = Path(text)
    else:
        raise ValueError(f"symmetry declaration {text!r} is neither a YAML file nor a shipped "
                         f"declaration ({', '.join(shipped_declarations())})")
    try:
        data = yaml.safe_load(path.read_text())
    except (OSError, yaml.YAMLError) as err:
        raise ValueError(f"symmetry declaration {text!r} cannot be read: "
                         f"{' '.join(str(err).split())}") from None
    if not isinstance(data, Mapping):
        raise ValueError(f"symmetry declaration {text!r}: expected a mapping, got {type(data).__name__}")
    return Declaration.from_dict(data)


def _box(space: spaces.Space, order: np.ndarray, kind: str) -> spaces.Box:
    if not isinstance(space, spaces.Box) or len(space.shape) != 1:
        raise ValueError(f"{kind} space {space} is not a flat Box: a declaration indexes a vector")
    return spaces.Box(space.low[order], space.high[order], dtype=space.dtype)


class DeclaredEnv(gymnasium.Wrapper):
    """A third-party env with a symmetry declaration, its vectors in declaration order.

    The agent sends actions in declaration order and receives observations in it;
    ``symmetry`` describes those reordered vectors. For a MuJoCo env whose state
    the declaration covers, ``simulator()`` gives the state access ``check_symmetry``
    uses (get/set/sample/transform state, observe, simulate), as the built-in tasks do.
    """

    def __init__(self, env: gymnasium.Env, declaration: Declaration) -> None:
        super().__init__(env)
        self.declaration = declaration
        name = env.spec.id if env.spec is not None else type(env.unwrapped).__name__
        self.env_name = name
        obs_space, act_space = env.observation_space, env.action_space
        obs_size = _box(obs_space, np.arange(obs_space.shape[0] if obs_space.shape else 0),
                        "observation").shape[0]
        act_size = _box(act_space, np.arange(act_space.shape[0] if act_space.shape else 0),
                        "action").shape[0]
        try:
            self.symmetry = declaration.symmetry(obs_size, act_size)
        except ValueError as err:
            raise ValueError(f"{name}: {err}") from None
        self._obs_order = declaration.order("observation", obs_size)
        self._action_order = declaration.order("action", act_size)
        self.observation_space = _box(obs_space, self._obs_order, "observation")
        self.action_space = _box(act_space, self._action_order, "action")
        self._check_action_bounds()

    def _check_action_bounds(self) -> None:
        """The group must map the action box to itself after Gymnasium's rescaling:
        signed fields need bounds symmetric about 0, vector fields one bound for all."""
        low, high = self.action_space.low, self.action_space.high
        for f in self.symmetry.action:
            lo, hi = low[f.start:f.stop], high[f.start:f.stop]
            if f.rep != "trivial" and not np.allclose(lo, -hi):
                raise ValueError(f"{self.env_name}: action field {f.name!r} is {f.rep} but its bounds "
                                 f"[{lo.tolist()}, {hi.tolist()}] are not symmetric about 0")
            if f.size > 1 and not (np.allclose(lo, lo[0]) and np.allclose(hi, hi[0])):
                raise ValueError(f"{self.env_name}: action field {f.name!r} is a {f.rep} but its "
                                 "coordinates have different bounds")

    # --- reordering ---------------------------------------------------------------
    def to_declared_observation(self, observation: np.ndarray) -> np.ndarray:
        """The env's observation in declaration order."""
        return np.asarray(observation)[..., self._obs_order]

    def to_env_action(self, action: np.ndarray) -> np.ndarray:
        """An action in declaration order, as the env takes it."""
        action = np.asarray(action)
        out = np.empty_like(action)
        out[..., self._action_order] = action
        return out

    def reset(self, **kwargs: Any) -> tuple[np.ndarray, dict[str, Any]]:
        obs, info = self.env.reset(**kwargs)
        return self.to_declared_observation(obs), info

    def step(self, action: np.ndarray) -> tuple[np.ndarray, float, bool, bool, dict[str, Any]]:
        obs, reward, terminated, truncated, info = self.env.step(self.to_env_action(action))
        return self.to_declared_observation(obs), reward, terminated, truncated, info

    # --- state access for check_symmetry ----------------------------------------------
    def simulator(self) -> DeclaredSimulator:
        """The env's simulator seen through the declaration, which ``check_symmetry`` moves
        by g; raises a one-line error when the declaration or the env does not allow it."""
        if self.declaration.state is None:
            raise ValueError(f"{self.env_name}: the declaration has no state, so check_symmetry cannot "
                             "move the simulator by g: declare how qpos and qvel transform "
                             "(state={'qpos': [...], 'qvel': [...]})")
        inner = self.env
        while isinstance(inner, gymnasium.Wrapper):
            if not isinstance(inner, BOOKKEEPING_WRAPPERS):
                raise ValueError(f"{self.env_name}: {type(inner).__name__} sits between declare() and "
                                 "the env, and check_symmetry steps the bare env, so it would check "
                                 "something else than what the agent sees: apply it outside declare()")
            inner = inner.env
        return DeclaredSimulator(self, self.env.unwrapped)


class DeclaredSimulator:
    """State access to a declared Gymnasium ``MujocoEnv``, in declaration order: get, set,
    sample and transform states, observe, simulate (what a built-in task offers
    ``check_symmetry``). Made by ``DeclaredEnv.simulator()``, which checks once that the
    env is a MuJoCo env whose qpos and qvel the declaration covers."""

    def __init__(self, wrapper: DeclaredEnv, mujoco_env: Any) -> None:
        name = wrapper.env_name
        missing = [a for a in ("model", "data", "set_state", "_get_obs", "do_simulation")
                   if not hasattr(mujoco_env, a)]
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
        saved_generator, saved_seed = self.env.np_random, self.env.np_random_seed
        try:
            self.env.reset(seed=int(rng.integers(2**31)))
            for action in self.symmetry.sample_action(rng, WARM_UP_STEPS):
                self.env.step(self._env_action(action))
        finally:
            self.env.np_random = saved_generator
            self.env._np_random_seed = saved_seed  # the setter above records -1 (unknown seed)
        return self.get_state()

    def observe(self) -> np.ndarray:
        return self.wrapper.to_declared_observation(np.asarray(self.env._get_obs(), dtype=np.float64))

    def simulate(self, action: np.ndarray) -> tuple[np.ndarray, float]:
        """One step of the bare env (no time limit), an action in ``ACTION_DOMAIN`` scaled
        to the action box: (observation in declaration order, reward)."""
        obs, reward, *_ = self.env.step(self._env_action(action))
        return self.wrapper.to_declared_observation(np.asarray(obs, dtype=np.float64)), float(reward)

    def _env_action(self, action: np.ndarray) -> np.ndarray:
        return self.wrapper.to_env_action(to_action_box(action, self.wrapper.action_space))


def declare(env: gymnasium.Env, declaration: str | Path | Mapping[str, Any] | Declaration | None = None,
            **fields: Any) -> DeclaredEnv:
    """``env`` with a symmetry declaration: a ``Declaration``, a shipped name or YAML path,
    plain data, or its keys as keyword arguments (``observation=``, ``action=``, ``state=``,
    ``dim=2``, ``continuous_group="O(2)"``, ``exact_group=``).

    >>> env = declare(gymnasium.make("Reacher-v5"), "reacher_v5")
    >>> env.symmetry.observation[0]  # Field('shoulder', 'vector', 0, 2): indices 0 and 2
    """
    if declaration is not None and fields:
        raise TypeError("declare: give a declaration or its fields as keywords, not both")
    if declaration is None:
        declaration = Declaration.from_dict({"dim": 2, "continuous_group": "O(2)", **fields})
    if symmetry_of(env) is not None:
        raise ValueError(f"{env.unwrapped} declares a symmetry already; declare() is for envs that do not")
    return DeclaredEnv(env, load_declaration(declaration))


def symmetry_of(env: gymnasium.Env) -> Symmetry | None:
    """The symmetry an env declares (a built-in task's, or a ``declare`` wrapper's), looking
    through wrappers; None if it declares none."""
    current = env
    while True:
        if isinstance(current, DeclaredEnv):
            return current.symmetry
        if not isinstance(current, gymnasium.Wrapper):
            return getattr(current, "symmetry", None)
        current = current.env


def declared_env(env: gymnasium.Env) -> DeclaredEnv | None:
    """The ``declare`` wrapper inside ``env``'s wrappers, if there is one."""
    current = env
    while isinstance(current, gymnasium.Wrapper):
        if isinstance(current, DeclaredEnv):
            return current
        current = current.env
    return None
