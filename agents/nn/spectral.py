"""Hidden layers for continuous groups: band-limited functions on the group.

A finite group's hidden feature is a regular field: a function on G, stored as
its |G| values, and a pointwise nonlinearity and LayerNorm act on the values.
SO(2), O(2), SO(3) and O(3) have no finite regular representation, so a hidden
field stores the function's Fourier coefficients up to a frequency L (escnn's
``spectral_regular_representation`` of the irreps ``bl_irreps(L)``):

    f_x(g) = <rho(g) k, x>,   so   f_{rho(h) x}(g) = f_x(h^-1 g)

(k: the inverse-transform kernel, one identity block per irrep, as in escnn's
Fourier nonlinearities). Rotating the coefficients translates the function.

* ``SpectralLayerNorm`` is LayerNorm of the functions f_x over G, computed
  exactly from the coefficients: the mean over G is the trivial coefficient,
  the mean square a fixed quadratic form of the coefficients (Schur
  orthogonality), both invariant; the shift is added to the trivial
  coefficient. No sampling, so exactly equivariant.
* ``GridActivation`` applies the pointwise nonlinearity to samples of f_x at a
  quadrature grid and projects the result back onto frequencies <= L with the
  grid's weights (escnn's Fourier-pointwise approach, ``FourierPointwise``,
  with weighted quadrature). The nonlinearity creates frequencies above L, which
  the grid aliases back; the equivariance error therefore falls as the grid
  integrates higher frequencies exactly (``Quadrature.frequency``), and is 0
  for rotations that map the grid to itself. Chosen over norm nonlinearities
  (exact, but a field's direction passes through unchanged; Weiler & Cesa 2019
  found them weaker) because the error can be driven down by the grid and is
  measured (docs/design.md, tests/test_continuous.py).

Grids are quadratures that integrate every irrep of frequency <= ``frequency``
exactly: uniform angles for SO(2) (N = frequency + 1), the same for both
reflection cosets of O(2); for SO(3) the icosahedral group's 60 rotations up to
frequency 5, above that Euler angles ZYZ with uniform alpha, gamma and
Gauss-Legendre nodes in cos(beta) ((f + 1)^2 ceil((f + 1) / 2) points); O(3)
takes SO(3)'s grid and its inversions.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
import torch
from escnn import nn as enn
from escnn.group import Group, Representation
from scipy.spatial.transform import Rotation
from torch import nn

from geomdp_envs import groups as env_groups


@dataclass(frozen=True)
class Quadrature:
    """Group elements and weights (summing to 1) that integrate exactly every
    irrep of frequency <= ``frequency``."""

    elements: tuple
    weights: np.ndarray
    frequency: int
    # sampling_matrix per representation name: a pure function of immutable inputs,
    # computed once (each of an agent's ~20 spectral layers needs it).
    _samples: dict = field(default_factory=dict, compare=False, repr=False)

    def __len__(self) -> int:
        return len(self.elements)


def quadrature(group: Group, kind: str, frequency: int) -> Quadrature:
    """The quadrature grid of ``group`` (escnn's SO2, O2, SO3 or O3) exact to ``frequency``."""
    n = frequency + 1
    if kind in ("SO2", "O2"):
        angles = [2 * math.pi * i / n for i in range(n)]
        elements = [group.element(a) for a in angles] if kind == "SO2" else [
            group.element((flip, a)) for flip in (0, 1) for a in angles]
        return Quadrature(tuple(elements), np.full(len(elements), 1 / len(elements)), frequency)
    if kind not in ("SO3", "O3"):
        raise ValueError(f"no quadrature for group {kind!r}; valid: SO2, O2, SO3, O3")
    if frequency <= 5:
        # The icosahedral group's 60 rotations: no irrep of SO(3) of degree 1..5 has a
        # vector fixed by all of them, so their average kills every such Wigner-D matrix.
        matrices = env_groups.group_elements("icosahedral")
        weights = np.full(len(matrices), 1.0)
    else:
        # The alpha and gamma sums kill every Wigner-D entry but D^l_00(beta) = P_l(cos beta),
        # a polynomial of degree l <= frequency: Gauss-Legendre with ceil(n / 2) nodes is exact.
        nodes, node_weights = np.polynomial.legendre.leggauss(math.ceil(n / 2))
        angles = 2 * math.pi * np.arange(n) / n
        alpha, cos_beta, gamma = np.meshgrid(angles, nodes, angles, indexing="ij")
        weights = np.broadcast_to(node_weights[None, :, None], alpha.shape).reshape(-1)
        euler = np.stack([alpha.ravel(), np.arccos(cos_beta.ravel()), gamma.ravel()], axis=1)
        matrices = Rotation.from_euler("ZYZ", euler).as_matrix()
    if kind == "SO3":
        elements = [group.element(m, param="MAT") for m in matrices]
    else:
        elements = [group.element((flip, m), param="MAT") for flip in (0, 1) for m in matrices]
        weights = np.concatenate([weights, weights])
    return Quadrature(tuple(elements), weights / weights.sum(), frequency)


def band_limited_regular(group: Group, max_frequency: int) -> Representation:
    """The representation of a function on ``group`` with frequencies <= ``max_frequency``."""
    return group.spectral_regular_representation(*group.bl_irreps(max_frequency),
                                                 name=f"band_limited_regular_{max_frequency}")


def fourier_kernel(rho: Representation) -> np.ndarray:
    """k of f_x(g) = <rho(g) k, x>: for each irrep psi of ``rho`` (in order) the first
    c_psi columns of sqrt(d_psi) I (one per independent copy of psi in the regular
    representation), normalised to |k| = 1."""
    parts = []
    for irrep_id in dict.fromkeys(rho.irreps):  # rho.irreps repeats each irrep per copy
        irrep = rho.group.irrep(*irrep_id)
        copies = irrep.size // irrep.sum_of_squares_constituents
        parts.append((np.sqrt(irrep.size) * np.eye(irrep.size)[:, :copies]).T.reshape(-1))
    kernel = np.concatenate(parts)
    if kernel.size != rho.size:
        raise ValueError(f"{rho.name} is not a band-limited regular representation")
    return kernel / np.linalg.norm(kernel)


def _spectral_fields(layout: enn.FieldType) -> tuple[int, Representation]:
    """(number of fields, their representation): every field must be the same
    band-limited regular representation with identity change of basis."""
    reps = layout.representations
    rho = reps[0]
    if any(r.name != rho.name for r in reps) or not np.allclose(rho.change_of_basis,
                                                                np.eye(rho.size)):
        raise ValueError("spectral layers need fields of one band-limited regular representation")
    return len(reps), rho


def sampling_matrix(rho: Representation, grid: Quadrature) -> np.ndarray:
    """[len(grid), rho.size]: row g maps coefficients x to the sample f_x(g)."""
    if rho.name not in grid._samples:
        kernel = fourier_kernel(rho)
        grid._samples[rho.name] = np.stack([rho(g) @ kernel for g in grid.elements])
    return grid._samples[rho.name]


class SpectralLayerNorm(nn.Module):
    """LayerNorm of the fields' functions over the group, from their coefficients.

    With the samples' mean mu and variance var over all fields and the whole
    group, LayerNorm maps f_i to (f_i - mu) / sqrt(var + eps) * w_i + b_i (one scale
    and shift per field, shared over the group, as ``FieldLayerNorm``). Here mu
    and E[f^2] are read off the coefficients exactly (no sampling), so it is
    exactly equivariant; a quadrature exact to frequency 2L gives the same
    quadratic form, which is how it is computed.
    """

    def __init__(self, layout: enn.FieldType, grid: Quadrature, eps: float = 1e-5) -> None:
        super().__init__()
        self.fields, rho = _spectral_fields(layout)
        self.size, self.eps = rho.size, eps
        trivial = [i for i, irrep_id in enumerate(rho.irreps)
                   if rho.group.irrep(*irrep_id).is_trivial()]
        if len(trivial) != 1 or grid.frequency < 2 * max(_frequency(i) for i in rho.irreps):
            raise ValueError(f"need one trivial irrep and a grid exact to frequency 2L, "
                             f"got irreps {rho.irreps} and grid frequency {grid.frequency}")
        samples = sampling_matrix(rho, grid)
        gram = samples.T @ (grid.weights[:, None] * samples)  # E_g[f(g)^2] = x^T gram x
        if not np.allclose(gram, np.diag(np.diag(gram)), atol=1e-9):
            raise AssertionError("quadrature is not exact to 2L: the Gram matrix is not diagonal")
        offset = sum(rho.group.irrep(*i).size for i in rho.irreps[:trivial[0]])
        self.mean_scale = float(samples[0, offset])  # f's value per unit trivial coefficient
        self.register_buffer("square_weights", torch.tensor(np.diag(gram), dtype=torch.float32),
                             persistent=False)
        self.register_buffer("trivial", torch.eye(rho.size)[offset], persistent=False)
        self.weight = nn.Parameter(torch.ones(self.fields))
        self.bias = nn.Parameter(torch.zeros(self.fields))

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        v = x.reshape(*x.shape[:-1], self.fields, self.size)
        mean = (v * self.trivial).sum(-1, keepdim=True).mean(-2, keepdim=True)
        centred = v - mean * self.trivial  # only the trivial coefficient moves
        var = (centred.square() * self.square_weights).sum(-1).mean(-1)[..., None, None]
        scale = torch.rsqrt(var + self.eps) * self.weight[:, None]
        shift = (self.bias / self.mean_scale)[:, None] * self.trivial
        return (centred * scale + shift).reshape(x.shape)


class GridActivation(nn.Module):
    """A pointwise nonlinearity on the fields' functions, sampled on a quadrature grid
    and projected back onto the band limit (approximately equivariant; see module)."""

    def __init__(self, layout: enn.FieldType, function: nn.Module, grid: Quadrature) -> None:
        super().__init__()
        self.fields, rho = _spectral_fields(layout)
        self.size, self.function, self.grid_size = rho.size, function, len(grid)
        samples = sampling_matrix(rho, grid)
        weighted = samples.T * grid.weights  # [D, N]
        analysis = np.linalg.solve(weighted @ samples, weighted)  # least squares with the weights
        self.register_buffer("to_grid", torch.tensor(samples.T, dtype=torch.float32),
                             persistent=False)
        self.register_buffer("from_grid", torch.tensor(analysis.T, dtype=torch.float32),
                             persistent=False)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        v = x.reshape(*x.shape[:-1], self.fields, self.size)
        return (self.function(v @ self.to_grid) @ self.from_grid).reshape(x.shape)

    def extra_repr(self) -> str:
        return f"{self.fields} fields of size {self.size}, grid of {self.grid_size} elements"


def _frequency(irrep_id: tuple) -> int:
    """An irrep's frequency: SO(2) (k,), O(2) (j, k), SO(3) (l,), O(3) (j, l)."""
    return int(irrep_id[-1])
