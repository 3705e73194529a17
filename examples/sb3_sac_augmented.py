"""Stable-Baselines3 SAC on a GeoMDP task, with symmetry data augmentation.

SB3 knows nothing of GeoMDP: the env comes from ``gymnasium.make``, and the only
GeoMDP-specific piece is a replay buffer that moves every sampled transition by
a random element of the task's symmetry group (``augment_transitions``).

    python examples/sb3_sac_augmented.py --env GeoMDP/PointMass2D-v0 --steps 20000
    python examples/sb3_sac_augmented.py --no-augment    # plain SAC, for comparison
"""

from __future__ import annotations

import argparse

import gymnasium
import numpy as np
from stable_baselines3 import SAC
from stable_baselines3.common.buffers import ReplayBuffer
from stable_baselines3.common.evaluation import evaluate_policy

import geomdp_envs
from geomdp_envs import Symmetry, augment_transitions


class SymmetricReplayBuffer(ReplayBuffer):
    """SB3's replay buffer, returning each sampled transition moved by a random g.

    Counts the transitions it returned (``sampled``) and those the augmentation
    changed (``moved``: all but those drawn with the identity, or fixed by g).
    """

    def __init__(self, *args, symmetry: Symmetry, seed: int = 0, **kwargs) -> None:
        super().__init__(*args, **kwargs)
        self.symmetry = symmetry
        self.rng = np.random.default_rng(seed)
        self.sampled = self.moved = 0

    def sample(self, batch_size: int, env=None):  # noqa: ANN001, ANN201
        batch = super().sample(batch_size, env)
        obs, actions, next_obs = augment_transitions(
            self.symmetry, batch.observations, batch.actions, batch.next_observations, self.rng)
        changed = ((obs != batch.observations).any(-1) | (actions != batch.actions).any(-1)
                   | (next_obs != batch.next_observations).any(-1))
        self.sampled += len(changed)
        self.moved += int(changed.sum())
        return batch._replace(observations=obs, actions=actions, next_observations=next_obs)


def main(argv: list[str] | None = None) -> float:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--env", default="GeoMDP/PointMass2D-v0")
    parser.add_argument("--steps", type=int, default=20_000)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--no-augment", action="store_true")
    parser.add_argument("--eval-episodes", type=int, default=5)
    args = parser.parse_args(argv)

    env = gymnasium.make(args.env)
    buffer = {}
    if not args.no_augment:
        symmetry = env.unwrapped.symmetry
        group = geomdp_envs.default_augmentation_group(symmetry)
        print(f"augmenting with {group} (exact group of the task: {symmetry.exact_group})")
        buffer = {"replay_buffer_class": SymmetricReplayBuffer,
                  "replay_buffer_kwargs": {"symmetry": symmetry, "seed": args.seed}}
    model = SAC("MlpPolicy", env, seed=args.seed, learning_starts=min(1000, args.steps // 2),
                device="cpu", verbose=0, **buffer)
    model.learn(total_timesteps=args.steps)
    if not args.no_augment:
        replay = model.replay_buffer
        print(f"augmentation moved {replay.moved} of {replay.sampled} sampled transitions")
    mean, std = evaluate_policy(model, env, n_eval_episodes=args.eval_episodes)
    print(f"{args.env}: return {mean:.1f} +- {std:.1f} over {args.eval_episodes} episodes "
          f"after {args.steps} steps ({'plain' if args.no_augment else 'augmented'} SAC)")
    return float(mean)


if __name__ == "__main__":
    main()
