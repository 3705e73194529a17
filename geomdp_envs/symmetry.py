"""The symmetry declaration of a Geometric MDP, as plain data.

A declaration says, for every slice ("field") of the observation and of the
action vector, which representation of O(d) it transforms under. Four are
enough for the tasks here and for most robotics features:

==============  ===================  ==========================================
rep             rho(g)               examples
==============  ===================  ==========================================
``trivial``     1                    distances, cos of a relative joint angle
``sign``        det(g)               joint angles/velocities/torques about the
                                     plane's normal (planar pseudo-scalars); a
                                     raw absolute angle under D1 (y -> -y) only
``vector``      g                    positions, velocities, forces
``pseudovector`` det(g) g            angular velocity and torque in 3D
==============  ===================  ==========================================

Nothing here needs escnn or torch: a third party can read the fields, build
rho_S(g) and rho_A(g) as numpy matrices for any orthogonal g, and check or
exploit the symmetry with any tool. The group-equivariant networks of the
``agents`` package are built from the same data.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, field
from typing import Any

import numpy as np

from geomdp_envs import groups

REPRESENTATIONS = ("trivial", "sign", "vector", "pseudovector")

ACTION_DOMAIN = (
    "every vector/pseudovector action field in the closed unit ball, "
    "every scalar action field in [-1, 1]"
)


def to_action_box(action: np.ndarray, space: Any) -> np.ndarray:
    """An action of the unit domain [-1, 1] mapped affinely onto a Box action space's
    bounds (for signed fields, whose bounds are symmetric about 0, that is a scaling
    and commutes with the group)."""
    low, high = np.asarray(space.low, dtype=np.float64), np.asarray(space.high, dtype=np.float64)
    return (low + high) / 2 + np.asarray(action) * (high - low) / 2


def rep_size(rep: str, dim: int) -> int:
    """Number of coordinates a field of representation ``rep`` occupies."""
    if rep not in REPRESENTATIONS:
        raise ValueError(f"unknown representation {rep!r}; valid: {', '.join(REPRESENTATIONS)}")
    return dim if rep in ("vector", "pseudovector") else 1


def rep_matrix(rep: str, g: np.ndarray) -> np.ndarray:
    """rho(g) for one field, given g as an orthogonal d x d matrix."""
    det = np.linalg.det(g)
    return {
        "trivial": np.ones((1, 1)),
        "sign": np.full((1, 1), np.sign(det)),
        "vector": g,
        "pseudovector": np.sign(det) * g,
    }[rep]


@dataclass(frozen=True)
class Field:
    """A contiguous slice ``[start, stop)`` of a vector that transforms under ``rep``.

    ``particle`` names which of several interchangeable bodies the field belongs
    to (None: the field is not part of a permutation symmetry).
    """

    name: str
    rep: str
    start: int
    stop: int
    particle: int | None = None

    @property
    def size(self) -> int:
        return self.stop - self.start

    @property
    def label(self) -> str:
        """The name, with the particle index where there is one: ``position[2]``."""
        return self.name if self.particle is None else f"{self.name}[{self.particle}]"


def layout(dim: int, entries: list[tuple[str, str] | tuple[str, str, int]]) -> tuple[Field, ...]:
    """Fields laid out one after another from ``(name, rep[, particle])`` entries."""
    fields, start = [], 0
    for entry in entries:
        name, rep = entry[0], entry[1]
        particle = entry[2] if len(entry) > 2 else None
        stop = start + rep_size(rep, dim)
        fields.append(Field(name, rep, start, stop, particle))
        start = stop
    return tuple(fields)


def _block_matrix(fields: tuple[Field, ...], size: int, g: np.ndarray) -> np.ndarray:
    out = np.zeros((size, size))
    for f in fields:
        out[f.start : f.stop, f.start : f.stop] = rep_matrix(f.rep, g)
    return out


def _permutation_matrix(fields: tuple[Field, ...], size: int, perm: np.ndarray) -> np.ndarray:
    """Matrix moving the fields of particle i to the slots of particle perm[i]."""
    slot = {(f.name, f.particle): f for f in fields}
    out = np.zeros((size, size))
    for f in fields:
        target = f if f.particle is None else slot[(f.name, int(perm[f.particle]))]
        out[target.start : target.stop, f.start : f.stop] = np.eye(f.size)
    return out


def check_groups(dim: int, continuous_group: str, exact_group: str) -> None:
    """Both groups act on R^dim and the exact one lies in the continuous one."""
    for group in (continuous_group, exact_group):
        if groups.group_dim(group) != dim:
            raise ValueError(f"group {group!r} does not act on R^{dim}")
    if not groups.is_subgroup(exact_group, continuous_group):
        raise ValueError(f"{exact_group} is not a subgroup of {continuous_group}")


@dataclass(frozen=True)
class Symmetry:
    """How a group of rotations/reflections acts on a task's observations and actions.

    ``continuous_group`` is O(d) or SO(d), the group the declaration is written
    for; ``exact_group`` is the subgroup under which the task is exactly
    symmetric (smaller when walls or joint limits break the continuous group).
    The symmetry holds for actions in ``ACTION_DOMAIN``: a box [-1, 1]^d is only
    closed under signed permutations, so a rotated action may leave it.
    """

    dim: int
    continuous_group: str
    exact_group: str
    observation: tuple[Field, ...]
    action: tuple[Field, ...]
    n_particles: int = 1
    notes: str = ""
    action_domain: str = field(default=ACTION_DOMAIN)

    def __post_init__(self) -> None:
        check_groups(self.dim, self.continuous_group, self.exact_group)
        for kind, fields in (("observation", self.observation), ("action", self.action)):
            start = 0
            for f in fields:
                if f.start != start or f.size != rep_size(f.rep, self.dim):
                    raise ValueError(f"{kind} field {f.name!r} at [{f.start}, {f.stop}) does not "
                                     f"continue the layout at {start} with a {f.rep} of R^{self.dim}")
                if f.particle is not None and not 0 <= f.particle < self.n_particles:
                    raise ValueError(f"{kind} field {f.name!r} names particle {f.particle}, "
                                     f"valid: 0..{self.n_particles - 1}")
                start = f.stop

    @property
    def observation_size(self) -> int:
        return self.observation[-1].stop

    @property
    def action_size(self) -> int:
        return self.action[-1].stop

    # --- the group action -------------------------------------------------
    def observation_matrix(self, g: np.ndarray) -> np.ndarray:
        """rho_S(g), the observation_size x observation_size matrix of g."""
        g = groups.as_orthogonal(g, self.dim)
        return _block_matrix(self.observation, self.observation_size, g)

    def action_matrix(self, g: np.ndarray) -> np.ndarray:
        """rho_A(g), the action_size x action_size matrix of g."""
        g = groups.as_orthogonal(g, self.dim)
        return _block_matrix(self.action, self.action_size, g)

    def transform_observation(self, obs: Any, g: np.ndarray) -> Any:
        """g . obs for one observation or a batch [..., observation_size]."""
        return _apply(self.observation_matrix(g), obs, self.observation_size, "observation")

    def transform_action(self, action: Any, g: np.ndarray) -> Any:
        """g . action for one action or a batch [..., action_size]."""
        return _apply(self.action_matrix(g), action, self.action_size, "action")

    def observation_permutation_matrix(self, perm: np.ndarray) -> np.ndarray:
        """Matrix relabelling particle i as particle perm[i] in an observation."""
        return _permutation_matrix(self.observation, self.observation_size,
                                   self._check_perm(perm))

    def action_permutation_matrix(self, perm: np.ndarray) -> np.ndarray:
        """Matrix relabelling particle i as particle perm[i] in an action."""
        return _permutation_matrix(self.action, self.action_size, self._check_perm(perm))

    def _check_perm(self, perm: np.ndarray) -> np.ndarray:
        perm = np.asarray(perm)
        if sorted(perm.tolist()) != list(range(self.n_particles)):
            raise ValueError(f"{perm.tolist()} is not a permutation of {self.n_particles} particles")
        return perm

    # --- the set of actions on which the symmetry is exact ------------------
    def action_in_domain(self, action: np.ndarray, atol: float = 1e-6) -> np.ndarray:
        """Whether each action (shape [..., action_size]) lies in ``ACTION_DOMAIN``."""
        action = np.asarray(action)
        ok = np.ones(action.shape[:-1], dtype=bool)
        for f in self.action:
            ok &= np.linalg.norm(action[..., f.start : f.stop], axis=-1) <= 1 + atol
        return ok

    def sample_action(self, rng: np.random.Generator, n: int | None = None) -> np.ndarray:
        """Actions drawn uniformly from ``ACTION_DOMAIN`` (unit ball per vector field)."""
        shape = (1 if n is None else n,)
        out = np.empty(shape + (self.action_size,))
        for f in self.action:
            direction = rng.normal(size=shape + (f.size,))
            direction /= np.linalg.norm(direction, axis=-1, keepdims=True)
            radius = rng.uniform(size=shape + (1,)) ** (1.0 / f.size)
            out[..., f.start : f.stop] = direction * radius
        return out[0] if n is None else out

    # --- plain data -------------------------------------------------------
    def to_dict(self) -> dict[str, Any]:
        """JSON-ready plain data (lists, strings and numbers)."""
        return asdict(self)

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> Symmetry:
        data = dict(data)
        for kind in ("observation", "action"):
            data[kind] = tuple(Field(**f) for f in data[kind])
        return cls(**data)

    def replace_field(self, kind: str, name: str, rep: str) -> Symmetry:
        """A copy with one field re-declared (for testing declarations)."""
        fields = tuple(
            Field(f.name, rep, f.start, f.stop, f.particle) if f.name == name else f
            for f in getattr(self, kind)
        )
        if fields == getattr(self, kind):
            raise ValueError(f"no {kind} field named {name!r}")
        data = self.to_dict()
        data[kind] = [asdict(f) for f in fields]
        return Symmetry.from_dict(data)

    def describe(self) -> str:
        """A markdown table of the fields, for READMEs and logs."""
        rows = [f"exact group: {self.exact_group} (of {self.continuous_group})", "",
                "| vector | slice | field | representation |", "|---|---|---|---|"]
        for kind, fields in (("observation", self.observation), ("action", self.action)):
            rows += [f"| {kind} | [{f.start}:{f.stop}] | {f.label} | {f.rep} |" for f in fields]
        return "\n".join(rows)


def as_float(x: Any) -> Any:
    """x as a floating-point numpy array or torch tensor: float inputs keep their
    dtype, integers (and bools, lists) become float64. A rotated integer vector
    is not an integer vector, so casting the result back would truncate it."""
    if not hasattr(x, "shape"):
        return np.asarray(x, dtype=np.float64)
    if isinstance(x, np.ndarray):
        return x if np.issubdtype(x.dtype, np.inexact) else x.astype(np.float64)
    import torch  # only for torch inputs; the declaration itself never needs torch

    return x if x.is_floating_point() or x.is_complex() else x.to(torch.float64)


def _apply(matrix: np.ndarray, x: Any, size: int, kind: str) -> Any:
    """x @ matrix.T for numpy arrays or torch tensors of shape [..., size]."""
    x = as_float(x)
    if x.ndim == 0 or x.shape[-1] != size:
        last = "no last dimension" if x.ndim == 0 else f"last dimension {x.shape[-1]}"
        raise ValueError(f"{kind} has {last}, expected {size}")
    if isinstance(x, np.ndarray):
        return (x @ matrix.T).astype(x.dtype, copy=False)
    import torch

    m = torch.as_tensor(matrix, dtype=x.dtype, device=x.device)
    return x @ m.T
