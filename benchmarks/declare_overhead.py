"""What a symmetry declaration costs a third-party env: steps per second of Gymnasium's
``Reacher-v5`` and ``InvertedPendulum-v5`` as ``gymnasium.make`` returns them, and the
same envs wrapped by ``geomdp_envs.declare`` (which reorders every observation and
action), measured alternately in one run; prints a markdown table with the ratio.

    python benchmarks/declare_overhead.py [--steps 20000] [--repeats 3]
"""

from __future__ import annotations

import argparse
import platform
import sys
import time

import gymnasium
import numpy as np

from geomdp_envs import declare

ENVS = [("Reacher-v5", "reacher_v5"), ("InvertedPendulum-v5", "inverted_pendulum_v5")]


def rate(env: gymnasium.Env, actions: np.ndarray) -> float:
    """Steps per second over ``actions``, resetting whenever an episode ends."""
    env.reset(seed=0)
    start = time.perf_counter()
    for a in actions:
        _, _, terminated, truncated, _ = env.step(a)
        if terminated or truncated:
            env.reset()
    return len(actions) / (time.perf_counter() - start)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--steps", type=int, default=20000)
    parser.add_argument("--repeats", type=int, default=3)
    args = parser.parse_args()
    print(f"{platform.processor() or platform.machine()}, {args.steps} steps, best of "
          f"{args.repeats} (alternating)\n")
    print("| env | gymnasium.make | declare(...) | declared / make |")
    print("|---|---|---|---|")
    for env_id, declaration in ENVS:
        plain = gymnasium.make(env_id)
        declared = declare(gymnasium.make(env_id), declaration)
        actions = np.random.default_rng(0).uniform(
            plain.action_space.low, plain.action_space.high,
            (args.steps, plain.action_space.shape[0])).astype(np.float32)
        best = {"make": 0.0, "declare": 0.0}
        for repeat in range(args.repeats):
            best["make"] = max(best["make"], rate(plain, actions))
            best["declare"] = max(best["declare"], rate(declared, actions))
            print(f"{env_id}: repeat {repeat + 1}/{args.repeats}", file=sys.stderr, flush=True)
        print(f"| {env_id} | {best['make']:,.0f} | {best['declare']:,.0f} | "
              f"{best['declare'] / best['make']:.2f} |")


if __name__ == "__main__":
    main()
