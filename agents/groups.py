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

and ``AgentGroup.element_matrix`` gives each escnn element as the orthogonal
d x d matrix the declaration is written for, so the two agree by construction;
``field_type`` checks it on every element anyway.
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

from geomdp_envs import groups as env_groups
from geomdp_envs.symmetry import Field, Symmetry, rep_matrix

PLANAR_GROUPS = ("C4", "C8", "C16", "D4", "D8", "D16")  # the paper's; any C<N>/D<N> works
SPATIAL_GROUPS = ("octahedral", "icosahedral")
_PLANAR = re.compile(r"^([CD])([1-9][0-9]*)$")


@dataclass(frozen=True)
class AgentGroup:
    """A finite group the agent's networks are equivariant to."""

    name: str
    escnn: escnn_group.Group
    dim: int

    @property
    def order(self) -> int:
        return self.escnn.order()

    @property
    def gspace(self) -> gspaces.GSpace:
        return gspaces.no_base_space(self.escnn)

    @property
    def has_reflections(self) -> bool:
        return self.name.startswith("D")

    @property
    def standard(self) -> escnn_group.Representation:
        """The representation on R^d: how positions, velocities and forces move."""
        if self.dim == 3:
            return self.escnn.standard_representation
        return self.escnn.irrep(1, 1) if self.has_reflections else self.escnn.irrep(1)

    @property
    def regular(self) -> escnn_group.Representation:
        return self.escnn.regular_representation

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
        return list(self.escnn.elements)

    def element_matrix(self, element: object) -> np.ndarray:
        """The element as an orthogonal d x d matrix (its standard representation)."""
        return np.asarray(self.standard(element), dtype=np.float64)


@functools.cache
def make_group(name: str) -> AgentGroup:
    """The escnn group called ``name``: C<N>, D<N>, octahedral or icosahedral."""
    match = _PLANAR.match(name)
    if match:
        n = int(match.group(2))
        if n < 2:
            raise ValueError(f"group {name}: N must be at least 2")
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
                     f"{', '.join(PLANAR_GROUPS + SPATIAL_GROUPS)} (or any C<N>, D<N>)")


def valid_groups(symmetry: Symmetry) -> tuple[str, ...]:
    """The named groups that act on a task with this declaration."""
    return PLANAR_GROUPS if symmetry.dim == 2 else SPATIAL_GROUPS


def group_for_task(name: str, symmetry: Symmetry) -> tuple[AgentGroup, bool]:
    """The group ``name`` for a task, and whether it is an exact symmetry of it.

    Raises a ValueError listing the valid groups when ``name`` is unknown or does
    not act on the task (a planar group for a 3D task, or the reverse).
    """
    valid = ", ".join(valid_groups(symmetry))
    try:
        group = make_group(name)
    except ValueError:
        raise ValueError(f"unknown group {name!r}; valid groups for this {symmetry.dim}D task: "
                         f"{valid}") from None
    if group.dim != symmetry.dim:
        raise ValueError(f"group {name} acts in {group.dim}D but the task is {symmetry.dim}D; "
                         f"valid groups for this task: {valid}")
    matrices = [group.element_matrix(e) for e in group.elements()]
    if not all(env_groups.contains(symmetry.continuous_group, m) for m in matrices):
        raise ValueError(f"group {name} is not a subgroup of the task's "
                         f"{symmetry.continuous_group}; valid groups: {valid}")
    exact = all(env_groups.contains(symmetry.exact_group, m) for m in matrices)
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
