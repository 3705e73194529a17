"""A run's logs: ``eval.csv`` and ``train.csv`` tables, plus TorchRL's loggers.

The two tables are the run's record (one row per evaluation / per update
round, fixed columns), read by plotting and by resume: on resume, rows logged
after the last checkpoint are dropped, since the run will log them again.
Every row is also sent to TorchRL's ``CSVLogger`` (one file per scalar) and,
when the ``tensorboard`` package is installed, its ``TensorboardLogger``.
"""

from __future__ import annotations

import csv
import importlib.util
from pathlib import Path

from torchrl.record.loggers import CSVLogger, Logger, TensorboardLogger


class RunLogError(ValueError):
    """A run directory's logs that this version cannot continue."""


class CsvTable:
    """Append-only CSV with a fixed header, flushed after every row."""

    def __init__(self, path: Path, columns: list[str]) -> None:
        self.path, self.columns = path, columns
        if not path.exists():
            with path.open("w", newline="") as f:
                csv.writer(f).writerow(columns)
        else:
            with path.open(newline="") as f:
                header = next(csv.reader(f), [])
            if header != columns:
                raise RunLogError(f"{path} has other columns than this version writes "
                                 "(made by an older version?): use another hydra.run.dir")

    def append(self, row: dict[str, float]) -> None:
        with self.path.open("a", newline="") as f:
            csv.writer(f).writerow([row.get(c, "") for c in self.columns])

    def rows(self) -> list[dict[str, str]]:
        with self.path.open(newline="") as f:
            return list(csv.DictReader(f))

    def truncate_after(self, env_step: int) -> int:
        """Drop rows with ``env_step`` beyond the given one; returns how many."""
        rows = self.rows()
        kept = [r for r in rows if int(float(r["env_step"])) <= env_step]
        with self.path.open("w", newline="") as f:
            writer = csv.DictWriter(f, fieldnames=self.columns)
            writer.writeheader()
            writer.writerows(kept)
        return len(rows) - len(kept)


# episode_reward: planner without exploration noise (TD-MPC's evaluation);
# noisy_episode_reward: with the training noise at that step (the training episodes' setting).
EVAL_COLUMNS = ["env_step", "agent_step", "episode", "wall_time", "episode_reward",
                "episode_reward_std", "eval_episodes", "noisy_episode_reward",
                "noisy_episode_reward_std", "noisy_eval_episodes"]
# q_mean / td_target_mean: the TD learner's health (they grow toward the return scale);
# target_lag: |online - target| / |online| over all parameters (the target must track).
TRAIN_COLUMNS = ["env_step", "agent_step", "episode", "wall_time", "updates", "loss_model",
                 "loss_pi", "consistency", "reward_error", "value_error", "q_mean",
                 "td_target_mean", "target_lag", "model_grad_norm", "policy_grad_norm",
                 "episode_reward", "steps_per_second"]


class RunLog:
    """Writes the run's tables and forwards every value to TorchRL's loggers."""

    def __init__(self, run_dir: Path, tensorboard: str | bool = "auto") -> None:
        self.run_dir = run_dir
        self.eval = CsvTable(run_dir / "eval.csv", EVAL_COLUMNS)
        self.train = CsvTable(run_dir / "train.csv", TRAIN_COLUMNS)
        self.loggers: list[Logger] = [CSVLogger(exp_name="torchrl_csv", log_dir=str(run_dir))]
        have_tb = importlib.util.find_spec("tensorboard") is not None
        if tensorboard is True and not have_tb:
            raise ValueError("logger.tensorboard=true but the tensorboard package is not "
                             "installed (pip install tensorboard), or use auto/false")
        if tensorboard is True or (tensorboard == "auto" and have_tb):
            self.loggers.append(TensorboardLogger(exp_name="tensorboard", log_dir=str(run_dir)))

    def truncate_after(self, env_step: int) -> int:
        """Drop rows logged after ``env_step`` (-1: all), TorchRL's CSV files included;
        returns how many rows of the two tables were dropped. TensorBoard event files
        cannot be trimmed: a resumed run's steps appear there twice."""
        for path in (self.run_dir / "torchrl_csv").rglob("*.csv"):
            lines = path.read_text().splitlines(keepends=True)
            kept = [line for line in lines if int(float(line.split(",", 1)[0])) <= env_step]
            if len(kept) != len(lines):
                path.write_text("".join(kept))
        return self.eval.truncate_after(env_step) + self.train.truncate_after(env_step)

    def log(self, table: str, row: dict[str, float]) -> None:
        getattr(self, table).append(row)
        for logger in self.loggers:
            for key, value in row.items():
                if key not in ("env_step", "agent_step", "episode"):
                    logger.log_scalar(f"{table}/{key}", float(value), step=int(row["env_step"]))
