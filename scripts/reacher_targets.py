"""Which Reacher targets a run solved: success by the target's direction and distance, from its replay.

    python scripts/reacher_targets.py RUN_DIR [--from-episode 20] [--solved 100]

Reacher hard's returns are all or nothing (an episode either brings the finger into
the target and holds it there, earning hundreds, or earns almost nothing), so a run's
mean return says how often it solves a target, not which ones. This reads the
training episodes a checkpoint's replay holds (``RUN_DIR/checkpoint/replay.pt``;
``RUN_DIR/config.yaml`` gives the task's frame), puts each episode's target back in
the arena (the finger's position, from the joint angles through the task's own
kinematics, plus the observed vector to the target) and prints the share solved
per direction of the target (eight 45° sectors, measured from the arena's x axis)
and per distance from the arm's base, each with a permutation test of independence
(the chi-square statistic against 10000 shufflings of which episodes were solved,
exact enough at these small counts). A symmetric agent that solves a target solves
its rotations alike; a plain one can cover some directions and not others.
Episodes from ``--from-episode`` on count (Reacher's 1000-step episodes, so episode
20 is env step 20k: after TD-MPC's warm-up and its burst of updates).
"""

from __future__ import annotations

import argparse
from pathlib import Path

import gymnasium
import mujoco
import numpy as np
import torch
from omegaconf import OmegaConf

import geomdp_envs  # noqa: F401  (registers GeoMDP/*)

SECTORS = 8
DISTANCES = (0.05, 0.10, 0.15, 0.20)  # the task draws the target's distance in [0.05, 0.20]


def episode_targets(observation: np.ndarray, episode: np.ndarray, frame: str) -> dict[int, np.ndarray]:
    """The target's (x, y) in the arena per episode, from the episode's first observation
    (cos q1, sin q1, cos, sin of the second link's angle, dq1, dq2, to_target x, y)."""
    env = gymnasium.make("GeoMDP/Reacher-v0", frame=frame).unwrapped
    targets = {}
    for e in np.unique(episode):
        o = observation[np.flatnonzero(episode == e)[0]]
        q1 = np.arctan2(o[1], o[0])
        second = np.arctan2(o[3], o[2])
        env.data.qpos[:] = [q1, second if frame == "local" else second - q1]
        mujoco.mj_kinematics(env.model, env.data)
        targets[int(e)] = env.data.geom("finger").xpos[:2] + o[6:8]
    env.close()
    return targets


def independence_p(groups: np.ndarray, solved: np.ndarray, rng: np.random.Generator,
                   shuffles: int = 10000) -> float:
    """Permutation p-value of the chi-square statistic of solved × group."""
    def statistic(s: np.ndarray) -> float:
        table = np.array([[np.sum((groups == g) & s), np.sum((groups == g) & ~s)]
                          for g in np.unique(groups)], dtype=float)
        expected = table.sum(1, keepdims=True) * table.sum(0, keepdims=True) / table.sum()
        return float(np.sum((table - expected) ** 2 / np.where(expected > 0, expected, 1)))
    observed = statistic(solved)
    at_least = sum(statistic(rng.permutation(solved)) >= observed - 1e-12 for _ in range(shuffles))
    return (at_least + 1) / (shuffles + 1)


def report(name: str, groups: np.ndarray, labels: list[str], solved: np.ndarray,
           rng: np.random.Generator) -> None:
    cells = [f"{label} {np.sum(solved[groups == g])}/{np.sum(groups == g)}"
             for g, label in enumerate(labels)]
    print(f"by {name}: " + ", ".join(cells)
          + f"; independence p = {independence_p(groups, solved, rng):.2g}")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("run_dir", type=Path, help="a Reacher run's directory, checkpoint included")
    parser.add_argument("--from-episode", type=int, default=20,
                        help="count episodes from this one on (default 20: after TD-MPC's warm-up)")
    parser.add_argument("--solved", type=float, default=100.0,
                        help="an episode with a larger return counts as solved (default 100 of 1000)")
    args = parser.parse_args()
    replay, config = args.run_dir / "checkpoint" / "replay.pt", args.run_dir / "config.yaml"
    for path in (replay, config):
        if not path.is_file():
            raise SystemExit(f"{path}: no such file (RUN_DIR must hold config.yaml and checkpoint/replay.pt)")
    env = OmegaConf.load(config).env
    if env.name != "reacher":
        raise SystemExit(f"{args.run_dir}: a run on {env.name!r}; this reads Reacher runs only")
    data = torch.load(replay, weights_only=False)["data"]
    episode = data["episode"].numpy()
    reward = data["next", "reward"].numpy().reshape(-1)
    targets = episode_targets(data["observation"].numpy(), episode, env.frame)
    counted = [e for e in sorted(targets) if e >= args.from_episode]
    if not counted:
        raise SystemExit(f"{args.run_dir}: no episode from {args.from_episode} on "
                         f"(the replay holds episodes {min(targets)}-{max(targets)})")
    returns = np.array([reward[episode == e].sum() for e in counted])
    solved = returns > args.solved
    xy = np.array([targets[e] for e in counted])
    angle = np.degrees(np.arctan2(xy[:, 1], xy[:, 0])) % 360
    distance = np.linalg.norm(xy, axis=1)
    print(f"{args.run_dir}: episodes {counted[0]}-{counted[-1]} ({len(counted)}), "
          f"solved {solved.sum()} (return > {args.solved:g})")
    if solved.any() and (~solved).any():
        print(f"returns: solved from {returns[solved].min():.0f}, "
              f"the others up to {returns[~solved].max():.0f}")
    rng = np.random.default_rng(0)
    width = 360 // SECTORS
    report("direction", (angle // width).astype(int),
           [f"{lo}-{lo + width}°" for lo in range(0, 360, width)], solved, rng)
    report("distance", np.clip(np.digitize(distance, DISTANCES[1:-1]), 0, len(DISTANCES) - 2),
           [f"{lo:.2f}-{hi:.2f}" for lo, hi in zip(DISTANCES, DISTANCES[1:])], solved, rng)


if __name__ == "__main__":
    main()
