"""Equivariant TD-MPC for Geometric MDPs: networks built from symmetry declarations.

Layers, bottom up: ``agents.nn`` (groups, equivariant layers, networks),
``agents.tdmpc`` (world model, loss, planner, replay, the agent),
``agents.run`` (a run's options, trainer, checkpoints, logs), ``agents.options`` (the
validator every option is declared for), ``agents.compat`` (dependency internals) and
``agents.cli`` (the
``geomdp-train``, ``geomdp-plot`` and ``geomdp-theory`` commands).
"""

from __future__ import annotations

import importlib
from typing import TYPE_CHECKING, Any

# Loaded on first use (PEP 562): the CSV readers behind ``geomdp-plot`` and the run queue
# live in this package too, and must not pay for importing torch, escnn and torchrl.
_EXPORTS = {
    "AgentGroup": "agents.nn.escnn_groups", "field_type": "agents.nn.escnn_groups",
    "group_for_task": "agents.nn.escnn_groups", "make_group": "agents.nn.escnn_groups",
    "valid_groups": "agents.nn.escnn_groups",
    "Architecture": "agents.nn.networks", "NetworkConfig": "agents.nn.networks",
    "Networks": "agents.nn.networks",
    "build_networks": "agents.nn.networks", "project": "agents.nn.networks",
    "squash": "agents.nn.networks",
    "TDMPCAgent": "agents.tdmpc.agent", "TDMPCConfig": "agents.tdmpc.agent",
    "agent_config": "agents.run.presets",
}
__all__ = ["AgentGroup", "Architecture", "NetworkConfig", "Networks", "TDMPCAgent", "TDMPCConfig",
           "agent_config", "build_networks", "field_type", "group_for_task", "make_group", "project",
           "squash", "valid_groups"]

if TYPE_CHECKING:
    from agents.nn.escnn_groups import AgentGroup, field_type, group_for_task, make_group, valid_groups
    from agents.nn.networks import Architecture, NetworkConfig, Networks, build_networks, project, squash
    from agents.run.presets import agent_config
    from agents.tdmpc.agent import TDMPCAgent, TDMPCConfig


def __getattr__(name: str) -> Any:
    if name not in _EXPORTS:
        raise AttributeError(f"module 'agents' has no attribute {name!r}")
    value = getattr(importlib.import_module(_EXPORTS[name]), name)
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(__all__))
