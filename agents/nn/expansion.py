"""Expanded weights: modules whose parameters are mapped to the tensors they apply
(``ScopedExpansion``: equivariant weights, tied LayerNorm affines), and the scope
inside which each expansion is computed once (``expansion_scope``)."""

from __future__ import annotations

import contextlib
from collections.abc import Iterator

import torch
from torch import nn

from agents.nn.parameters import submodules


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


def _aliases(a: torch.Tensor | None, b: torch.Tensor | None) -> bool:
    """Whether two tensors view the same memory the same way (``None`` matches ``None``)."""
    if a is None or b is None:
        return a is b
    return (a.data_ptr() == b.data_ptr() and a.shape == b.shape and a.stride() == b.stride()
            and a.dtype == b.dtype and not a.requires_grad)


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
