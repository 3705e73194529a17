"""TorchRL's stock SAC on a GeoMDP task, with symmetry data augmentation.

TorchRL knows nothing of GeoMDP: the env is a ``GymEnv``, the agent TorchRL's own
``SACLoss``, and the only GeoMDP-specific piece is the replay buffer's transform,
``SymmetryAugment``, which moves every sampled transition by a random element of
the task's exact symmetry group.

    python examples/torchrl_sac_augmented.py --env GeoMDP/PointMass2D-v0 --steps 20000 --augment
    python examples/torchrl_sac_augmented.py --steps 20000    # plain SAC, for comparison

A progress bar shows the environment steps, the last training episode's return and the
speed; torch uses one thread unless ``--threads`` says otherwise, so two copies side by
side (augmented and plain) each keep a core.
"""

from __future__ import annotations

import argparse
import time

import torch
from tensordict.nn import NormalParamExtractor, TensorDictModule
from torch import nn
from torchrl.collectors import Collector
from torchrl.data import LazyTensorStorage, TensorDictReplayBuffer
from torchrl.envs import DoubleToFloat, GymEnv, TransformedEnv
from torchrl.envs.utils import ExplorationType, set_exploration_type
from torchrl.modules import MLP, ProbabilisticActor, TanhNormal, ValueOperator
from torchrl.objectives import SACLoss, SoftUpdate
from tqdm import tqdm

import geomdp_envs  # noqa: F401  (registers the GeoMDP tasks with Gymnasium)
from geomdp_envs.torchrl_augment import SymmetryAugment


def make_env(env_id: str, seed: int) -> TransformedEnv:
    env = TransformedEnv(GymEnv(env_id), DoubleToFloat())  # MuJoCo observations are float64
    env.set_seed(seed)
    return env


def make_actor_and_critic(env: TransformedEnv, hidden: int = 256):
    n_obs = env.observation_spec["observation"].shape[-1]
    n_act = env.action_spec.shape[-1]
    actor = ProbabilisticActor(
        TensorDictModule(nn.Sequential(MLP(n_obs, 2 * n_act, num_cells=[hidden, hidden]),
                                       NormalParamExtractor()),
                         in_keys=["observation"], out_keys=["loc", "scale"]),
        in_keys=["loc", "scale"], spec=env.action_spec, distribution_class=TanhNormal,
        distribution_kwargs={"low": env.action_spec.space.low, "high": env.action_spec.space.high})
    qvalue = ValueOperator(MLP(n_obs + n_act, 1, num_cells=[hidden, hidden]),
                           in_keys=["observation", "action"])
    return actor, qvalue


def main(argv: list[str] | None = None) -> float:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--env", default="GeoMDP/PointMass2D-v0")
    parser.add_argument("--steps", type=int, default=20_000)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--augment", action="store_true", help="augment replay samples by symmetry")
    parser.add_argument("--batch-size", type=int, default=256)
    parser.add_argument("--eval-episodes", type=int, default=5)
    parser.add_argument("--threads", type=int, default=1, help="torch threads (default 1)")
    parser.add_argument("--no-progress", action="store_true", help="no progress bar")
    args = parser.parse_args(argv)
    torch.set_num_threads(args.threads)
    torch.manual_seed(args.seed)

    env = make_env(args.env, args.seed)
    actor, qvalue = make_actor_and_critic(env)
    loss = SACLoss(actor, qvalue, num_qvalue_nets=2, loss_function="l2", delay_qvalue=True)
    loss.make_value_estimator(gamma=0.99)
    target_update = SoftUpdate(loss, tau=0.005)
    optimizer = torch.optim.Adam(loss.parameters(), lr=3e-4)

    transform = None
    if args.augment:
        symmetry = env.base_env.unwrapped.symmetry  # GymEnv forwards to the gymnasium env
        transform = SymmetryAugment(symmetry, seed=args.seed)
        print(f"augmenting with {transform.group} (exact group of the task: {symmetry.exact_group})")
    buffer = TensorDictReplayBuffer(storage=LazyTensorStorage(args.steps), batch_size=args.batch_size,
                                    transform=transform)
    frames_per_batch = min(100, args.steps)
    init_random = frames_per_batch * max(1, min(1000, args.steps // 2) // frames_per_batch)
    # a feed-forward policy needs no InitTracker/primers: tell the collector not to add any
    collector = Collector(env, actor, frames_per_batch=frames_per_batch, total_frames=args.steps,
                          init_random_frames=init_random, auto_register_policy_transforms=False)
    bar = tqdm(total=args.steps, unit="step", desc="env steps", disable=args.no_progress)
    sampled = moved = 0
    episode_return, last_return, start = 0.0, float("nan"), time.perf_counter()
    for data in collector:
        buffer.extend(data.reshape(-1))
        for reward, done in zip(data["next", "reward"].reshape(-1).tolist(),
                                data["next", "done"].reshape(-1).tolist()):
            episode_return += reward
            if done:
                last_return, episode_return = episode_return, 0.0
        bar.update(data.numel())
        bar.set_postfix_str(f"episode return {last_return:.1f}, "
                            f"{bar.n / (time.perf_counter() - start):.0f} steps/s")
        if len(buffer) < init_random:
            continue
        for _ in range(data.numel()):  # one update per environment step
            batch = buffer.sample()
            if transform is not None:  # count the samples the transform moved
                stored = buffer.storage[batch["index"]]["observation"]
                sampled += batch.shape[0]
                moved += int((batch["observation"] != stored).any(-1).sum())
            losses = loss(batch)
            total = losses["loss_actor"] + losses["loss_qvalue"] + losses["loss_alpha"]
            optimizer.zero_grad()
            total.backward()
            optimizer.step()
            target_update.step()
    bar.close()
    collector.shutdown()

    eval_env = make_env(args.env, args.seed + 10_000)
    with set_exploration_type(ExplorationType.DETERMINISTIC), torch.no_grad():
        returns = torch.tensor([eval_env.rollout(10_000, actor)["next", "reward"].sum().item()
                                for _ in range(args.eval_episodes)])
    mean, std = returns.mean().item(), returns.std(correction=0).item()
    if transform is not None:
        print(f"augmentation moved {moved} of {sampled} sampled transitions")
    print(f"{args.env}: return {mean:.1f} +- {std:.1f} over {args.eval_episodes} episodes "
          f"after {args.steps} steps ({'augmented' if args.augment else 'plain'} TorchRL SAC)")
    return mean


if __name__ == "__main__":
    main()
