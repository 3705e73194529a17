"""TorchRL internals: prioritised samplers' trees and losses' target-updater flags."""

from __future__ import annotations

from typing import Any

import torch
import torchrl
from torchrl.data import PrioritizedSampler
from torchrl.objectives import LossModule


def prioritized_replay_available() -> bool:
    """Whether TorchRL's compiled extension, whose segment trees prioritised replay needs,
    loads here. It loads only against the torch its wheel was built for (torchrl 0.14.1:
    torch 2.14.1); otherwise TorchRL warns once at import and fails when a prioritised
    sampler is made, after the run has started (seen on a GPU image with torch 2.11).

    Private: the module ``torchrl._torchrl`` (the extension) and its ``SumSegmentTreeFp32``.
    """
    try:
        from torchrl._torchrl import SumSegmentTreeFp32  # noqa: F401
    except ImportError:
        return False
    return True


def prioritized_replay_refusal() -> str | None:
    """Why prioritised replay cannot run here, in one line naming the choices, or None
    where it can. Checked before a run starts and again where a buffer is made."""
    if prioritized_replay_available():
        return None
    return (f"agent.replay.prioritized=true needs TorchRL's compiled extension, which does not "
            f"load here (torchrl {torchrl.__version__} with torch {torch.__version__}): install "
            "the pinned torch (pyproject.toml), or use agent.replay.prioritized=false")


def priority_state(sampler: PrioritizedSampler, n: int) -> dict[str, Any]:
    """The priorities of slots ``[0, n)`` of ``sampler`` and the priority it gives new
    data (``{"sum", "min", "max"}``), for ``restore_priority_state``.

    Private: ``PrioritizedSampler._sum_tree`` and ``._min_tree`` (its segment trees,
    read at the given slots) and ``._max_priority``. The public ``state_dict()``
    deep-copies both trees over the whole capacity (and ``dumps`` reads them slot
    by slot in Python), which is what ``agents.tdmpc.replay.save_replay`` avoids.
    """
    index = torch.arange(n)
    return {"sum": sampler._sum_tree[index], "min": sampler._min_tree[index],
            "max": sampler._max_priority}


def restore_priority_state(sampler: PrioritizedSampler, n: int, state: dict[str, Any]) -> None:
    """Write what ``priority_state(.., n)`` returned into slots ``[0, n)`` of a fresh
    sampler of the same configuration (the same private attributes, written)."""
    index = torch.arange(n)
    sampler._sum_tree[index] = state["sum"]
    sampler._min_tree[index] = state["min"]
    sampler._max_priority = state["max"]


def expect_target_updater(loss: LossModule, name: str) -> None:
    """Mark ``loss``'s ``target_<name>_params`` as awaiting an updater: until a
    ``SoftUpdate``/``HardUpdate`` is built on the loss, calling it warns (TorchRL's
    ``TARGET_NET_WARNING``), as it does for targets made by ``convert_to_functional``.

    Private: ``LossModule._has_update_associated``, the flags those warnings read and
    the updaters set. The public way to set one, ``convert_to_functional(..,
    create_target_params=True)``, also builds the parameters and their targets
    itself, not as a deep-copied target module as ``TDMPCLoss`` keeps them.
    """
    loss._has_update_associated[name] = False
