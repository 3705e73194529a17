"""Whether an equivariant agent's layers can carry the task's state: copies of each irrep
in the encoder's hidden layers, the latent and the dynamics' hidden layers, against what
each must pass on (RESULTS.md, issue 38).

    .venv/bin/python scripts/field_capacity.py GeoMDP/PointMass3D-v0:n_balls=5 \\
        --groups octahedral icosahedral --widths linear sqrt --encoder-dim 128 --latent-dim 32

An equivariant linear map sends each irrep's copies only to copies of the same irrep
(Schur's lemma): for the real-type irreps of these groups it is a matrix over the copies.
So where a layer holds fewer copies of an irrep than its input has, its output sees the
input's copies only through a projection. What each layer is counted against:

- the encoder's hidden layers, against the observation: the first one is linear in the
  observation, so a shortfall there is a hard loss (states that differ in the projection's
  null space look the same to the whole agent);
- the latent, against the observation: after the encoder's nonlinearities, so a shortfall
  is a bound on linear passage only (the headline's D8 Reacher agent has its latent 2
  copies of a sign representation that its observation has 3 of, and learns);
- the dynamics' hidden layers, against the observation and the action together: the next
  state depends on both, and its first layer is linear in (latent, action).

A regular field of a finite group holds each irrep as many times as the irrep's dimension
(3 copies of the vector representation for the octahedral and icosahedral groups), and
``agent.width_strategy`` sets how many regular fields stand for a plain width (the CPU
preset: encoder and dynamics 128, latent 32; TD-MPC's: encoder 256, dynamics 512, latent 50).
"""

from __future__ import annotations

import argparse
import collections

import escnn.nn as enn
import gymnasium
import yaml

import geomdp_envs  # noqa: F401  (registers the tasks)
from agents.nn.escnn_groups import field_type, group_for_task
from agents.nn.networks import WIDTH_STRATEGIES, regular_copies

LAYERS = ("encoder hidden", "latent", "dynamics hidden")


def irrep_copies(layout: enn.FieldType) -> collections.Counter:
    """Copies of each irrep (by escnn's id) in a field type."""
    return collections.Counter(irrep for rep in layout.representations for irrep in rep.irreps)


def shortfalls(env_id: str, kwargs: dict, group: str, width: str, encoder_dim: int,
               latent_dim: int, hidden_dim: int) -> dict[str, tuple[int, dict[tuple, tuple[int, int]]]]:
    """Per layer of ``LAYERS``: (its regular fields, {irrep: (copies it must pass on, copies
    it holds)} for every irrep it holds fewer copies of)."""
    symmetry = gymnasium.make(env_id, **kwargs).unwrapped.symmetry
    agent_group = group_for_task(group, symmetry, None, None, False)[0]
    observation = irrep_copies(field_type(agent_group, symmetry.observation))
    action = irrep_copies(field_type(agent_group, symmetry.action))
    needs = {"encoder hidden": (encoder_dim, observation), "latent": (latent_dim, observation),
             "dynamics hidden": (hidden_dim, observation + action)}
    table = {}
    for layer, (plain_width, need) in needs.items():
        fields = regular_copies(plain_width, agent_group, width)
        held = irrep_copies(agent_group.gspace.type(*[agent_group.regular] * fields))
        table[layer] = fields, {irrep: (n, held[irrep]) for irrep, n in sorted(need.items())
                                if held[irrep] < n}
    return table


def task(spec: str) -> tuple[str, dict]:
    """``GeoMDP/PointMass3D-v0:n_balls=5,target_size=0.03`` -> id and keyword arguments."""
    env_id, _, rest = spec.partition(":")
    kwargs = {}
    for item in filter(None, rest.split(",")):
        key, sep, value = item.partition("=")
        if not sep:
            raise SystemExit(f"field_capacity: error: {item!r} in {spec!r} is not KEY=VALUE")
        kwargs[key] = yaml.safe_load(value)  # as geomdp-check's --kwarg: 0.03 is a float
    return env_id, kwargs


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("tasks", nargs="+", type=task, help="ENV_ID[:KEY=VALUE,...]")
    parser.add_argument("--groups", nargs="+", required=True)
    parser.add_argument("--widths", nargs="+", default=["linear"], choices=WIDTH_STRATEGIES)
    parser.add_argument("--encoder-dim", type=int, default=128,
                        help="the plain encoder's hidden width (CPU preset: 128)")
    parser.add_argument("--latent-dim", type=int, default=32, help="the plain latent (CPU preset: 32)")
    parser.add_argument("--hidden-dim", type=int, default=128,
                        help="the plain dynamics' hidden width (CPU preset: 128)")
    args = parser.parse_args(argv)
    print("| task | group | width | " + " | ".join(f"{layer}: fields, short" for layer in LAYERS) + " |")
    print("|---|---|---|" + "---|" * len(LAYERS))
    for env_id, kwargs in args.tasks:
        name = env_id + "".join(f" {k}={v}" for k, v in kwargs.items())
        for group in args.groups:
            for width in args.widths:
                table = shortfalls(env_id, kwargs, group, width, args.encoder_dim,
                                   args.latent_dim, args.hidden_dim)
                cells = [f"{fields}, " + (", ".join(f"{irrep}: {n} vs {m}" for irrep, (n, m)
                                                    in short.items()) or "none")
                         for fields, short in table.values()]
                print(f"| {name} | {group} | {width} | {' | '.join(cells)} |", flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
