"""Whether an equivariant agent's layers can carry the task's state: copies of each irrep
in the encoder's hidden layers, the latent and the dynamics' hidden layers, against what
each must pass on (``agents.nn.capacity``; RESULTS.md, issue 38).

    .venv/bin/python scripts/field_capacity.py GeoMDP/PointMass3D-v0:n_balls=5 \\
        --groups octahedral icosahedral --widths linear sqrt --encoder-dim 128 --latent-dim 32

The defaults are the CPU preset's widths (encoder and dynamics 128, latent 32); TD-MPC's are
encoder 256, dynamics 512, latent 50. ``geomdp-train`` warns when the encoder's are short.
"""

from __future__ import annotations

import argparse

import gymnasium

import geomdp_envs  # noqa: F401  (registers the tasks)
from agents.nn.capacity import LAYERS, shortfalls
from agents.nn.networks import WIDTH_STRATEGIES, Architecture, NetworkConfig
from geomdp_envs.check_cli import parse_env_kwarg


def task(spec: str) -> tuple[str, dict]:
    """``GeoMDP/PointMass3D-v0:n_balls=5,target_size=0.03`` -> id and keyword arguments."""
    env_id, _, rest = spec.partition(":")
    kwargs = {}
    for item in filter(None, rest.split(",")):
        try:
            key, value = parse_env_kwarg(item)
        except ValueError as error:
            raise SystemExit(f"field_capacity: error: in {spec!r}: {error}") from None
        kwargs[key] = value
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
        symmetry = gymnasium.make(env_id, **kwargs).unwrapped.symmetry
        for group in args.groups:
            for width in args.widths:
                config = NetworkConfig(group=group, width_strategy=width, networks=Architecture(
                    hidden_dim=args.hidden_dim, latent_dim=args.latent_dim, encoder_dim=args.encoder_dim))
                table = shortfalls(config, symmetry)
                cells = [f"{fields}, " + (", ".join(f"{irrep}: {n} vs {m}" for irrep, (n, m)
                                                    in short.items()) or "none")
                         for fields, short in table.values()]
                print(f"| {name} | {group} | {width} | {' | '.join(cells)} |", flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
