"""A symmetry declaration as data: which indices of an env's observation and action
vectors hold which field (``IndexedField``), how each transforms, and, to be checked
against a MuJoCo simulator, how ``qpos`` and ``qvel`` move. Parsed from plain data or
YAML (``load_declaration("reacher_v5")`` reads a shipped one, or give a path), checked
on construction; ``geomdp_envs.declare`` attaches one to an env."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from importlib import resources
from pathlib import Path
from typing import Any

import numpy as np
import yaml

from geomdp_envs import groups
from geomdp_envs.symmetry import (
    REPRESENTATIONS,
    Symmetry,
    check_groups,
    layout,
    rep_matrix,
    rep_size,
)

# A planar orientation angle phi (an absolute hinge about the plane's normal): g moves
# it to the angle of g (cos phi, sin phi). Only the state has these; observations show
# an angle as a vector (cos, sin) or not at all.
STATE_REPRESENTATIONS = REPRESENTATIONS + ("angle",)
STATE_VECTORS = ("qpos", "qvel")
SHIPPED = resources.files("geomdp_envs") / "declarations"
# The keys every declaration states (none has a default), with their valid values.
REQUIRED_KEYS = {
    "dim": "valid: 2, 3",
    "continuous_group": f"valid: {', '.join(groups.CONTINUOUS_GROUPS)}",
    "exact_group": "the subgroup of continuous_group the env is exactly symmetric under, C1 if "
                   f"none; valid: {groups.VALID_GROUP_NAMES}",
    "observation": "a list of fields {name, rep, index}",
    "action": "a list of fields {name, rep, index}",
}
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
        """From plain data (as YAML holds it); unknown and missing keys are errors (only
        ``state`` and ``notes`` may be left out)."""
        data = dict(data)
        allowed = {"dim", "continuous_group", "exact_group", "observation", "action", "state", "notes"}
        unknown = set(data) - allowed
        if unknown:
            raise ValueError(f"declaration: unknown key(s) {sorted(unknown)}; "
                             f"valid: {', '.join(sorted(allowed))}")
        missing = [k for k in REQUIRED_KEYS if k not in data]
        if missing:
            raise ValueError(f"declaration: missing key{'s' if len(missing) > 1 else ''} "
                             + ", ".join(f"{k!r} ({REQUIRED_KEYS[k]})" for k in missing))
        return cls(dim=data["dim"], continuous_group=data["continuous_group"],
                   exact_group=data["exact_group"],
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
