"""Equivariant TD-MPC for Geometric MDPs: networks built from symmetry declarations.

Layers, bottom up: ``agents.nn`` (groups, equivariant layers, networks),
``agents.tdmpc`` (world model, loss, planner, replay, the agent),
``agents.run`` (a run's options, trainer, checkpoints, logs), ``agents.options`` (the
validator every option is declared for), ``agents.compat`` (dependency internals) and
``agents.cli`` (the
``geomdp-train``, ``geomdp-plot`` and ``geomdp-theory`` commands).
"""

from agents.nn.escnn_groups import AgentGroup, field_type, group_for_task, make_group, valid_groups
from agents.nn.networks import NetworkConfig, Networks, build_networks, project, squash
from agents.tdmpc.agent import TDMPCAgent, TDMPCConfig

__all__ = ["AgentGroup", "NetworkConfig", "Networks", "TDMPCAgent", "TDMPCConfig", "build_networks",
           "field_type", "group_for_task", "make_group", "project", "squash", "valid_groups"]
