"""torch internals: ``nn.Module``'s own tables, its conversion funnel, dispatch modes."""

from __future__ import annotations

from collections.abc import Callable, MutableMapping
from typing import Any

import torch
from torch import nn

try:
    from torch.utils._python_dispatch import TorchDispatchMode
except ImportError as err:  # pragma: no cover - only on a torch that moved it
    raise ImportError(f"torch {torch.__version__} has no torch.utils._python_dispatch."
                      f"TorchDispatchMode (see agents/compat/torch.py)") from err

__all__ = ["ConversionHook", "TorchDispatchMode", "child_modules", "parameter_table"]

# ``TorchDispatchMode`` (re-exported above): the base class of a mode that sees every
# aten call (benchmarks/agent_speed.py counts FLOPs with one). torch has no public
# import path for it; its public ``FlopCounterMode`` also tracks modules, and its
# tracker tests TorchRL's modules for truth, which raises.


def child_modules(module: nn.Module) -> list[nn.Module]:
    """The direct submodules of ``module``, in registration order, without hashing them.

    Private: ``Module._modules``. The public ``Module.children()`` de-duplicates
    through a set, so it hashes (and compares) every child: escnn's basis modules
    hash by value, recursively over their bases (~20 us each), and two distinct
    but equal ones would be merged into one.
    """
    return [m for m in module._modules.values() if m is not None]


def parameter_table(module: nn.Module) -> MutableMapping[str, torch.Tensor | None]:
    """The live table of ``module``'s own parameters: name -> tensor (None: unset).

    Private: ``Module._parameters``. Writing into it puts a plain tensor (a
    detached alias of a parameter) in a parameter's slot, and the ``Parameter``
    back afterwards, with no hook and no check: ``Module.__setattr__`` and
    ``register_parameter`` (public) accept only a ``Parameter`` there, and
    ``TensorDict.to_module`` (public) does the swap for a whole network at ~200x
    the cost. Only for swaps; read parameters with ``named_parameters``.
    """
    return module._parameters


class ConversionHook(nn.Module):
    """A ``Module`` told after each conversion of its tensors (``.to``, ``.double``,
    ``.float``, ``.cuda``, ``.cpu``, ...): override ``converted``.

    Private: ``Module._apply``, the one method all those conversions go through,
    overridden here (as torch's own ``RNNBase`` does). torch's public module
    hooks fire on forward, backward, state-dict and registration, none after a
    conversion.
    """

    def converted(self) -> None:
        """Runs after every conversion, once this module's tensors are converted."""

    def _apply(self, fn: Callable[..., Any], *args: Any, **kwargs: Any) -> ConversionHook:
        super()._apply(fn, *args, **kwargs)
        self.converted()
        return self
