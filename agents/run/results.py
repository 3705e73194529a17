"""Runs as data: the run directories (``eval.csv`` and ``config.yaml``) under some
paths, each with its options and evaluation returns (``Run``), grouped by the options
in which they differ (``group_runs``).

Torch-free, as ``run_tables``: ``geomdp-plot`` reads runs without loading the networks'
libraries.
"""

from __future__ import annotations

import csv
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from omegaconf import OmegaConf

from agents.run.nested import flatten, with_added_later

IGNORED_KEYS = ("seed", "train.progress", "train.threads", "logger", "device",
                "train.eval_every", "train.eval_episodes", "train.eval_noisy_episodes",
                "train.checkpoint_every", "train.video")


@dataclass
class Run:
    path: Path
    options: dict[str, object]
    steps: np.ndarray
    returns: np.ndarray
    noisy_returns: np.ndarray  # with the training noise (NaN where not logged)


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


def group_runs(runs: list[Run], ignored: tuple[str, ...] = ()) -> dict[str, list[Run]]:
    """Runs keyed by the options that differ between them (seed and display options
    aside, and ``ignored``: e.g. an option added later whose default changes nothing)."""
    keys = sorted({k for r in runs for k in r.options
                   if not k.startswith(IGNORED_KEYS + tuple(ignored))
                   and len({str(x.options.get(k)) for x in runs}) > 1})
    groups: dict[str, list[Run]] = {}
    for r in runs:
        label = ", ".join(f"{k.split('.')[-1]}={r.options.get(k)}" for k in keys) or "all runs"
        groups.setdefault(label, []).append(r)
    return groups


def seed_order(seed: object) -> str:
    """Sort key: seeds in numeric order (2 before 10) whether they are ints or strings."""
    return str(seed).zfill(12)
