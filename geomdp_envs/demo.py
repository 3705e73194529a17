"""Roll out every GeoMDP task and check its declared symmetry: ``geomdp-demo``.

The suite's smoke job: for each task, one episode with random actions from
the declared action domain, the return, and ``check_symmetry`` on the task's
exact group and on the continuous group it approximates. The last two are
Gymnasium's own MuJoCo envs with a shipped declaration (``geomdp_envs.declare``).
"""

from __future__ import annotations

import argparse
import time

import gymnasium
import numpy as np

import geomdp_envs  # noqa: F401  (registers the tasks)
from geomdp_envs import check_symmetry, declare, symmetry_of
from geomdp_envs.symmetry import to_action_box

DEMO_TASKS = [
    ("GeoMDP/PointMass2D-v0", {}),
    ("GeoMDP/PointMass3D-v0", {"n_balls": 3}),
    ("GeoMDP/PointMass3D-v0", {"walls": True, "target_size": 0.02}),
    ("GeoMDP/Reacher-v0", {"difficulty": "easy", "frame": "local"}),
    ("GeoMDP/Reacher-v0", {"difficulty": "hard", "frame": "global"}),
    ("Reacher-v5", {}),
    ("InvertedPendulum-v5", {}),
]
DECLARATIONS = {"Reacher-v5": "reacher_v5", "InvertedPendulum-v5": "inverted_pendulum_v5"}


def random_episode(env: gymnasium.Env, seed: int) -> tuple[float, int]:
    """Return and length of one episode with actions uniform in the action domain."""
    rng = np.random.default_rng(seed)
    env.reset(seed=seed)
    total, steps, done = 0.0, 0, False
    while not done:  # the domain's unit ball, scaled to the action box
        action = to_action_box(symmetry_of(env).sample_action(rng), env.action_space).astype(np.float32)
        _, reward, terminated, truncated, _ = env.step(action)
        total, steps, done = total + reward, steps + 1, terminated or truncated
    return total, steps


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--trials", type=int, default=64, help="symmetry-check trials per group")
    args = parser.parse_args(argv)
    for env_id, kwargs in DEMO_TASKS:
        env = gymnasium.make(env_id, **kwargs)
        if env_id in DECLARATIONS:
            env = declare(env, DECLARATIONS[env_id])
        sym = symmetry_of(env)
        start = time.perf_counter()
        ret, steps = random_episode(env, args.seed)
        rate = steps / (time.perf_counter() - start)
        declared = f" declared by {DECLARATIONS[env_id]}" if env_id in DECLARATIONS else ""
        print(f"\n{env_id} {kwargs}{declared}: obs {env.observation_space.shape}, "
              f"action {env.action_space.shape}; random-policy return {ret:.1f} over "
              f"{steps} steps ({rate:.0f} steps/s)")
        for group in dict.fromkeys([sym.exact_group, sym.continuous_group]):
            kind = "exact group  " if group == sym.exact_group else "approximation"
            report = check_symmetry(env, group=group, n_trials=args.trials, seed=args.seed)
            print(f"   {kind} {report}")
        env.close()


if __name__ == "__main__":
    main()
