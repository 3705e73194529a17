"""Groups of rotations and reflections as plain numpy matrices.

Every group here is a subgroup of O(d) (d = 2 or 3) and every element is an
orthogonal d x d matrix, so a declaration written for O(d) can be evaluated on
any element without a group library. Names:

* planar: ``O(2)``, ``SO(2)``, ``C<N>`` (rotations by 2*pi*k/N), ``D<N>`` (``C<N>``
  plus the reflection y -> -y, ``diag(1, -1)``, the convention escnn uses, and its
  products with the rotations: the reflections across the lines at angles pi*k/N).
  So ``D1`` is {I, y -> -y}, and x -> -x lies in ``D<N>`` for even N only. ``sign``
  fields see only det g = -1, the same for every reflection; the axis matters for
  ``vector`` fields;
* spatial: ``O(3)``, ``SO(3)``, ``octahedral`` (the cube's 24 rotations),
  ``full_octahedral`` (48, all signed permutations), ``icosahedral`` (60
  rotations), ``full_icosahedral`` (120, with the inversion -I).
"""

from __future__ import annotations

import functools
import re

import numpy as np
from scipy.stats import ortho_group, special_ortho_group

CONTINUOUS_GROUPS = {"O(2)": 2, "SO(2)": 2, "O(3)": 3, "SO(3)": 3}
SPATIAL_FINITE_GROUPS = ("octahedral", "full_octahedral", "icosahedral", "full_icosahedral")
_PLANAR_FINITE = re.compile(r"^([CD])([1-9][0-9]*)$")

VALID_GROUP_NAMES = (
    "O(2), SO(2), C<N>, D<N> (planar); O(3), SO(3), " + ", ".join(SPATIAL_FINITE_GROUPS)
)


def _unknown(name: str) -> ValueError:
    return ValueError(f"unknown group {name!r}; valid groups: {VALID_GROUP_NAMES}")


def group_dim(name: str) -> int:
    """The d of the d x d matrices the group ``name`` is made of."""
    if name in CONTINUOUS_GROUPS:
        return CONTINUOUS_GROUPS[name]
    if name in SPATIAL_FINITE_GROUPS:
        return 3
    if _PLANAR_FINITE.match(name):
        return 2
    raise _unknown(name)


def is_finite(name: str) -> bool:
    group_dim(name)  # validates the name
    return name not in CONTINUOUS_GROUPS


def rotation_2d(angle: float) -> np.ndarray:
    """Counter-clockwise rotation of the plane by ``angle`` radians."""
    c, s = np.cos(angle), np.sin(angle)
    return np.array([[c, -s], [s, c]])


def rotation_3d(axis: np.ndarray, angle: float) -> np.ndarray:
    """Rotation by ``angle`` about ``axis`` (Rodrigues' formula)."""
    axis = np.asarray(axis, dtype=float)
    axis = axis / np.linalg.norm(axis)
    k = np.array([[0, -axis[2], axis[1]], [axis[2], 0, -axis[0]], [-axis[1], axis[0], 0]])
    return np.eye(3) + np.sin(angle) * k + (1 - np.cos(angle)) * (k @ k)


def _closure(generators: list[np.ndarray]) -> np.ndarray:
    """All products of ``generators``: the finite group they generate."""
    d = generators[0].shape[0]

    def key(m: np.ndarray) -> bytes:
        return (np.round(m, 8) + 0.0).tobytes()  # + 0.0 turns -0.0 into 0.0

    elements = {key(np.eye(d)): np.eye(d)}
    frontier = [np.eye(d)]
    while frontier:
        new = []
        for a in frontier:
            for b in generators:
                c = a @ b
                if key(c) not in elements:
                    elements[key(c)] = c
                    new.append(c)
        frontier = new
        if len(elements) > 1000:
            raise RuntimeError("generators do not generate a small finite group")
    return np.stack(list(elements.values()))


@functools.cache
def _finite_elements(name: str) -> np.ndarray:
    match = _PLANAR_FINITE.match(name)
    if match:
        kind, n = match.group(1), int(match.group(2))
        rotations = [rotation_2d(2 * np.pi * k / n) for k in range(n)]
        if kind == "C":
            return np.stack(rotations)
        flip = np.diag([1.0, -1.0])
        return np.stack(rotations + [r @ flip for r in rotations])
    if name in ("octahedral", "full_octahedral"):
        quarter_z = rotation_3d([0, 0, 1], np.pi / 2)
        cycle_axes = np.array([[0.0, 0, 1], [1, 0, 0], [0, 1, 0]])  # x -> y -> z -> x
        gens = [quarter_z, cycle_axes]
    elif name in ("icosahedral", "full_icosahedral"):
        phi = (1 + np.sqrt(5)) / 2
        # The icosahedron with vertices (0, +-1, +-phi) and cyclic permutations:
        # (0, 1, phi) is a 5-fold axis, the coordinate axes are 2-fold axes.
        gens = [rotation_3d([0, 1, phi], 2 * np.pi / 5), rotation_3d([0, 0, 1], np.pi)]
    else:
        raise _unknown(name)
    if name.startswith("full_"):
        gens.append(-np.eye(3))
    return _closure(gens)


def group_elements(name: str) -> np.ndarray:
    """All elements of a finite group, shape [|G|, d, d]."""
    if not is_finite(name):
        raise ValueError(f"group {name!r} is continuous; it has no finite list of elements")
    return _finite_elements(name).copy()


def as_orthogonal(g: np.ndarray, dim: int, atol: float = 1e-6) -> np.ndarray:
    """``g`` as a float64 d x d orthogonal matrix, or a clear error."""
    g = np.asarray(g, dtype=np.float64)
    if g.shape != (dim, dim):
        raise ValueError(f"group element must be a {dim}x{dim} matrix, got shape {g.shape}")
    if not np.allclose(g @ g.T, np.eye(dim), atol=atol):
        raise ValueError("group element must be orthogonal (g @ g.T == I): got " + str(g.tolist()))
    return g


def contains(name: str, g: np.ndarray, atol: float = 1e-6) -> bool:
    """Whether the orthogonal matrix ``g`` belongs to the group ``name``."""
    g = as_orthogonal(g, group_dim(name), atol)
    if name.startswith("SO("):
        return bool(np.linalg.det(g) > 0)
    if name.startswith("O("):
        return True
    return bool(np.any(np.all(np.abs(group_elements(name) - g) < atol, axis=(1, 2))))


def sample(name: str, rng: np.random.Generator, n: int) -> np.ndarray:
    """``n`` elements drawn uniformly (Haar measure) from the group, shape [n, d, d]."""
    d = group_dim(name)
    if is_finite(name):
        elements = _finite_elements(name)
        return elements[rng.integers(len(elements), size=n)].copy()
    seed = int(rng.integers(2**31))
    if name.startswith("SO("):
        out = special_ortho_group.rvs(d, size=n, random_state=seed)
    else:
        out = ortho_group.rvs(d, size=n, random_state=seed)
    return np.asarray(out).reshape(n, d, d)


def is_subgroup(sub: str, group: str) -> bool:
    """Whether every element of ``sub`` belongs to ``group`` (same d required)."""
    if group_dim(sub) != group_dim(group):
        return False
    if not is_finite(sub):
        return sub == group or (sub.startswith("SO(") and group.startswith("O("))
    return all(contains(group, g) for g in _finite_elements(sub))
