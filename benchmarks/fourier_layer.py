"""Hidden-layer cost: dense ``F.linear`` with the expanded matrix vs ``FourierLinear``.

For each group at its hidden width (c regular fields, the ``sqrt`` width
strategy for a plain width of 128), the same layer is applied as a dense
product with its expanded [c|G|, c|G|] matrix (what ``EquivariantLinear``
does inside an ``expansion_scope``; the expansion itself is not timed) and in
the irrep basis by ``FourierLinear``. Batch 268 is a planner call, 1280 an
update. Forward, and forward + backward (gradients for the input and the
parameters: the dense matrix as a leaf, the Fourier layer's block weights).

    python benchmarks/fourier_layer.py [--threads 1] [--min-time 0.5]
"""

from __future__ import annotations

import argparse
import platform

import torch
import torch.nn.functional as F
from timing import best_time

from agents.nn.escnn_groups import make_group
from agents.nn.fourier import FourierLinear

CASES = [("D8", 32), ("octahedral", 26), ("icosahedral", 17)]
BATCHES = (268, 1280)


def timed(fn, min_time: float) -> float:
    """Seconds per call: the best of 5 runs (``timing.best_time``)."""
    return best_time(fn, min_time, rounds=5)


def flops_per_sample(layer: FourierLinear) -> tuple[int, int]:
    """(dense, Fourier) multiply-add FLOPs of one sample."""
    size = layer.order
    dense = 2 * layer.c_out * size * layer.c_in * size
    transforms = 2 * layer.c_in * layer.fourier_in.numel() + 2 * layer.c_out * layer.fourier_out_t.numel()
    blocks = 2 * sum(g.n * g.d * g.out_size * g.in_size for g in layer.groups)
    return dense, transforms + blocks


def measure(layer: FourierLinear, batch: int, min_time: float, rounds: int = 3) -> list[float]:
    """[dense fwd, Fourier fwd, dense f+b, Fourier f+b] seconds, the best of interleaved rounds."""
    with torch.no_grad():
        weight, bias = layer.expand()
    dense_weight, dense_bias = weight.clone().requires_grad_(True), bias.clone().requires_grad_(True)
    x = torch.randn(batch, layer.in_type.size)
    xg = x.clone().requires_grad_(True)

    def dense_forward() -> None:
        with torch.no_grad():
            F.linear(x, weight, bias)

    def fourier_forward() -> None:
        with torch.no_grad():
            layer(x)

    def dense_step() -> None:
        dense_weight.grad = dense_bias.grad = xg.grad = None
        F.linear(xg, dense_weight, dense_bias).sum().backward()

    def fourier_step() -> None:
        layer.zero_grad(set_to_none=True)
        xg.grad = None
        layer(xg).sum().backward()

    fns = (dense_forward, fourier_forward, dense_step, fourier_step)
    best = [float("inf")] * len(fns)
    for _ in range(rounds):  # interleaved, so that a burst of load elsewhere hits both sides
        for k, fn in enumerate(fns):
            best[k] = min(best[k], timed(fn, min_time / rounds))
    return best


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--threads", type=int, default=1)
    parser.add_argument("--min-time", type=float, default=0.5)
    args = parser.parse_args()
    torch.set_num_threads(args.threads)
    torch.manual_seed(0)
    print(f"torch {torch.__version__}, {platform.processor() or platform.machine()}, "
          f"{args.threads} thread(s); ms per call; FLOP ratio: dense / Fourier FLOPs per sample")
    header = (f"{'group':<12}{'c':>4}{'|G|':>5}{'batch':>7}{'FLOP ratio':>11} | {'dense fwd':>10}"
              f"{'Fourier fwd':>12}{'ratio':>7} | {'dense f+b':>10}{'Fourier f+b':>12}{'ratio':>7}")
    print(header)
    print("-" * len(header))
    for name, copies in CASES:
        group = make_group(name)
        field_type = group.gspace.type(*[group.regular] * copies)
        layer = FourierLinear(field_type, field_type)
        dense_flops, fourier_flops = flops_per_sample(layer)
        for batch in BATCHES:
            dense_fwd, fourier_fwd, dense_fb, fourier_fb = measure(layer, batch, args.min_time)
            print(f"{name:<12}{copies:>4}{group.order:>5}{batch:>7}{dense_flops / fourier_flops:>10.2f}x"
                  f" | {1e3 * dense_fwd:>10.3f}{1e3 * fourier_fwd:>12.3f}{dense_fwd / fourier_fwd:>6.2f}x"
                  f" | {1e3 * dense_fb:>10.3f}{1e3 * fourier_fb:>12.3f}{dense_fb / fourier_fb:>6.2f}x",
                  flush=True)


if __name__ == "__main__":
    main()
