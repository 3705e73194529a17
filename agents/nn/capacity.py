"""Whether an equivariant agent's layers can carry the task's state.

An equivariant linear map sends copies of an irrep only to copies of the same irrep
(Schur's lemma; for a real-type irrep, such as the vector representation of the 3D groups,
it is a matrix over the copies). So a layer that holds fewer copies of an irrep than its
input passes that input on only through a projection. A regular field holds each irrep as
many times as its dimension, and ``width_strategy`` sets how many fields stand for a plain
width, so a narrow preset with a large group can hold fewer copies than a task has:
PointMass3D with 5 balls (10 vectors) against the icosahedral agent's 2 hidden fields at the
CPU preset's ``linear`` width (6 copies). What each layer is counted against:

- the encoder's hidden layers, against the observation: the first one is linear in the
  observation, so a shortfall there is a loss of state (observations that differ in the
  projection's null space look the same to the whole agent) -- the trainer warns of it;
- the latent, against the observation, and the dynamics' hidden layers, against the
  observation and the action: these come after nonlinear layers and bound only what passes
  linearly (the headline's D8 Reacher agent has its latent short of one sign representation
  and learns).
"""

from __future__ import annotations

import collections
import itertools

import escnn.nn as enn

from agents.nn.escnn_groups import AgentGroup, group_for_task
from agents.nn.networks import NetworkConfig, Space, regular_copies
from geomdp_envs.symmetry import Symmetry

LAYERS = ("encoder hidden", "latent", "dynamics hidden")

Shortfall = dict[tuple, tuple[int, int]]  # irrep id -> (copies needed, copies held)


def irrep_copies(layout: enn.FieldType) -> collections.Counter:
    """Copies of each irrep (by escnn's id) in a field type."""
    return collections.Counter(irrep for rep in layout.representations for irrep in rep.irreps)


def shortfalls(config: NetworkConfig, symmetry: Symmetry,
               layers: tuple[str, ...] = LAYERS) -> dict[str, tuple[int, Shortfall]]:
    """Per layer of ``layers`` (some of ``LAYERS``), for the agent ``config`` describes (with
    a group): its fields, and the irreps it holds fewer copies of than it must pass on."""
    nets = config.networks
    group = _agent_group(config, symmetry)
    space = Space(symmetry.observation, symmetry.action, group, config)
    observation, action = irrep_copies(space.observation), irrep_copies(space.action)
    needs = {"encoder hidden": (nets.hidden_blocks("encoder")[0], observation),
             "latent": (nets.latent_dim, observation),
             "dynamics hidden": (nets.hidden_blocks("dynamics")[0], observation + action)}
    table = {}
    for layer in layers:
        width, need = needs[layer]
        held = irrep_copies(space.regular(width))
        table[layer] = (regular_copies(width, group, config.width_strategy),
                        {irrep: (n, held[irrep]) for irrep, n in sorted(need.items()) if held[irrep] < n})
    return table


def encoder_shortfall(config: NetworkConfig, symmetry: Symmetry) -> str | None:
    """One line when the equivariant encoder's hidden layers cannot carry the observation
    (None when they can, or the encoder is plain), with the encoder width that would."""
    if config.group is None or not config.equivariant.get("transition", True):
        return None
    fields, short = shortfalls(config, symmetry, ("encoder hidden",))["encoder hidden"]
    if not short:
        return None
    nets = config.networks
    group = _agent_group(config, symmetry)
    per_field = irrep_copies(group.gspace.type(group.regular))
    lacking = ", ".join(f"{held} of the observation's {needed} copies of irrep {irrep}"
                        for irrep, (needed, held) in short.items())
    if any(per_field[irrep] == 0 for irrep in short):
        remedy = "no width fits: raise agent.networks.max_frequency"
    else:
        needed_fields = max(-(-needed // per_field[irrep]) for irrep, (needed, _) in short.items())
        width = next(w for w in itertools.count(nets.hidden_blocks("encoder")[0])
                     if regular_copies(w, group, config.width_strategy) >= needed_fields)
        remedy = f"agent.networks.encoder_dim={width} or more fits it"
    layers = f"the encoder's hidden layers ({fields} field{'s' * (fields != 1)})"
    return (f"agent.group={config.group} at width_strategy={config.width_strategy}: {layers} hold "
            f"{lacking}, so part of the state never reaches the agent; {remedy} "
            "(scripts/field_capacity.py)")


def _agent_group(config: NetworkConfig, symmetry: Symmetry) -> AgentGroup:
    nets = config.networks
    return group_for_task(config.group, symmetry, nets.max_frequency, nets.grid_frequency)[0]
