"""Environment steps per second: GeoMDP tasks against the same model stepped directly.

For each task, in one run: the GeoMDP env through ``gymnasium.make`` (with
Gymnasium's wrappers), the same env unwrapped, dm_control's suite env where
one exists, and a bare MuJoCo loop over the same model (set ctrl, mj_step2,
mj_step1: the floor any Python env sits on). Prints a markdown table with the
ratios GeoMDP / dm_control and GeoMDP / bare MuJoCo.

    python benchmarks/env_throughput.py [--steps 20000]
"""

from __future__ import annotations

import argparse
import functools
import os
import platform
import time

os.environ.setdefault("MUJOCO_GL", "egl")

import gymnasium  # noqa: E402
import mujoco  # noqa: E402
import numpy as np  # noqa: E402

import geomdp_envs  # noqa: E402,F401
from geomdp_envs.mujoco_env import load_triton_before_mesa  # noqa: E402

TASKS = [
    ("PointMass2D", "GeoMDP/PointMass2D-v0", {}, ("point_mass", "easy")),
    ("Reacher easy", "GeoMDP/Reacher-v0", {"difficulty": "easy"}, ("reacher", "easy")),
    ("PointMass3D 1 ball", "GeoMDP/PointMass3D-v0", {}, None),
    ("PointMass3D 5 balls", "GeoMDP/PointMass3D-v0", {"n_balls": 5}, None),
]


def rate(step, reset, actions: np.ndarray, episode: int = 1000) -> float:
    """Steps per second of ``step`` over ``actions``, resetting every ``episode`` steps."""
    reset()
    start = time.perf_counter()
    for i, a in enumerate(actions):
        if i and i % episode == 0:
            reset()
        step(a)
    return len(actions) / (time.perf_counter() - start)


def best_rate(repeats: int, step, reset, actions: np.ndarray) -> float:
    return max(rate(step, reset, actions) for _ in range(repeats))


def bare_mujoco(model: mujoco.MjModel, actions: np.ndarray) -> float:
    data = mujoco.MjData(model)

    def step(a: np.ndarray) -> None:
        data.ctrl[:] = a
        mujoco.mj_step2(model, data)
        mujoco.mj_step1(model, data)

    def reset() -> None:
        mujoco.mj_resetData(model, data)
        mujoco.mj_forward(model, data)

    return rate(step, reset, actions)


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("--steps", type=int, default=20_000)
    parser.add_argument("--repeats", type=int, default=3, help="best of this many runs")
    args = parser.parse_args()
    load_triton_before_mesa()  # dm_control.suite loads Mesa
    from dm_control import suite

    print(f"machine: {platform.processor() or platform.machine()}, {os.cpu_count()} cores; "
          f"steps per measurement: {args.steps}, best of {args.repeats}\n")
    print("| task | gymnasium.make | unwrapped | dm_control | bare MuJoCo "
          "| make / dm_control | make / bare MuJoCo |")
    print("|---|---|---|---|---|---|---|")
    for name, env_id, kwargs, dmc_task in TASKS:
        env = gymnasium.make(env_id, **kwargs)
        actions = np.random.default_rng(0).uniform(
            -1, 1, (args.steps, *env.action_space.shape)).astype(np.float32)

        base = env.unwrapped
        wrapped = best_rate(args.repeats, env.step, functools.partial(env.reset, seed=0), actions)
        unwrapped = best_rate(args.repeats, base.step, functools.partial(base.reset, seed=0), actions)
        bare = max(bare_mujoco(base.model, actions) for _ in range(args.repeats))
        if dmc_task:
            dm = suite.load(*dmc_task, task_kwargs={"random": 0})
            dm_rate = best_rate(args.repeats, dm.step, dm.reset, actions.astype(np.float64))
            dm_cells = f"{dm_rate:,.0f} | ", f"{wrapped / dm_rate:.2f} | "
        else:
            dm_cells = "– | ", "– | "
        print(f"| {name} | {wrapped:,.0f} | {unwrapped:,.0f} | {dm_cells[0]}{bare:,.0f} | "
              f"{dm_cells[1]}{wrapped / bare:.2f} |")


if __name__ == "__main__":
    main()
