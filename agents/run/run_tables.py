"""A run's tables, ``eval.csv``, ``train.csv`` and ``sessions.csv``: their columns, the
append-only file that writes them, and the readers that summarise a finished run.

Torch-free on purpose: plotting and the run queue read runs without loading the
networks' libraries.
"""

from __future__ import annotations

import csv
from dataclasses import dataclass
from pathlib import Path


class RunLogError(ValueError):
    """A run directory's logs that this version cannot continue."""


def read_header(path: Path) -> list[str] | None:
    """A CSV file's header row (None: no file)."""
    if not path.exists():
        return None
    with path.open(newline="") as f:
        return next(csv.reader(f), [])


class CsvTable:
    """Append-only CSV with a fixed header, flushed after every row. Constructing one
    writes nothing: the header is written with the first row. ``grows``: a file whose
    header is a leading part of ``columns`` (made by a version that logged fewer
    columns) is accepted, and rewritten with the full header at the next append."""

    def __init__(self, path: Path, columns: list[str], grows: bool = False) -> None:
        self.path, self.columns = path, columns
        header = self.header()
        if header is not None and header != columns and not (grows and columns[:len(header)]
                                                              == header):
            raise RunLogError(f"{path} has other columns than this version writes "
                              "(made by an older version?): use another hydra.run.dir")

    def header(self) -> list[str] | None:
        """The file's header row (None: no file yet)."""
        return read_header(self.path)

    def append(self, row: dict[str, float]) -> None:
        if self.header() != self.columns:  # new, empty, or written with fewer columns
            self._rewrite(self.rows())
        with self.path.open("a", newline="") as f:
            csv.writer(f).writerow([row.get(c, "") for c in self.columns])

    def _rewrite(self, rows: list[dict[str, str]]) -> None:
        with self.path.open("w", newline="") as f:
            writer = csv.DictWriter(f, fieldnames=self.columns, restval="")
            writer.writeheader()
            writer.writerows(rows)

    def rows(self) -> list[dict[str, str]]:
        """The rows written so far (none before the first)."""
        if not self.path.exists():
            return []
        with self.path.open(newline="") as f:
            return list(csv.DictReader(f))

    def truncate_after(self, env_step: int) -> int:
        """Drop rows with ``env_step`` beyond the given one; returns how many."""
        if not self.path.exists():
            return 0  # nothing written: nothing to drop, and nothing to create
        rows = self.rows()
        kept = [r for r in rows if int(float(r["env_step"])) <= env_step]
        self._rewrite(kept)
        return len(rows) - len(kept)


# episode_reward: planner without exploration noise (TD-MPC's evaluation);
# noisy_episode_reward: with the training noise at that step (the training episodes' setting);
# q_start, discounted_return, q_return_corr: Q at the noiseless episodes' first states against
# the discounted returns they earned (td_invariants.value_at_start; logs before 2026-12-06
# lack them).
EVAL_COLUMNS = ["env_step", "agent_step", "episode", "wall_time", "episode_reward",
                "episode_reward_std", "eval_episodes", "noisy_episode_reward",
                "noisy_episode_reward_std", "noisy_eval_episodes", "q_start",
                "discounted_return", "q_return_corr"]
# q_mean / td_target_mean: the TD learner's health (they grow toward the return scale);
# target_lag: |online - target| / |online| over all parameters (the target must track).
TRAIN_COLUMNS = ["env_step", "agent_step", "episode", "wall_time", "updates", "loss_model",
                 "loss_pi", "consistency", "reward_error", "value_error", "q_mean",
                 "td_target_mean", "target_lag", "model_grad_norm", "policy_grad_norm",
                 "episode_reward", "steps_per_second"]


# One row per start or resume: which code, libraries and machine made which steps (a run
# resumed in another session may run other code; float rounding differs between versions
# and CPUs), whether the task's declaration was checked, and the options this session
# changed from config.yaml (budgets and display only: the rest must not change).
SESSION_COLUMNS = ["env_step", "started", "git_commit", "git_dirty", "torch", "escnn",
                   "torchrl", "host", "geomdp", "numpy", "mujoco", "dm_control", "gymnasium",
                   "cpu", "torch_threads", "symmetry_check", "changed_options"]


def wall_minutes(run_dir: Path) -> float | None:
    """A run's wall time over all its sessions (evaluations included), in minutes, from
    its tables (``wall_time`` accumulates across resumes); None when nothing is logged."""
    times = []
    for table in ("train.csv", "eval.csv"):
        if (run_dir / table).exists():
            with (run_dir / table).open(newline="") as f:
                times += [float(r["wall_time"]) for r in csv.DictReader(f) if r.get("wall_time")]
    return max(times) / 60 if times else None


@dataclass(frozen=True)
class TrainingEpisode:
    """One training episode as ``train.csv`` logs it: the env steps it started and
    ended at, and its return (noisy actions and warm-up included)."""

    start: int
    end: int
    reward: float


def training_episodes(run_dir: Path) -> list[TrainingEpisode]:
    """A run's training episodes in order. ``train.csv`` writes one row per episode, at
    its end, so each episode starts where the previous one ended."""
    path = run_dir / "train.csv"
    if not path.is_file():
        raise FileNotFoundError(f"{path}: no such file (a run directory holds config.yaml "
                                "and train.csv)")
    with path.open(newline="") as f:
        rows = list(csv.DictReader(f))
    ends = [int(float(row["env_step"])) for row in rows]
    return [TrainingEpisode(start, end, float(row["episode_reward"]))
            for start, end, row in zip([0] + ends[:-1], ends, rows)]


def evaluation_share(run_dir: Path) -> float | None:
    """The share of a run's wall time spent evaluating (the evaluation at step 0 aside),
    from its tables: training time is each episode's env steps over its logged
    ``steps_per_second`` (collection and updates), the rest of ``wall_time`` is
    evaluation. None for logs without those columns."""
    total = wall_minutes(run_dir)
    try:
        with (run_dir / "train.csv").open(newline="") as f:
            rows = [r for r in csv.DictReader(f) if r.get("steps_per_second")]
    except OSError:
        return None
    if not total or not rows:
        return None
    training, previous = 0.0, 0
    for row in rows:
        step = int(float(row["env_step"]))
        training += (step - previous) / float(row["steps_per_second"])
        previous = step
    return max(0.0, 1 - training / (60 * total))


def last_value_check(run_dir: Path) -> dict[str, float] | None:
    """The last evaluation's ``q_start``, ``discounted_return`` and ``q_return_corr``
    (``td_invariants.value_at_start``); None for logs without them."""
    try:
        with (run_dir / "eval.csv").open(newline="") as f:
            rows = [r for r in csv.DictReader(f) if r.get("q_start")]
    except OSError:
        return None
    if not rows:
        return None
    return {k: float(rows[-1][k]) for k in ("q_start", "discounted_return", "q_return_corr")}


# Columns that measure the machine, not the run: two runs of the same code, seed and options
# differ only there (on one machine; RESULTS.md, "What reproduces where").
WALL_CLOCK_COLUMNS = ("wall_time", "steps_per_second")


def rows_without_wall_clock(path: Path) -> list[dict[str, str]]:
    """A run's CSV table without the wall-clock columns: what two runs of the same code,
    seed and options on one machine must share to the last digit."""
    with Path(path).open(newline="") as f:
        return [{k: v for k, v in row.items() if k not in WALL_CLOCK_COLUMNS}
                for row in csv.DictReader(f)]


def added_columns(run_a: Path, run_b: Path, names: tuple[str, str] = ("a", "b")) -> list[str]:
    """The columns of ``eval.csv`` and ``train.csv`` that only one of two runs writes (a
    version that logs more), as ``eval.csv: q_start (only in b)``, a run named by ``names``."""
    added = []
    for table in ("eval.csv", "train.csv"):
        a, b = (set(read_header(run_dir / table) or ()) for run_dir in (run_a, run_b))
        added += [f"{table}: {column} (only in {name})"
                  for name, only in zip(names, (a - b, b - a)) for column in sorted(only)]
    return added


def differing_tables(run_a: Path, run_b: Path) -> list[str]:
    """Which of two run directories' ``eval.csv`` and ``train.csv`` differ in any column
    both write but the wall-clock ones, each with where it first does (``train.csv: from
    env step 2000, loss_model, q_mean``); empty when the runs are the same to the last
    digit. A column only one writes is not compared (``added_columns`` names it)."""
    differing = []
    for table in ("eval.csv", "train.csv"):
        a, b = (rows_without_wall_clock(run_dir / table) for run_dir in (run_a, run_b))
        shared = set(a[0] if a else ()) & set(b[0] if b else ())
        a, b = ([{k: v for k, v in row.items() if k in shared} for row in rows] for rows in (a, b))
        if a == b:
            continue
        first = next((i for i, (x, y) in enumerate(zip(a, b)) if x != y), None)
        if first is None:
            differing.append(f"{table}: {len(a)} rows against {len(b)}")
        else:
            columns = sorted(k for k in a[first].keys() | b[first].keys()
                             if a[first].get(k) != b[first].get(k))
            differing.append(f"{table}: from env step {a[first].get('env_step')}, "
                             f"{', '.join(columns)}")
    return differing
