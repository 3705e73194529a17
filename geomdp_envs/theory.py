"""How much a declared symmetry shrinks a task, computed from the declaration alone.

* ``hom_dimension``: dim Hom_G(rho_in, rho_out), the free parameters of a
  G-equivariant linear map, e.g. the linearised dynamics A (rho_S -> rho_S),
  B (rho_A -> rho_S), the LQR gain K (rho_S -> rho_A), and (symmetric maps)
  the LQR value matrix P. Computed as the null space of the constraints
  rho_out(g) X = X rho_in(g) over generating elements (for a continuous group,
  a few Haar-random elements generate a dense subgroup, which imposes the same
  linear constraints), and for finite groups cross-checked by the character
  inner product (1/|G|) sum_g chi_in(g) chi_out(g).
* ``orbit_dimension``: the dimension of the orbit of a generic point of
  S x A, i.e. the rank of the Lie algebra's action there (0 for finite groups);
  the quotient S x A / G has dimension dim(S x A) minus that.
"""

from __future__ import annotations

import itertools

import numpy as np
import scipy.linalg

from geomdp_envs import groups
from geomdp_envs.symmetry import Field, Symmetry, rep_matrix


def block_matrix(fields: tuple[Field, ...], g: np.ndarray) -> np.ndarray:
    """rho(g) for a list of fields (observation, action, or both concatenated)."""
    return scipy.linalg.block_diag(*[rep_matrix(f.rep, g) for f in fields])


def _generators(group: str, rng: np.random.Generator) -> np.ndarray:
    if groups.is_finite(group):
        return groups.group_elements(group)
    return groups.sample(group, rng, 6)


def hom_dimension(group: str, fields_in: tuple[Field, ...], fields_out: tuple[Field, ...],
                  symmetric: bool = False, seed: int = 0) -> int:
    """dim of {X : rho_out(g) X = X rho_in(g) for all g in G} (and X = X^T if ``symmetric``)."""
    elements = _generators(group, np.random.default_rng(seed))
    n_in = sum(f.size for f in fields_in)
    n_out = sum(f.size for f in fields_out)
    rows = []
    for g in elements:
        r_in, r_out = block_matrix(fields_in, g), block_matrix(fields_out, g)
        # vec(r_out X - X r_in) = (I (x) r_out - r_in^T (x) I) vec(X), column-major vec
        rows.append(np.kron(np.eye(n_in), r_out) - np.kron(r_in.T, np.eye(n_out)))
    if symmetric:
        if n_in != n_out:
            raise ValueError("a symmetric map needs the same input and output")
        transpose = np.zeros((n_in * n_in, n_in * n_in))
        for i, j in itertools.product(range(n_in), repeat=2):
            transpose[i * n_in + j, j * n_in + i] = 1
        rows.append(np.eye(n_in * n_in) - transpose)
    constraints = np.concatenate(rows)
    singular = np.linalg.svd(constraints, compute_uv=False)
    return int(n_in * n_out - np.sum(singular > 1e-8 * max(1.0, singular.max())))


def character_hom_dimension(group: str, fields_in: tuple[Field, ...],
                            fields_out: tuple[Field, ...]) -> int:
    """dim Hom_G by characters: (1/|G|) sum_g chi_in(g) chi_out(g) (finite, real reps)."""
    elements = groups.group_elements(group)
    total = sum(np.trace(block_matrix(fields_in, g)) * np.trace(block_matrix(fields_out, g))
                for g in elements)
    return int(round(total / len(elements)))


def _lie_algebra(dim: int) -> list[np.ndarray]:
    """A basis of so(d): the generators of rotations."""
    basis = []
    for i, j in itertools.combinations(range(dim), 2):
        xi = np.zeros((dim, dim))
        xi[i, j], xi[j, i] = -1.0, 1.0
        basis.append(xi)
    return basis


def orbit_dimension(group: str, fields: tuple[Field, ...], seed: int = 0) -> int:
    """Dimension of the orbit of a generic point (0 for a finite group)."""
    if groups.is_finite(group):
        return 0
    dim = groups.group_dim(group)
    x = np.random.default_rng(seed).normal(size=sum(f.size for f in fields))
    tangents = []
    for xi in _lie_algebra(dim):
        # d/dt rho(exp(t xi)) at t = 0: xi on (pseudo)vectors, 0 on scalars
        d_rho = scipy.linalg.block_diag(*[xi if f.size > 1 else np.zeros((1, 1)) for f in fields])
        tangents.append(d_rho @ x)
    return int(np.linalg.matrix_rank(np.stack(tangents), tol=1e-9))


def dimension_table(symmetry: Symmetry, group: str) -> dict[str, int]:
    """The reduction numbers of one task under one group."""
    s, a = symmetry.observation, symmetry.action
    both = s + tuple(Field(f.name, f.rep, f.start + symmetry.observation_size,
                           f.stop + symmetry.observation_size, f.particle) for f in a)
    n_s, n_a = symmetry.observation_size, symmetry.action_size
    orbit = orbit_dimension(group, both)
    return {
        "dim S×A": n_s + n_a, "orbit": orbit, "dim (S×A)/G": n_s + n_a - orbit,
        "A": hom_dimension(group, s, s), "A plain": n_s * n_s,
        "B": hom_dimension(group, a, s), "B plain": n_s * n_a,
        "K": hom_dimension(group, s, a), "K plain": n_a * n_s,
        "P": hom_dimension(group, s, s, symmetric=True), "P plain": n_s * (n_s + 1) // 2,
    }
