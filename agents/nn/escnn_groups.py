"""The agent's symmetry groups as escnn groups, and declared fields as escnn field types.

A task's declaration (``geomdp_envs.Symmetry``) names a representation of O(d)
for every slice of its observation and action vectors. Here each name becomes
the matching escnn representation of a finite subgroup G of O(d):

=================  ===========================  ===============================
declared rep       C_N / octahedral / icosah.   D_N (reflection y -> -y)
=================  ===========================  ===============================
``trivial``        trivial                      trivial
``sign``           trivial (no reflections)     irrep(1, 0): -1 on reflections
``vector``         standard (irrep(1), 3x3)     irrep(1, 1)
``pseudovector``   standard                     irrep(1, 1) (x) irrep(1, 0)
=================  ===========================  ===============================

The continuous groups SO(2), O(2) (reflection y -> -y, as D_N), SO(3) and O(3)
(reflections: the inversion -I times a rotation) follow the same table: SO(n)
like C_N, O(n) like D_N, with escnn's determinant irrep(1, 0) as ``sign``. Their
hidden fields are band-limited functions on the group (``agents/nn/spectral.py``)
instead of regular representations, and their finite checks below run on a
fixed sample of elements.

The declaration and escnn meet on matrices: ``AgentGroup.element_matrix`` gives
each escnn element as the orthogonal d x d matrix (its standard representation)
that the declaration is written for, so a declared field's matrix at that element
and escnn's representation of the field agree by construction. ``field_type``
still checks the two against each other on every element (on the fixed sample,
for continuous groups).
"""

from __future__ import annotations

import contextlib
import functools
import io
import re
from dataclasses import dataclass

import numpy as np
from escnn import group as escnn_group
from escnn import gspaces
from escnn import nn as enn

import agents.compat.escnn  # noqa: F401  (on import: escnn solves for bases with scipy's exact SVD)
from agents.nn import spectral
from geomdp_envs import groups as env_groups
from geomdp_envs.symmetry import Field, Symmetry, rep_matrix

PLANAR_GROUPS = ("C4", "C8", "C16", "D4", "D8", "D16")  # the paper's; any C<N>/D<N> works
SPATIAL_GROUPS = ("octahedral", "icosahedral")
# agent name -> (the declaration's name for it, d, default band limit L of hidden fields).
# Default grids: frequency 4L + 3 in 2D (16 angles for L = 3), 4L + 1 in 3D (for
# L = 1 the icosahedral group's 60 rotations). Measured (docs/design.md): relative
# equivariance error of a network about 1% under random elements; the 3D grid is
# the cheapest that keeps it there (SO(3) with L = 2 and an 864-point grid costs 20x
# a plain network at 0.4% error).
CONTINUOUS_GROUPS = {"SO2": ("SO(2)", 2, 3), "O2": ("O(2)", 2, 3),
                     "SO3": ("SO(3)", 3, 1), "O3": ("O(3)", 3, 1)}
_PLANAR = re.compile(r"^([CD])([1-9][0-9]*)$")


@dataclass(frozen=True)
class AgentGroup:
    """A group the agent's networks are equivariant to, as escnn builds it: a finite
    subgroup of O(2) or O(3) (C<N>, D<N>, octahedral, icosahedral) or one of the
    continuous groups SO(2), O(2), SO(3), O(3) (``continuous``: no ``order``, hidden
    fields band-limited to ``max_frequency``, nonlinearities on a quadrature grid
    exact to ``grid_frequency``)."""

    name: str
    escnn: escnn_group.Group
    dim: int
    max_frequency: int | None = None  # band limit L of hidden fields (continuous groups)
    grid_frequency: int | None = None  # exactness of the nonlinearity's quadrature grid

    @property
    def continuous(self) -> bool:
        return self.name in CONTINUOUS_GROUPS

    @property
    def order(self) -> int:
        if self.continuous:
            raise ValueError(f"{self.name} is a continuous group: it has no order")
        return self.escnn.order()

    @property
    def declared_name(self) -> str:
        """The name a task's declaration uses (geomdp_envs.groups): SO2 -> SO(2)."""
        return CONTINUOUS_GROUPS[self.name][0] if self.continuous else self.name

    @property
    def gspace(self) -> gspaces.GSpace:
        return gspaces.no_base_space(self.escnn)

    @property
    def has_reflections(self) -> bool:
        return self.name.startswith("D") or self.name in ("O2", "O3")

    @functools.cached_property
    def standard(self) -> escnn_group.Representation:
        """The representation on R^d: how positions, velocities and forces move."""
        if self.dim == 3:
            standard = self.escnn.standard_representation  # a method on SO(3)/O(3)
            return standard if isinstance(standard, escnn_group.Representation) else standard()
        if self.name == "D1":  # one reflection (y -> -y): R^2 splits into x (fixed) and y (sign)
            return escnn_group.directsum([self.trivial, self.escnn.irrep(1, 0)], name="D1_standard")
        return self.escnn.irrep(1, 1) if self.has_reflections else self.escnn.irrep(1)

    @functools.cached_property
    def regular(self) -> escnn_group.Representation:
        """A hidden field: the regular representation, or for a continuous group the
        functions on it with frequencies <= ``max_frequency``."""
        if self.continuous:
            return spectral.band_limited_regular(self.escnn, self.max_frequency)
        return self.escnn.regular_representation

    @property
    def field_size(self) -> int:
        """Size of one hidden field: |G|, or the band-limited field's number of coefficients."""
        return self.regular.size

    @functools.cached_property
    def quadrature(self) -> spectral.Quadrature | None:
        """The grid a continuous group's hidden nonlinearities sample (None if finite)."""
        if not self.continuous:
            return None
        return spectral.quadrature(self.escnn, self.name, self.grid_frequency)

    @property
    def trivial(self) -> escnn_group.Representation:
        return self.escnn.trivial_representation

    def representation(self, rep: str) -> escnn_group.Representation:
        """The escnn representation of a declared representation name."""
        sign = self.escnn.irrep(1, 0) if self.has_reflections else self.trivial
        if rep == "trivial":
            return self.trivial
        if rep == "sign":
            return sign
        if rep == "vector":
            return self.standard
        if rep == "pseudovector":
            return self.standard.tensor(sign) if self.has_reflections else self.standard
        raise ValueError(f"unknown representation {rep!r}")

    def elements(self) -> list:
        """All elements; for a continuous group a fixed sample of 16 (Haar measure)."""
        if not self.continuous:
            return list(self.escnn.elements)
        matrices = env_groups.sample(self.declared_name, np.random.default_rng(0), 16)
        return [self.element(m) for m in matrices]

    def element(self, matrix: np.ndarray) -> object:
        """The escnn element of an orthogonal d x d matrix of a continuous group."""
        m = env_groups.as_orthogonal(matrix, self.dim)
        reflected = np.linalg.det(m) < 0
        if reflected and not self.has_reflections:
            raise ValueError(f"{self.name} has no reflections; got det = -1")
        if self.name == "SO2":
            return self.escnn.element(float(np.arctan2(m[1, 0], m[0, 0])))
        if self.name == "O2":
            rotation = m @ np.diag([1.0, -1.0]) if reflected else m
            return self.escnn.element((int(reflected), float(np.arctan2(rotation[1, 0],
                                                                        rotation[0, 0]))))
        if self.name == "SO3":
            return self.escnn.element(m, param="MAT")
        if self.name == "O3":
            return self.escnn.element((int(reflected), -m if reflected else m), param="MAT")
        raise ValueError(f"{self.name} is finite: use elements()")

    def element_matrix(self, element: object) -> np.ndarray:
        """The element as an orthogonal d x d matrix (its standard representation)."""
        return np.asarray(self.standard(element), dtype=np.float64)


@functools.cache
def make_group(name: str, max_frequency: int | None = None,
               grid_frequency: int | None = None) -> AgentGroup:
    """The escnn group called ``name``: C<N>, D<N>, octahedral, icosahedral, or a
    continuous SO2, O2, SO3, O3 with hidden fields band-limited to ``max_frequency``
    and nonlinearities sampled on a grid exact to ``grid_frequency`` (defaults:
    ``CONTINUOUS_GROUPS``)."""
    if name in CONTINUOUS_GROUPS:
        return _continuous_group(name, max_frequency, grid_frequency)
    if max_frequency is not None or grid_frequency is not None:
        raise ValueError(f"max_frequency and grid_frequency apply to the continuous groups "
                         f"({', '.join(CONTINUOUS_GROUPS)}), not to {name}; leave them null")
    match = _PLANAR.match(name)
    if match:
        n = int(match.group(2))
        if n < (1 if match.group(1) == "D" else 2):
            raise ValueError(f"group {name}: N must be at least {1 if match.group(1) == 'D' else 2} "
                             "(D1 is the one reflection, C1 the trivial group)")
        g = escnn_group.cyclic_group(n) if match.group(1) == "C" else escnn_group.dihedral_group(n)
        return AgentGroup(name, g, 2)
    spatial = {"octahedral": escnn_group.octa_group, "icosahedral": escnn_group.ico_group}
    if name in spatial:
        # escnn caches these groups' irreps with joblib, which reports on stdout.
        with contextlib.redirect_stdout(io.StringIO()):
            group = spatial[name]()
            group.standard_representation  # noqa: B018  (built and cached here, silently)
        return AgentGroup(name, group, 3)
    raise ValueError(f"unknown group {name!r}; valid groups: "
                     f"{', '.join(PLANAR_GROUPS + SPATIAL_GROUPS + tuple(CONTINUOUS_GROUPS))} "
                     "(or any C<N>, D<N>)")


def _continuous_group(name: str, max_frequency: int | None,
                      grid_frequency: int | None) -> AgentGroup:
    _, dim, default_frequency = CONTINUOUS_GROUPS[name]
    max_frequency = default_frequency if max_frequency is None else max_frequency
    if max_frequency < 1:
        raise ValueError(f"max_frequency must be >= 1 (a vector needs frequency 1), "
                         f"got {max_frequency}")
    if grid_frequency is None:
        grid_frequency = 4 * max_frequency + (3 if dim == 2 else 1)
    if grid_frequency < 2 * max_frequency:
        raise ValueError(f"grid_frequency must be >= 2 * max_frequency = {2 * max_frequency} "
                         f"(the grid must integrate products of two fields), got {grid_frequency}")
    constructors = {"SO2": escnn_group.so2_group, "O2": escnn_group.o2_group,
                    "SO3": escnn_group.so3_group, "O3": escnn_group.o3_group}
    # escnn builds intertwiner bases from tensor products of irreps, and must have
    # instantiated every irrep they decompose into (up to twice the band limit, plus
    # the vectors' frequency 1); it reports solving them on stdout.
    with contextlib.redirect_stdout(io.StringIO()):
        group = constructors[name](maximum_frequency=2 * max_frequency + 2)
        for irrep_id in group.bl_irreps(2 * max_frequency + 2):
            group.irrep(*irrep_id)
    return AgentGroup(name, group, dim, max_frequency, grid_frequency)


GROUP_NAMES = "C<N>, D<N> (N >= 1), SO2, O2 (planar); octahedral, icosahedral, SO3, O3 (3D)"


def is_group_name(name: str) -> bool:
    """Whether ``name`` is a group the agent can build (for some task)."""
    return name in CONTINUOUS_GROUPS or bool(_PLANAR.match(name)) or name in SPATIAL_GROUPS


def valid_groups(symmetry: Symmetry) -> tuple[str, ...]:
    """The named groups that act on a task with this declaration."""
    named = PLANAR_GROUPS if symmetry.dim == 2 else SPATIAL_GROUPS
    continuous = tuple(name for name, (declared, dim, *_) in CONTINUOUS_GROUPS.items()
                       if dim == symmetry.dim
                       and env_groups.is_subgroup(declared, symmetry.continuous_group))
    return named + continuous


def group_for_task(name: str, symmetry: Symmetry, max_frequency: int | None = None,
                   grid_frequency: int | None = None, allow_approximate: bool = True,
                   task: str = "this task") -> tuple[AgentGroup, bool]:
    """The group ``name`` for a task, and whether it is an exact symmetry of it.

    Raises a ValueError listing the valid groups when ``name`` is unknown or does
    not act on the task (a planar group for a 3D task, or the reverse), and one
    for a continuous group that is only an approximate symmetry of ``task``
    unless ``allow_approximate``.
    """
    valid = ", ".join(valid_groups(symmetry))
    if not is_group_name(name):
        raise ValueError(f"unknown group {name!r}; valid groups for this {symmetry.dim}D task: "
                         f"{valid}")
    group = make_group(name, max_frequency, grid_frequency)
    if group.dim != symmetry.dim:
        raise ValueError(f"group {name} acts in {group.dim}D but the task is {symmetry.dim}D; "
                         f"valid groups for this task: {valid}")
    if group.continuous:
        inside = env_groups.is_subgroup(group.declared_name, symmetry.continuous_group)
        exact = env_groups.is_subgroup(group.declared_name, symmetry.exact_group)
    else:
        matrices = [group.element_matrix(e) for e in group.elements()]
        inside = all(env_groups.contains(symmetry.continuous_group, m) for m in matrices)
        exact = all(env_groups.contains(symmetry.exact_group, m) for m in matrices)
    if not inside:
        raise ValueError(f"group {name} is not a subgroup of the task's "
                         f"{symmetry.continuous_group}; valid groups: {valid}")
    if group.continuous and not exact and not allow_approximate:
        raise ValueError(f"{name} is only an approximate symmetry of {task} (exact group: "
                         f"{symmetry.exact_group}); set agent.allow_approximate=true to train "
                         "with it anyway")
    return group, exact


def field_type(group: AgentGroup, fields: tuple[Field, ...]) -> enn.FieldType:
    """escnn field type of declared fields, in their order, checked on every element."""
    reps = [group.representation(f.rep) for f in fields]
    for element in group.elements():
        g = group.element_matrix(element)
        for f, rep in zip(fields, reps):
            if not np.allclose(rep(element), rep_matrix(f.rep, g), atol=1e-6):
                raise AssertionError(f"escnn's {rep.name} disagrees with the declared "
                                     f"{f.rep} of field {f.name!r} at {element}")
    return enn.FieldType(group.gspace, reps)
