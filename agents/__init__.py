"""Equivariant TD-MPC for Geometric MDPs: networks built from symmetry declarations."""

from agents.groups import AgentGroup, field_type, group_for_task, make_group
from agents.networks import NetworkConfig, Networks, build_networks, project, squash

__all__ = ["AgentGroup", "NetworkConfig", "Networks", "build_networks", "field_type",
           "group_for_task", "make_group", "project", "squash"]
