"""Runs as data: the run directories (``eval.csv`` and ``config.yaml``) under some
paths, each with its options and evaluation returns (``Run``), grouped by the options
in which they differ (``group_runs``); and published per-seed results to compare
against (``read_published``).

Torch-free, as ``run_tables``: ``geomdp-plot`` reads runs without loading the networks'
libraries.
"""

from __future__ import annotations

import csv
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np
from omegaconf import OmegaConf

from agents.run.nested import flatten, with_added_later

IGNORED_KEYS = ("seed", "train.progress", "train.threads", "logger", "device",
                "train.eval_every", "train.eval_episodes", "train.eval_noisy_episodes",
                "train.eval_noise",
                "train.checkpoint_every", "train.video")


@dataclass
class Run:
    path: Path
    options: dict[str, object]
    steps: np.ndarray
    returns: np.ndarray
    noisy_returns: np.ndarray  # with the training noise (NaN where not logged)

    def from_step(self, step: int) -> Run:
        """The run with only its evaluations at ``step`` or later (e.g. to compare agents
        after warm-ups of different lengths, whose early evaluations are random play)."""
        keep = self.steps >= step
        return replace(self, steps=self.steps[keep], returns=self.returns[keep],
                       noisy_returns=self.noisy_returns[keep])


def find_runs(paths: list[Path]) -> list[Run]:
    runs = []
    for root in paths:
        for eval_csv in sorted(root.rglob("eval.csv")):
            config = eval_csv.parent / "config.yaml"
            if not config.exists():
                continue
            with eval_csv.open(newline="") as f:
                rows = list(csv.DictReader(f))
            if not rows:
                continue
            options = with_added_later(flatten(OmegaConf.to_container(OmegaConf.load(config),
                                                                      resolve=False)))
            runs.append(Run(eval_csv.parent, options,
                            np.array([int(float(r["env_step"])) for r in rows]),
                            np.array([float(r["episode_reward"]) for r in rows]),
                            np.array([float(r.get("noisy_episode_reward") or "nan") for r in rows])))
    return runs


def varying_options(runs: list[Run], ignored: tuple[str, ...] = ()) -> list[str]:
    """The options whose value differs between ``runs``, but those starting with one of
    ``ignored``, sorted."""
    return sorted({k for r in runs for k in r.options
                   if not k.startswith(ignored) and len({str(x.options.get(k)) for x in runs}) > 1})


def group_runs(runs: list[Run], ignored: tuple[str, ...] = ()) -> dict[str, list[Run]]:
    """Runs keyed by the options that differ between them (seed and display options
    aside, and ``ignored``: e.g. an option added later whose default changes nothing)."""
    keys = varying_options(runs, IGNORED_KEYS + tuple(ignored))
    groups: dict[str, list[Run]] = {}
    for r in runs:
        label = ", ".join(f"{k.split('.')[-1]}={r.options.get(k)}" for k in keys) or "all runs"
        groups.setdefault(label, []).append(r)
    return groups


def seed_order(seed: object) -> str:
    """Sort key: seeds in numeric order (2 before 10) whether they are ints or strings."""
    return str(seed).zfill(12)


@dataclass
class Published:
    """Another project's per-seed evaluation returns on one task (e.g. TD-MPC's own runs
    of reacher-hard), read from a CSV with columns algorithm, task, seed, env_step,
    episode_reward."""

    algorithm: str
    task: str
    points: dict[int, list[tuple[str, float]]]  # env step -> [(seed, return)]

    def until(self, last_step: float) -> dict[int, list[tuple[str, float]]]:
        """The points at env steps up to ``last_step`` (the longest run compared)."""
        return {step: values for step, values in self.points.items() if step <= last_step}


def read_published(spec: str) -> Published:
    """``PATH:ALGORITHM:TASK`` (e.g. ``results/published/reacher.csv:tdmpc:reacher-hard``)."""
    path, algorithm, task = (spec.rsplit(":", 2) + ["", ""])[:3]
    if not algorithm or not task:
        raise ValueError(f"--published {spec!r} is not PATH:ALGORITHM:TASK "
                         "(e.g. results/published/reacher.csv:tdmpc:reacher-hard)")
    try:
        with open(path, newline="") as f:
            rows = list(csv.DictReader(f))
    except OSError as err:
        raise ValueError(f"--published {spec!r}: cannot read {path} ({err.strerror})") from None
    missing = {"algorithm", "task", "seed", "env_step", "episode_reward"} - set(rows[0] if rows else ())
    if missing:
        raise ValueError(f"--published {spec!r}: {path} lacks the columns {sorted(missing)}")
    points: dict[int, list[tuple[str, float]]] = {}
    for row in rows:
        if row["algorithm"] == algorithm and row["task"] == task:
            points.setdefault(int(row["env_step"]), []).append(
                (row["seed"], float(row["episode_reward"])))
    if not points:
        pairs = sorted({f"{r['algorithm']}:{r['task']}" for r in rows})
        raise ValueError(f"--published {spec!r}: no rows of {algorithm} on {task} in {path}; "
                         f"valid: {', '.join(pairs)}")
    return Published(algorithm, task, {step: sorted(v, key=lambda sv: seed_order(sv[0]))
                                       for step, v in sorted(points.items())})
