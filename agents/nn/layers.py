"""Layers shared by plain and equivariant networks.

A *layout* describes a feature vector: an ``int`` (plain R^n, no group action)
or an escnn ``FieldType`` (a direct sum of representations of a group). Every
layer here takes layouts, so one network definition serves both: only
``make_linear`` looks at which kind it got.

Why these layers are exact for hidden layers made of regular fields: a regular
representation permutes the coordinates of its field, so any pointwise
nonlinearity commutes with it, LayerNorm's mean and variance over all channels
are invariant, and a scale and shift shared by the coordinates of one field
(``FieldLayerNorm``) commutes with the permutation. Per-channel affine
parameters would not.
"""

from __future__ import annotations

import contextlib
import io
import math
from collections import Counter
from collections.abc import Iterator
from dataclasses import dataclass

import torch
import torch.nn.functional as F
from escnn import nn as enn
from torch import nn

from agents.compat.escnn import basis_blocks, own_basis_expansion
from agents.compat.torch import child_modules, parameter_table
from agents.nn.activations import activation
from agents.nn.spectral import GridActivation, Quadrature, SpectralLayerNorm

Layout = int | enn.FieldType

def layout_size(layout: Layout) -> int:
    return layout if isinstance(layout, int) else layout.size


def field_sizes(layout: Layout) -> list[int]:
    """Sizes of the fields whose coordinates share a LayerNorm scale and shift."""
    if isinstance(layout, int):
        return [1] * layout
    return [rep.size for rep in layout.representations]


def concat(a: Layout, b: Layout) -> Layout:
    """The layout of ``torch.cat([x_a, x_b], -1)``."""
    if isinstance(a, int) and isinstance(b, int):
        return a + b
    if isinstance(a, int) or isinstance(b, int):
        raise TypeError("cannot concatenate a plain and an equivariant layout")
    return a + b


def is_pointwise(layout: Layout) -> bool:
    """Whether pointwise nonlinearities and field-tied LayerNorm are exact on it."""
    return isinstance(layout, int) or all(
        "pointwise" in rep.supported_nonlinearities for rep in layout.representations)


class ScopedExpansion(nn.Module):
    """A module whose parameters are mapped to the tensors it applies (``expand``).

    Outside an ``expansion_scope`` the map runs at every call, so the result always
    reflects the parameters as they are now, however they were written (optimiser,
    ``SoftUpdate`` through ``.data``, ``load_state_dict``, ``TensorDict.to_module``,
    ``detached_parameters``).
    Inside one it runs once, at the scope's entry, and every call reuses it: the
    scope is the explicit refresh point; nothing outlives it. An earlier design
    cached across calls keyed on the parameters' version counters and was
    silently stale after writes through ``.data`` (TorchRL's ``SoftUpdate``, fused
    Adam): the target network never moved.
    """

    def __init__(self) -> None:
        super().__init__()
        self._scoped: tuple[tuple[torch.Tensor | None, ...], torch.Tensor,
                            torch.Tensor | None] | None = None

    def _current_parameters(self) -> tuple[torch.Tensor | None, ...]:
        raise NotImplementedError

    def expand(self) -> tuple[torch.Tensor, torch.Tensor | None]:
        """(weight, bias) as applied, freshly computed from the parameters."""
        raise NotImplementedError

    def open_scope(self) -> None:
        """Expand now and reuse the result until ``expansion_scope`` restores the outer one."""
        weight, bias = self.expand()
        self._scoped = (self._current_parameters(), weight, bias)

    def expanded(self) -> tuple[torch.Tensor, torch.Tensor | None]:
        """The weight and bias this call uses: the scope's, or a fresh expansion."""
        if self._scoped is not None:
            scoped_params, weight, bias = self._scoped
            current = self._current_parameters()
            if all(c is s for c, s in zip(current, scoped_params)):
                if weight.requires_grad or not torch.is_grad_enabled() or not any(
                        p is not None and p.requires_grad for p in current):
                    return weight, bias
            elif all(_aliases(c, s) for c, s in zip(current, scoped_params)):
                # Detached aliases swapped in by ``detached_parameters`` or ``to_module``
                # (the policy loss's frozen Q): the same memory, unwritten inside the
                # scope, so the same values.
                return weight.detach(), None if bias is None else bias.detach()
        return self.expand()


class EquivariantLinear(ScopedExpansion):
    """A G-equivariant linear map (escnn's basis), applied as a plain ``F.linear``.

    The weight matrix is a linear function of escnn's basis coefficients (the
    layer's parameters), expanded at every call or once per ``expansion_scope``
    (``ScopedExpansion``): that is how the planner (hundreds of network calls per
    action) and the loss (the horizon unroll) avoid re-expanding.

    The expansion (``expand``) is computed here from escnn's sampled bases, as one
    GEMM per pair of field types (coefficients [field pairs, basis] @ basis
    [basis, out x in]) and one copy into place; escnn's own ``expand_parameters``
    (an einsum, then copies through index lists) gives the same matrix and stays
    the reference in the tests. Measured on a D8 hidden layer: 20 us against 166 us
    forward, 120 against 386 us forward and backward (docs/design.md).
    """

    def __init__(self, in_type: enn.FieldType, out_type: enn.FieldType, bias: bool = True,
                 bias_init: float = 0.0) -> None:
        super().__init__()
        # escnn reports on stdout each tensor-product decomposition it solves (continuous
        # groups, the first time a band limit is used); the result is all that matters.
        with contextlib.redirect_stdout(io.StringIO()):
            self.layer = enn.Linear(in_type, out_type, bias=bias)
        # escnn caches one basis module per pair of representations and shares it
        # between layers, so .to()/.double() on one network would change the others'
        # buffers (seen: a float network failing after another was made double). Own a copy.
        own_basis_expansion(self.layer)
        if self.layer.bias is not None and bias_init > 0:
            # escnn starts biases (one per trivial sub-field) at zero; see ``make_linear``
            # for why they are spread out instead, as nn.Linear's are.
            with torch.no_grad():
                self.layer.bias.uniform_(-bias_init, bias_init)
        pairs = _field_type_pairs(self.layer)
        self._pairs = [pair for pair, _, _ in pairs]
        for k, (_, basis, indices) in enumerate(pairs):
            # Buffers (so they follow .to()), not persistent: rebuilt with the network.
            self.register_buffer(f"_basis{k}", basis, persistent=False)
            if indices is not None:
                self.register_buffer(f"_rows{k}", indices[0][:, None], persistent=False)
                self.register_buffer(f"_cols{k}", indices[1][None, :], persistent=False)
        self._whole = (len(self._pairs) == 1 and self._pairs[0].rows == slice(0, out_type.size)
                       and self._pairs[0].cols == slice(0, in_type.size))

    @property
    def in_type(self) -> enn.FieldType:
        return self.layer.in_type

    @property
    def out_type(self) -> enn.FieldType:
        return self.layer.out_type

    def train(self, mode: bool = True) -> EquivariantLinear:
        # escnn's Linear stores expanded buffers in eval mode, which would change
        # the state_dict between modes; this layer never uses them.
        self.training = mode
        return self

    def _current_parameters(self) -> tuple[torch.Tensor | None, ...]:
        # Attribute lookups, not ``Module.parameters()``: they see parameters swapped
        # in by ``TensorDict.to_module``, and do not walk escnn's basis modules
        # (which cost more than the matmul itself in planning).
        return (self.layer.weights, self.layer.bias)

    def expand(self) -> tuple[torch.Tensor, torch.Tensor | None]:
        coefficients = self.layer.weights
        blocks = []
        for k, pair in enumerate(self._pairs):
            block = coefficients[pair.weights].view(pair.n_out * pair.n_in, -1) @ getattr(
                self, f"_basis{k}")
            blocks.append(block.view(pair.n_out, pair.n_in, pair.out_size, pair.in_size)
                          .transpose(1, 2).reshape(pair.n_out * pair.out_size,
                                                   pair.n_in * pair.in_size))
        if self._whole:
            weight = blocks[0]
        else:
            weight = coefficients.new_zeros(self.out_type.size, self.in_type.size)
            for k, (pair, block) in enumerate(zip(self._pairs, blocks)):
                if pair.rows is not None:
                    weight[pair.rows, pair.cols] = block
                else:  # fields of this type interleaved with others: channel indices
                    weight[getattr(self, f"_rows{k}"), getattr(self, f"_cols{k}")] = block
        bias = None
        if self.layer.bias is not None:
            bias = self.layer.bias_expansion @ self.layer.bias
        return weight, bias

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        weight, bias = self.expanded()
        return F.linear(x, weight, bias)

    def export(self) -> nn.Linear:
        """A plain ``nn.Linear`` with the current expanded weights."""
        with torch.no_grad():
            weight, bias = self.expand()
        out = nn.Linear(weight.shape[1], weight.shape[0], bias=bias is not None)
        with torch.no_grad():
            out.weight.copy_(weight)
            if bias is not None:
                out.bias.copy_(bias)
        return out.to(weight.device)


@dataclass(frozen=True)
class _FieldTypePair:
    """One (input representation, output representation) pair of an escnn ``Linear``:
    where its coefficients sit in the flat parameter vector, and where its blocks go
    in the weight: ``rows``/``cols`` slices when the fields of each type are adjacent,
    else None (the layer keeps channel indices in buffers)."""

    weights: slice
    n_out: int
    n_in: int
    out_size: int
    in_size: int
    rows: slice | None
    cols: slice | None


def _field_type_pairs(layer: enn.Linear) -> list[
        tuple[_FieldTypePair, torch.Tensor, tuple[torch.Tensor, torch.Tensor] | None]]:
    """The pairs of an escnn ``Linear``'s ``BlocksBasisExpansion`` (the layout of its
    ``forward``), each with its sampled basis as a [basis, out_size x in_size] matrix
    and, when its fields are not adjacent, the channel indices of its rows and columns."""
    expansion = layer.basisexpansion
    if expansion.S != 1:
        raise ValueError(f"expected a 0-dimensional base space (one sample), got {expansion.S}")

    def channels(reprs: list) -> dict[str, list[int]]:
        out, start = {}, 0
        for rep in reprs:
            out.setdefault(rep.name, []).extend(range(start, start + rep.size))
            start += rep.size
        return out

    def adjacent(positions: list[int]) -> bool:
        return positions == list(range(positions[0], positions[-1] + 1))

    # The representations escnn's expansion was built from, in the same order.
    out_reprs, in_reprs = layer.out_type.representations, layer.in_type.representations
    out_channels, in_channels = channels(out_reprs), channels(in_reprs)
    out_count, in_count = Counter(r.name for r in out_reprs), Counter(r.name for r in in_reprs)
    pairs = []
    for block in basis_blocks(expansion):
        in_name, out_name = block.in_name, block.out_name
        basis = block.sampled_basis  # [basis, out_size, in_size, 1]
        start, stop = block.weights
        rows, cols = out_channels[out_name], in_channels[in_name]
        sliced = adjacent(rows) and adjacent(cols)
        pairs.append((_FieldTypePair(
            weights=slice(start, stop), n_out=out_count[out_name],
            n_in=in_count[in_name], out_size=basis.shape[1], in_size=basis.shape[2],
            rows=slice(rows[0], rows[-1] + 1) if sliced else None,
            cols=slice(cols[0], cols[-1] + 1) if sliced else None),
            basis.reshape(basis.shape[0], -1).clone(),
            None if sliced else (torch.tensor(rows), torch.tensor(cols))))
    return pairs


def _aliases(a: torch.Tensor | None, b: torch.Tensor | None) -> bool:
    """Whether two tensors view the same memory the same way (``None`` matches ``None``)."""
    if a is None or b is None:
        return a is b
    return (a.data_ptr() == b.data_ptr() and a.shape == b.shape and a.stride() == b.stride()
            and a.dtype == b.dtype and not a.requires_grad)


def submodules(module: nn.Module) -> Iterator[nn.Module]:
    """``module.modules()`` (each module once, in the same order) without hashing them:
    ``Module.modules()`` keeps a set of the modules it has seen, and escnn's basis
    modules hash by value, recursively over their bases (~20 us each), which made every
    walk of an equivariant network cost milliseconds (D8 `linear`: ~6 ms per update
    and ~3 ms per plan in ``expansion_scope``)."""
    seen: set[int] = set()
    stack = [module]
    while stack:
        current = stack.pop()
        if id(current) in seen:
            continue
        seen.add(id(current))
        yield current
        stack.extend(reversed(child_modules(current)))


@contextlib.contextmanager
def expansion_scope(*modules: nn.Module) -> Iterator[None]:
    """Expand every ``ScopedExpansion`` of ``modules`` (equivariant weights, tied
    LayerNorm affines) once, and reuse the result until exit.

    The contract: nothing writes the parameters inside the scope. The agent opens
    one around each plan (no gradients) and one around each loss evaluation (with
    gradients, so the expansions are part of the graph: one per layer per update,
    not one per call). Optimiser steps, target updates and loads happen outside,
    and the next scope expands again, so no write path can leave a stale weight.
    A scope inside a scope re-expands; leaving it restores the outer one.
    """
    layers = [m for module in modules for m in submodules(module) if isinstance(m, ScopedExpansion)]
    outer = [layer._scoped for layer in layers]
    try:
        for layer in layers:
            layer.open_scope()
        yield
    finally:
        for layer, saved in zip(layers, outer):
            layer._scoped = saved


ParameterSlots = list[tuple[nn.Module, str]]


def parameter_slots(module: nn.Module) -> ParameterSlots:
    """Where each parameter of ``module`` lives, as (owning module, attribute name): the
    network's structure, fixed once it is built, so it is listed once; the parameters
    are read at each use."""
    return [(owner, name) for owner in submodules(module)
            for name, _ in owner.named_parameters(recurse=False, remove_duplicate=False)]


@contextlib.contextmanager
def detached_parameters(slots: ParameterSlots) -> Iterator[None]:
    """Every parameter in ``slots`` replaced by a detached alias (same memory) until exit:
    calls inside compute with the current values and send no gradient to them (the
    policy loss's frozen Q). Inside an ``expansion_scope`` the layers recognise the
    aliases and reuse the scope's expansion, detached (``ScopedExpansion.expanded``).
    What ``TensorDict.from_module(m).detach().to_module(m)`` does, for parameters only
    and without walking the modules: 12 us against 2.6 ms for the D8 twin Q."""
    tables = [parameter_table(owner) for owner, _ in slots]
    saved = [table[name] for table, (_, name) in zip(tables, slots)]
    try:
        for table, (_, name), p in zip(tables, slots, saved):
            table[name] = p.detach()
        yield
    finally:
        for table, (_, name), p in zip(tables, slots, saved):
            table[name] = p


LINEAR_KINDS = ("dense", "fourier")


def is_regular(layout: Layout) -> bool:
    """Whether a layout is made only of regular fields of a finite group (a hidden
    layer of an equivariant net; continuous groups' hidden fields are band-limited)."""
    if isinstance(layout, int):
        return False
    regular, rest = _regular_prefix(layout)
    return regular is not None and rest is None


def make_linear(in_layout: Layout, out_layout: Layout, bias: bool = True,
                kind: str = "dense") -> nn.Module:
    """``nn.Linear`` between plain layouts; between field types ``EquivariantLinear``
    (escnn's dense expansion), or with ``kind="fourier"`` and regular output fields
    ``FourierLinear`` (the same maps, applied block-diagonally in the irrep basis)
    from the input's leading regular fields, plus an ``EquivariantLinear`` from any
    fields after them (``SplitLinear``)."""
    if kind not in LINEAR_KINDS:
        raise ValueError(f"layers={kind!r}; valid: {', '.join(LINEAR_KINDS)}")
    if isinstance(in_layout, int) and isinstance(out_layout, int):
        return nn.Linear(in_layout, out_layout, bias=bias)
    if isinstance(in_layout, int) or isinstance(out_layout, int):
        raise TypeError("a linear layer maps plain to plain or field type to field type")
    # Biases start as nn.Linear's do (uniform, +-1/sqrt(fan_in)), not at escnn's zero:
    # an equivariant map from vector fields has zero mean over its output channels,
    # so with zero biases the LayerNorm after it would divide out |input| entirely.
    bias_init = 1 / math.sqrt(layout_size(in_layout))
    regular, rest = _regular_prefix(in_layout) if kind == "fourier" else (None, None)
    if regular is not None and is_regular(out_layout):
        from agents.nn.fourier import FourierLinear

        fourier = FourierLinear(regular, out_layout, bias=bias, bias_init=bias_init)
        if rest is None:
            return fourier
        return SplitLinear(fourier, EquivariantLinear(rest, out_layout, bias=False))
    return EquivariantLinear(in_layout, out_layout, bias=bias, bias_init=bias_init)


def _regular_prefix(layout: enn.FieldType) -> tuple[enn.FieldType | None, enn.FieldType | None]:
    """(the leading regular fields, the fields after them), as field types (None if empty)."""
    reps = layout.representations
    regular_name = None if layout.gspace.fibergroup.continuous else (
        layout.gspace.fibergroup.regular_representation.name)
    n = next((i for i, rep in enumerate(reps) if rep.name != regular_name), len(reps))
    return (enn.FieldType(layout.gspace, reps[:n]) if n else None,
            enn.FieldType(layout.gspace, reps[n:]) if n < len(reps) else None)


class SplitLinear(nn.Module):
    """An equivariant map from (regular fields, other fields), as the sum of a
    ``FourierLinear`` on the regular part and an ``EquivariantLinear`` on the rest.

    The input layers of dynamics, reward and Q read (latent, action): the latent's
    regular-to-regular block is most of the layer and runs in the irrep basis. A
    linear map from a direct sum is the sum of maps from its summands, so this is
    escnn's function class with its parameter count (the bias is the Fourier
    part's). Each part is initialised for the layer's whole fan-in, as escnn's
    single layer is.
    """

    def __init__(self, regular: nn.Module, rest: EquivariantLinear) -> None:
        super().__init__()
        self.regular, self.rest = regular, rest
        self.split = regular.in_type.size
        total = self.split + rest.in_type.size
        with torch.no_grad():
            regular.weights.mul_(math.sqrt(self.split / total))
            rest.layer.weights.mul_(math.sqrt(rest.in_type.size / total))

    @property
    def in_type(self) -> enn.FieldType:
        return self.regular.in_type + self.rest.in_type

    @property
    def out_type(self) -> enn.FieldType:
        return self.regular.out_type

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return self.regular(x[..., :self.split]) + self.rest(x[..., self.split:])

    def expand(self) -> tuple[torch.Tensor, torch.Tensor | None]:
        """(weight, bias) of the equivalent dense map."""
        weight, bias = self.regular.expand()
        rest_weight, _ = self.rest.expand()
        return torch.cat([weight, rest_weight], dim=1), bias


class FieldLayerNorm(ScopedExpansion):
    """LayerNorm whose scale and shift are shared within each field.

    With all fields of size 1 (a plain layout) this is ``nn.LayerNorm``. Otherwise
    the tied scale and shift are gathered to one per channel (``expand``) and
    applied inside the kernel: half the time of normalising, then gathering,
    multiplying and adding; once per ``expansion_scope``, not once per call.
    """

    def __init__(self, layout: Layout, eps: float = 1e-5) -> None:
        super().__init__()
        if not is_pointwise(layout):
            raise ValueError("FieldLayerNorm is exact only on regular/trivial fields")
        sizes = field_sizes(layout)
        self.size, self.eps = sum(sizes), eps
        self.weight = nn.Parameter(torch.ones(len(sizes)))
        self.bias = nn.Parameter(torch.zeros(len(sizes)))
        index = torch.repeat_interleave(torch.arange(len(sizes)), torch.tensor(sizes))
        self.register_buffer("field_index", index, persistent=False)
        # Fields of one size (hidden layers): repeat each parameter by a broadcast, whose
        # backward is a sum, not the gather's scatter-add. Size 1: a plain LayerNorm.
        self.common_size = sizes[0] if len(set(sizes)) == 1 else None
        self.per_channel = self.common_size == 1

    def _current_parameters(self) -> tuple[torch.Tensor | None, ...]:
        return (self.weight, self.bias)

    def expand(self) -> tuple[torch.Tensor, torch.Tensor | None]:
        if self.common_size is not None:
            n, size = len(self.weight), self.common_size
            return (self.weight[:, None].expand(n, size).reshape(-1),
                    self.bias[:, None].expand(n, size).reshape(-1))
        return self.weight[self.field_index], self.bias[self.field_index]

    def open_scope(self) -> None:
        if not self.per_channel:  # plain layers apply their parameters as they are
            super().open_scope()

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        if self.per_channel:  # plain: nothing to gather
            return F.layer_norm(x, (self.size,), self.weight, self.bias, self.eps)
        weight, bias = self.expanded()
        return F.layer_norm(x, (self.size,), weight, bias, self.eps)


def norm_and_activation(layout: Layout, activation_name: str,
                        grid: Quadrature | None = None) -> list[nn.Module]:
    """LayerNorm then the nonlinearity, for a hidden layout: pointwise on plain and
    regular fields; on band-limited fields of a continuous group, LayerNorm of their
    functions (exact) and the nonlinearity sampled on ``grid`` (``agents/nn/spectral.py``)."""
    if is_pointwise(layout):
        return [FieldLayerNorm(layout), activation(activation_name)]
    if grid is None:
        raise ValueError("band-limited fields need a quadrature grid for their nonlinearity")
    return [SpectralLayerNorm(layout, grid), GridActivation(layout, activation(activation_name),
                                                            grid)]
