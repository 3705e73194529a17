"""Which Reacher targets a run solved: success by the target's direction and distance.

    python scripts/reacher_targets.py RUN_DIR [RUN_DIR ...] [--from-step 20000] [--solved 100]

Reacher hard's returns are all or nothing (an episode either brings the finger into
the target and holds it there, earning hundreds, or earns almost nothing), so a run's
mean return says how often it solves a target, not which ones. A training episode's
start state and target are a function of the run's seed and the episode's index only
(``agents.run.trainer.training_episode_seed``), so every committed run's targets can be
drawn again without its checkpoint: this resets the run's task (``config.yaml``) with
each episode's seed as the trainer does, reads the target, pairs it with the return
``train.csv`` logged for that episode, and prints the share solved per direction of
the target (eight 45° sectors from the arena's x axis), per direction relative to the
arm's first link at the start, and per distance from the arm's base, each with a
permutation test of independence (the chi-square statistic against 10000 shufflings
of which episodes were solved, ``scipy.stats.permutation_test``: exact enough at these
small counts, where the chi-square distribution is not), and whether the
direction holes last: the second half's success in the sectors the first half never
solved, against elsewhere (summed over the runs when several are given).

Reacher's difficulty does not depend on the target's direction (the arm starts at a
uniformly drawn angle), so a direction the run never solves, where the direction
relative to the arm (which the difficulty can depend on) shows no such pattern, is a
hole in what it learned: one an O(2)-equivariant agent cannot have. Episodes starting
at ``--from-step`` or later count (default 20000: after TD-MPC's warm-up and its burst
of updates); they ran with the training noise.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np
from scipy.stats import permutation_test

from agents.options import OptionError
from agents.run.config import RunOptions
from agents.run.envs import make_gym_env, torchrl_env
from agents.run.run_tables import training_episodes
from agents.run.trainer import training_episode_seed

SECTORS = 8
DISTANCES = (0.05, 0.10, 0.15, 0.20)  # the task draws the target's distance in [0.05, 0.20]


def run_options(run_dir: Path) -> RunOptions:
    options = RunOptions.from_run_dir(run_dir)
    if options.env.name != "reacher":
        raise SystemExit(f"{run_dir}: a run on {options.env.name!r}; this reads Reacher runs only")
    return options


def training_starts(options: RunOptions, episodes: range) -> tuple[np.ndarray, np.ndarray]:
    """The first observation and the target's (x, y) of each training episode, drawn as
    the trainer draws them (``set_seed`` with the episode's seed, then a reset)."""
    gym_env = make_gym_env(options.env)
    env = torchrl_env(gym_env, options.env.action_repeat)
    observations, targets = [], []
    for episode in episodes:
        env.set_seed(training_episode_seed(options.seed, episode))
        observations.append(env.reset()["observation"].numpy())
        targets.append(gym_env.unwrapped.model.geom("target").pos[:2].copy())
    env.close()
    return np.array(observations), np.array(targets)


def episode_returns(run_dir: Path) -> tuple[np.ndarray, np.ndarray]:
    """Each logged training episode's return and the env step it started at."""
    episodes = training_episodes(run_dir)
    return (np.array([e.reward for e in episodes]),
            np.array([e.start for e in episodes], dtype=int))


def chi_square(groups: np.ndarray, solved: np.ndarray, axis: int = -1) -> np.ndarray:
    """Pearson's chi-square statistic of the solved × group table, for a batch of
    ``solved`` vectors along ``axis`` (``scipy.stats.chi2_contingency`` computes it for
    one table but refuses a table with an all-zero column: a run that solved every
    target or none)."""
    solved = np.moveaxis(np.asarray(solved, dtype=float), axis, -1)
    members = (groups[:, None] == np.unique(groups)[None, :]).astype(float)  # episode × group
    table = np.stack([solved @ members, (1 - solved) @ members], axis=-1)  # ... × group × {yes, no}
    expected = table.sum(-1, keepdims=True) * table.sum(-2, keepdims=True) / len(groups)
    return np.sum((table - expected) ** 2 / np.where(expected > 0, expected, 1), axis=(-2, -1))


def independence_p(groups: np.ndarray, solved: np.ndarray, rng: np.random.Generator,
                   shuffles: int = 10000) -> float:
    """Permutation p-value of the chi-square statistic: which episodes were solved is
    shuffled against their groups (``scipy.stats.permutation_test``, pairings)."""
    result = permutation_test((solved,), lambda s, axis: chi_square(groups, s, axis),
                              permutation_type="pairings", vectorized=True,
                              n_resamples=shuffles, alternative="greater", rng=rng)
    return float(result.pvalue)


def table(name: str, groups: np.ndarray, labels: list[str], solved: np.ndarray) -> str:
    cells = [f"{label} {np.sum(solved[groups == g])}/{np.sum(groups == g)}"
             for g, label in enumerate(labels)]
    p = independence_p(groups, solved, np.random.default_rng(0))
    return f"  by {name}: " + ", ".join(cells) + f"; independence p = {p:.2g}"


def persistence(sector: np.ndarray, solved: np.ndarray) -> np.ndarray:
    """Do the direction holes last? Among the second half of the episodes: (solved, count)
    in the sectors the first half never solved (and visited), then elsewhere."""
    first = np.arange(len(solved)) < len(solved) // 2
    holes = [k for k in np.unique(sector[first]) if not solved[first & (sector == k)].any()]
    in_hole = np.isin(sector, holes)
    return np.array([solved[~first & in_hole].sum(), (~first & in_hole).sum(),
                     solved[~first & ~in_hole].sum(), (~first & ~in_hole).sum()])


def persistence_line(counts: np.ndarray) -> str:
    return (f"second half, in the sectors the first half never solved: {counts[0]}/{counts[1]} "
            f"solved; elsewhere: {counts[2]}/{counts[3]}")


def summary(run_dir: Path, from_step: int, threshold: float) -> tuple[list[str], np.ndarray]:
    options = run_options(run_dir)
    returns, starts = episode_returns(run_dir)
    counted = np.flatnonzero(starts >= from_step)
    if not len(counted):
        raise SystemExit(f"{run_dir}: no training episode starts at env step {from_step} or later "
                         f"(train.csv ends at {starts[-1] if len(starts) else 0})")
    observations, xy = training_starts(options, range(counted[0], counted[-1] + 1))
    returns, solved = returns[counted], returns[counted] > threshold
    lines = [f"{run_dir}: episodes {counted[0]}-{counted[-1]} ({len(counted)}), "
             f"solved {solved.sum()} (return > {threshold:g})"]
    if solved.any() and (~solved).any():
        lines.append(f"  returns: solved from {returns[solved].min():.0f}, "
                     f"the others up to {returns[~solved].max():.0f}")
    width = 360 // SECTORS
    angle = np.degrees(np.arctan2(xy[:, 1], xy[:, 0])) % 360
    sector = (angle // width).astype(int)
    sectors = [f"{lo}-{lo + width}°" for lo in range(0, 360, width)]
    lines.append(table("direction", sector, sectors, solved))
    lines.append("    " + persistence_line(held := persistence(sector, solved)))
    arm = np.degrees(np.arctan2(observations[:, 1], observations[:, 0]))  # (cos q1, sin q1)
    lines.append(table("direction relative to the arm's start", ((angle - arm) % 360 // width).astype(int),
                       sectors, solved))
    distance = np.clip(np.digitize(np.linalg.norm(xy, axis=1), DISTANCES[1:-1]), 0, len(DISTANCES) - 2)
    lines.append(table("distance", distance,
                       [f"{lo:.2f}-{hi:.2f}" for lo, hi in zip(DISTANCES, DISTANCES[1:])], solved))
    return lines, held


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("run_dirs", type=Path, nargs="+", metavar="RUN_DIR",
                        help="a Reacher run's directory (config.yaml, train.csv)")
    parser.add_argument("--from-step", type=int, default=20000,
                        help="count episodes starting at this env step or later (default 20000)")
    parser.add_argument("--solved", type=float, default=100.0,
                        help="an episode with a larger return counts as solved (default 100 of 1000)")
    args = parser.parse_args()
    held = np.zeros(4, dtype=int)
    for run_dir in args.run_dirs:
        try:
            lines, counts = summary(run_dir, args.from_step, args.solved)
        except (OptionError, FileNotFoundError) as err:  # no config.yaml or train.csv
            raise SystemExit(str(err)) from None
        print("\n".join(lines), flush=True)
        held += counts
    if len(args.run_dirs) > 1:
        print(f"all {len(args.run_dirs)} runs, {persistence_line(held)}")


if __name__ == "__main__":
    main()
