"""How many copies of each irrep an equivariant agent's latent state holds, against the
observation's: where the latent holds fewer, no linear map can pass the observation's
fields of that irrep through it, and only the nonlinear layers can (RESULTS.md, issue 38).

    .venv/bin/python scripts/latent_capacity.py GeoMDP/PointMass3D-v0:n_balls=5 \\
        --groups octahedral icosahedral --widths linear sqrt --latent-dim 32

A regular field of a finite group holds each irrep as many times as the irrep's dimension
(3 copies of the vector representation for the octahedral and icosahedral groups), and
``agent.width_strategy`` sets how many regular fields stand for ``latent_dim`` plain units.
The count is a necessary condition for linear layers, not for the agent: the headline's D8
Reacher agent holds 2 copies of a sign representation that its observation has 3 of.
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


def irrep_copies(layout: enn.FieldType) -> collections.Counter:
    """Copies of each irrep (by escnn's id) in a field type."""
    return collections.Counter(irrep for rep in layout.representations for irrep in rep.irreps)


def shortfalls(env_id: str, kwargs: dict, group: str, width: str,
               latent_dim: int) -> tuple[int, dict[tuple, tuple[int, int]]]:
    """(regular fields in the latent, {irrep: (copies in the observation, in the latent)}
    for every irrep the latent holds fewer copies of)."""
    symmetry = gymnasium.make(env_id, **kwargs).unwrapped.symmetry
    agent_group = group_for_task(group, symmetry, None, None, False)[0]
    fields = regular_copies(latent_dim, agent_group, width)
    observation = irrep_copies(field_type(agent_group, symmetry.observation))
    latent = irrep_copies(agent_group.gspace.type(*[agent_group.regular] * fields))
    return fields, {irrep: (n, latent[irrep]) for irrep, n in sorted(observation.items())
                    if latent[irrep] < n}


def task(spec: str) -> tuple[str, dict]:
    """``GeoMDP/PointMass3D-v0:n_balls=5,target_size=0.03`` -> id and keyword arguments."""
    env_id, _, rest = spec.partition(":")
    kwargs = {}
    for item in filter(None, rest.split(",")):
        key, sep, value = item.partition("=")
        if not sep:
            raise SystemExit(f"latent_capacity: error: {item!r} in {spec!r} is not KEY=VALUE")
        kwargs[key] = yaml.safe_load(value)  # as geomdp-check's --kwarg: 0.03 is a float
    return env_id, kwargs


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("tasks", nargs="+", type=task, help="ENV_ID[:KEY=VALUE,...]")
    parser.add_argument("--groups", nargs="+", required=True)
    parser.add_argument("--widths", nargs="+", default=["linear"], choices=WIDTH_STRATEGIES)
    parser.add_argument("--latent-dim", type=int, default=32, help="the plain latent (CPU preset: 32)")
    args = parser.parse_args(argv)
    print("| task | group | width | latent fields | irreps short: (observation, latent) copies |")
    print("|---|---|---|---|---|")
    for env_id, kwargs in args.tasks:
        name = env_id + "".join(f" {k}={v}" for k, v in kwargs.items())
        for group in args.groups:
            for width in args.widths:
                fields, short = shortfalls(env_id, kwargs, group, width, args.latent_dim)
                text = ", ".join(f"{irrep}: {n} vs {m}" for irrep, (n, m) in short.items())
                print(f"| {name} | {group} | {width} | {fields} | {text or 'none'} |", flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
