"""Cost of equivariant networks relative to the plain network, measured side by side.

For each group and width strategy, TD-MPC's dynamics network (latent + action
-> latent, two hidden layers of plain width W) is built from a task's
declaration, and compared with the plain network of the same config in the
same run:

* free parameters;
* training step: forward + backward at batch 256 (escnn expands the weights
  from their basis coefficients on every call, as in training);
* inference: forward at batch 512 with the cached expanded weights (what the
  planner calls thousands of times per action);
* achieved GFLOP/s of the inference forward (2 * batch * sum of in x out of the
  expanded linear layers, over its time), plain and equivariant.

    python benchmarks/network_cost.py [--width 256] [--threads 1]
"""

from __future__ import annotations

import argparse
import os
import platform

import gymnasium
import torch
from timing import best_time

import geomdp_envs  # noqa: F401
from agents import Architecture, NetworkConfig, build_networks
from agents.nn.layers import EquivariantLinear
from agents.nn.layout import layout_size

TASKS = {2: ("GeoMDP/PointMass2D-v0", {}), 3: ("GeoMDP/PointMass3D-v0", {})}
GROUPS = [("D4", 2), ("D8", 2), ("octahedral", 3), ("icosahedral", 3)]


def timed(fn, min_time: float = 0.5) -> float:  # noqa: ANN001
    """Seconds per call: the best of 3 runs (``timing.best_time``)."""
    return best_time(fn, min_time, rounds=3)


def measure(net: torch.nn.Module) -> dict[str, float]:
    in_size = layout_size(net.in_layout)
    x_train, x_infer = torch.randn(256, in_size), torch.randn(512, in_size)

    def train_step() -> None:
        net.zero_grad(set_to_none=True)
        net(x_train).square().mean().backward()

    def inference() -> None:
        with torch.no_grad():
            net(x_infer)

    linear_sizes = [(m.weight.shape if isinstance(m, torch.nn.Linear) else m.expanded()[0].shape)
                    for m in net.net if isinstance(m, (torch.nn.Linear, EquivariantLinear))]
    flops = 2 * 512 * sum(o * i for o, i in linear_sizes)
    infer = timed(inference)
    return {"params": sum(p.numel() for p in net.parameters()), "train": timed(train_step),
            "infer": infer, "gflops": flops / infer / 1e9,
            "hidden": linear_sizes[0][0]}


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("--width", type=int, default=256, help="plain hidden width W")
    parser.add_argument("--latent", type=int, default=64)
    parser.add_argument("--threads", type=int, default=1)
    args = parser.parse_args()
    torch.set_num_threads(args.threads)
    torch.manual_seed(0)
    print(f"machine: {platform.machine()}, {os.cpu_count()} cores, torch {torch.__version__}, "
          f"{args.threads} thread(s); dynamics MLP, plain width {args.width}, latent "
          f"{args.latent}, 2 hidden layers\n")
    print("| group | strategy | hidden channels | params (x plain) | train fwd+bwd @256 "
          "(x plain) | inference fwd @512 (x plain) | GFLOP/s equivariant / plain |")
    print("|---|---|---|---|---|---|---|")
    plain_cache = {}
    sizes = Architecture(hidden_dim=args.width, latent_dim=args.latent)
    for group, dim in GROUPS:
        sym = gymnasium.make(TASKS[dim][0], **TASKS[dim][1]).unwrapped.symmetry
        if dim not in plain_cache:
            cfg = NetworkConfig(networks=sizes)
            plain_cache[dim] = measure(build_networks(cfg, sym).dynamics)
        plain = plain_cache[dim]
        for strategy in ("sqrt", "linear"):
            cfg = NetworkConfig(group=group, width_strategy=strategy, networks=sizes)
            eq = measure(build_networks(cfg, sym).dynamics)
            print(f"| {group} | {strategy} | {eq['hidden']} (plain {plain['hidden']}) "
                  f"| {eq['params']:,} ({eq['params'] / plain['params']:.2f}) "
                  f"| {eq['train'] * 1e3:.2f} ms ({eq['train'] / plain['train']:.1f}) "
                  f"| {eq['infer'] * 1e3:.2f} ms ({eq['infer'] / plain['infer']:.1f}) "
                  f"| {eq['gflops']:.1f} / {plain['gflops']:.1f} |")


if __name__ == "__main__":
    main()
