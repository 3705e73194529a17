"""The layer classes shared by plain and equivariant networks: ``make_linear``
(``nn.Linear``, ``EquivariantLinear``, ``FourierLinear`` or ``SplitLinear``),
``FieldLayerNorm`` and ``norm_and_activation``.

Every layer here takes layouts (``agents.nn.layout``: an ``int`` or an escnn
``FieldType``), so one network definition serves both: only ``make_linear``
looks at which kind it got.

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

import torch
import torch.nn.functional as F
from escnn import nn as enn
from torch import nn

from agents.compat.escnn import bias_expansion, own_basis_expansion
from agents.nn.activations import activation
from agents.nn.escnn_basis import field_type_pairs
from agents.nn.expansion import ScopedExpansion
from agents.nn.layout import Layout, field_sizes, is_pointwise, is_regular, layout_size, regular_prefix
from agents.nn.spectral import GridActivation, Quadrature, SpectralLayerNorm


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
        pairs = field_type_pairs(self.layer)
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

    def bases(self) -> list[torch.Tensor]:
        """The sampled basis of each field-type pair as this layer applies it
        ([basis, out_size x in_size]): what its coefficients mean. escnn solves for some
        bases numerically and caches them on disk, so another machine (other BLAS
        kernels) can rebuild another basis of the same space (docs/checkpoints.md)."""
        return [getattr(self, f"_basis{k}") for k in range(len(self._pairs))]

    @torch.no_grad()
    def adopt_bases(self, bases: list[torch.Tensor]) -> None:
        """Apply ``bases`` (another build's ``bases()``) from now on, so that the same
        coefficients give the same maps as in that build. Each must span exactly the
        space of the basis rebuilt here (this machine's equivariant maps between the
        pair's fields); otherwise a ValueError, and nothing is changed."""
        own = self.bases()
        if len(bases) != len(own):
            raise ValueError(f"{len(bases)} bases for a layer with {len(own)} field-type pairs")
        for k, (saved, rebuilt) in enumerate(zip(bases, own)):
            if saved.shape != rebuilt.shape:
                raise ValueError(f"basis {k} has shape {tuple(saved.shape)}, this layer's "
                                 f"{tuple(rebuilt.shape)}")
            if not (_spans_within(saved, rebuilt) and _spans_within(rebuilt, saved)):
                raise ValueError(f"basis {k} spans other maps than this layer's equivariant "
                                 "ones (another group representation?)")
        for saved, rebuilt in zip(bases, own):
            rebuilt.copy_(saved)

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
            bias = bias_expansion(self.layer) @ self.layer.bias
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


def dense_equivariant_layers(module: nn.Module) -> dict[str, EquivariantLinear]:
    """The ``EquivariantLinear`` layers of ``module`` by name (those inside a
    ``SplitLinear`` included): the layers whose bases a checkpoint stores."""
    return {name: m for name, m in module.named_modules() if isinstance(m, EquivariantLinear)}


def _spans_within(a: torch.Tensor, b: torch.Tensor, rtol: float = 1e-5) -> bool:
    """Whether every row of ``a`` is a linear combination of the rows of ``b`` (up to
    float32 rounding): least squares in float64."""
    a64, b64 = a.detach().double().cpu(), b.detach().double().cpu()
    mix = torch.linalg.lstsq(b64.T, a64.T).solution
    return bool(torch.linalg.norm(b64.T @ mix - a64.T) <= rtol * torch.linalg.norm(a64))


LINEAR_KINDS = ("dense", "fourier")


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
    regular, rest = regular_prefix(in_layout) if kind == "fourier" else (None, None)
    if regular is not None and is_regular(out_layout):
        from agents.nn.fourier import FourierLinear

        fourier = FourierLinear(regular, out_layout, bias=bias, bias_init=bias_init)
        if rest is None:
            return fourier
        return SplitLinear(fourier, EquivariantLinear(rest, out_layout, bias=False))
    return EquivariantLinear(in_layout, out_layout, bias=bias, bias_init=bias_init)


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


def norm_and_activation(layout: Layout, activation_name: str, grid: Quadrature | None = None,
                        layer_norm: bool = True) -> list[nn.Module]:
    """LayerNorm (unless ``layer_norm`` is false) then the nonlinearity, for a hidden layout:
    pointwise on plain and regular fields; on band-limited fields of a continuous group,
    LayerNorm of their functions (exact) and the nonlinearity sampled on ``grid``
    (``agents/nn/spectral.py``)."""
    pointwise = is_pointwise(layout)
    if not pointwise and grid is None:
        raise ValueError("band-limited fields need a quadrature grid for their nonlinearity")
    blocks: list[nn.Module] = []
    if layer_norm:
        blocks.append(FieldLayerNorm(layout) if pointwise else SpectralLayerNorm(layout, grid))
    function = activation(activation_name)
    blocks.append(function if pointwise else GridActivation(layout, function, grid))
    return blocks
