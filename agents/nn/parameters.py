"""A network's modules and parameters, walked without hashing escnn's modules
(``submodules``, ``parameter_slots``), and swapped for detached aliases
(``detached_parameters``)."""

from __future__ import annotations

import contextlib
from collections.abc import Iterator

from torch import nn

from agents.compat.torch import child_modules, parameter_table


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
