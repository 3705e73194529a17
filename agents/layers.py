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

import copy

import torch
import torch.nn.functional as F
from escnn import nn as enn
from torch import nn

Layout = int | enn.FieldType

ACTIVATIONS = {"mish": nn.Mish, "elu": nn.ELU, "relu": nn.ReLU, "silu": nn.SiLU}


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


class EquivariantLinear(nn.Module):
    """A G-equivariant linear map (escnn's basis), applied as a plain ``F.linear``.

    escnn expands the weight from its basis coefficients at every call. With
    gradients on, so does this layer (the expansion is part of the graph).
    Without them (planning, evaluation) the expanded weight is cached and
    reused until a parameter changes in place (optimiser step, ``SoftUpdate``,
    ``load_state_dict``): the cache is keyed on the parameters' version
    counters, so it can never be stale.
    """

    def __init__(self, in_type: enn.FieldType, out_type: enn.FieldType, bias: bool = True) -> None:
        super().__init__()
        self.layer = enn.Linear(in_type, out_type, bias=bias)
        # escnn caches one basis module per pair of representations and shares it
        # between layers, so .to()/.double() on one network would change the others'
        # buffers (seen: a float network failing after another was made double). Own a copy.
        self.layer._basisexpansion = copy.deepcopy(self.layer._basisexpansion)
        self._cache_key: tuple | None = None
        self._cache: tuple[torch.Tensor, torch.Tensor | None] | None = None

    @property
    def in_type(self) -> enn.FieldType:
        return self.layer.in_type

    @property
    def out_type(self) -> enn.FieldType:
        return self.layer.out_type

    def train(self, mode: bool = True) -> EquivariantLinear:
        # escnn's Linear stores expanded buffers in eval mode, which would change
        # the state_dict between modes; this layer caches on its own instead.
        self.training = mode
        return self

    def expanded(self) -> tuple[torch.Tensor, torch.Tensor | None]:
        """(weight, bias) as plain matrices, as ``nn.Linear`` would hold them."""
        # Read the two parameters directly: ``Module.parameters()`` walks the module
        # tree and hashes escnn's basis modules, which cost more than the matmul
        # itself in planning (measured: 60% of a D8 plan). Attribute lookups also
        # see parameters swapped in by ``TensorDict.to_module``.
        params = [p for p in (self.layer.weights, self.layer.bias) if p is not None]
        if torch.is_grad_enabled() and any(p.requires_grad for p in params):
            return self.layer.expand_parameters()
        key = tuple((p.data_ptr(), p._version) for p in params)
        if key != self._cache_key:
            with torch.no_grad():
                self._cache = self.layer.expand_parameters()
            self._cache_key = key
        return self._cache

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        weight, bias = self.expanded()
        return F.linear(x, weight, bias)

    def export(self) -> nn.Linear:
        """A plain ``nn.Linear`` with the current expanded weights."""
        weight, bias = self.expanded()
        out = nn.Linear(weight.shape[1], weight.shape[0], bias=bias is not None)
        with torch.no_grad():
            out.weight.copy_(weight)
            if bias is not None:
                out.bias.copy_(bias)
        return out.to(weight.device)


def make_linear(in_layout: Layout, out_layout: Layout, bias: bool = True) -> nn.Module:
    """``nn.Linear`` between plain layouts, ``EquivariantLinear`` between field types."""
    if isinstance(in_layout, int) and isinstance(out_layout, int):
        return nn.Linear(in_layout, out_layout, bias=bias)
    if isinstance(in_layout, int) or isinstance(out_layout, int):
        raise TypeError("a linear layer maps plain to plain or field type to field type")
    return EquivariantLinear(in_layout, out_layout, bias=bias)


class FieldLayerNorm(nn.Module):
    """LayerNorm whose scale and shift are shared within each field.

    With all fields of size 1 (a plain layout) this is ``nn.LayerNorm``.
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

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        x = F.layer_norm(x, (self.size,), eps=self.eps)
        return x * self.weight[self.field_index] + self.bias[self.field_index]


def activation(name: str) -> nn.Module:
    """A pointwise nonlinearity by name (exact on regular fields)."""
    if name not in ACTIVATIONS:
        raise ValueError(f"unknown activation {name!r}; valid: {', '.join(ACTIVATIONS)}")
    return ACTIVATIONS[name]()
