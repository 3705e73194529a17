"""A run's logs: ``eval.csv`` and ``train.csv`` tables, plus TorchRL's loggers.

The two tables are the run's record (one row per evaluation / per update
round, fixed columns), read by plotting and by resume: on resume, rows logged
after the last checkpoint are dropped, since the run will log them again.
Every row is also sent to TorchRL's ``CSVLogger`` (one file per scalar) and,
when the ``tensorboard`` package is installed, its ``TensorboardLogger``.
"""

from __future__ import annotations

import csv
import datetime
import importlib.metadata
import importlib.util
import platform
import subprocess
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


# One row per start or resume: which code made which steps (a run resumed in another
# session may run other code; float rounding differs between versions).
SESSION_COLUMNS = ["env_step", "started", "git_commit", "git_dirty", "torch", "escnn",
                   "torchrl", "host"]
_CODE_ROOT = Path(__file__).resolve().parents[2]


def wall_minutes(run_dir: Path) -> float | None:
    """A run's wall time over all its sessions (evaluations included), in minutes, from
    its tables (``wall_time`` accumulates across resumes); None when nothing is logged."""
    times = []
    for table in ("train.csv", "eval.csv"):
        if (run_dir / table).exists():
            with (run_dir / table).open(newline="") as f:
                times += [float(r["wall_time"]) for r in csv.DictReader(f) if r.get("wall_time")]
    return max(times) / 60 if times else None


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


def code_version() -> dict[str, str]:
    """The git commit of the code this process imported (``unknown`` outside a git
    checkout) and whether its tracked sources differ from that commit."""

    def git(*args: str) -> str | None:
        try:
            done = subprocess.run(["git", "-C", str(_CODE_ROOT), *args], capture_output=True,
                                  text=True, timeout=30, check=False)
        except (OSError, subprocess.SubprocessError):
            return None
        return done.stdout.strip() if done.returncode == 0 else None

    commit = git("rev-parse", "HEAD")
    if commit is None:
        return {"git_commit": "unknown", "git_dirty": "unknown"}
    changed = git("status", "--porcelain", "--untracked-files=no", "--", "agents",
                  "geomdp_envs", "configs")
    return {"git_commit": commit, "git_dirty": "unknown" if changed is None else str(bool(changed))}


def _version(package: str) -> str:
    try:
        return importlib.metadata.version(package)
    except importlib.metadata.PackageNotFoundError:
        return "absent"


class RunLog:
    """Writes the run's tables and forwards every value to TorchRL's loggers."""

    def __init__(self, run_dir: Path, tensorboard: str | bool = "auto") -> None:
        self.run_dir = run_dir
        self.eval = CsvTable(run_dir / "eval.csv", EVAL_COLUMNS)
        self.train = CsvTable(run_dir / "train.csv", TRAIN_COLUMNS)
        self.sessions = CsvTable(run_dir / "sessions.csv", SESSION_COLUMNS)
        self.loggers: list[Logger] = [CSVLogger(exp_name="torchrl_csv", log_dir=str(run_dir))]
        have_tb = importlib.util.find_spec("tensorboard") is not None
        if tensorboard is True and not have_tb:
            raise ValueError("logger.tensorboard=true but the tensorboard package is not "
                             "installed (pip install tensorboard), or use auto/false")
        if tensorboard is True or (tensorboard == "auto" and have_tb):
            self.loggers.append(TensorboardLogger(exp_name="tensorboard", log_dir=str(run_dir)))

    def record_session(self, env_step: int) -> None:
        """Append who ran this run from ``env_step`` on: code commit, library versions, host.
        Kept across resumes (not truncated): it is the run's provenance."""
        self.sessions.append({
            "env_step": env_step,
            "started": datetime.datetime.now(datetime.timezone.utc).isoformat(timespec="seconds"),
            **code_version(), "torch": _version("torch"), "escnn": _version("escnn"),
            "torchrl": _version("torchrl"), "host": platform.node()})

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

    def close(self) -> None:
        """Flush what TorchRL's loggers buffer (TensorBoard's event files)."""
        for logger in self.loggers:
            close = getattr(logger.experiment, "close", None)
            if isinstance(logger, TensorboardLogger) and close is not None:
                close()

    def log(self, table: str, row: dict[str, float]) -> None:
        getattr(self, table).append(row)
        for logger in self.loggers:
            for key, value in row.items():
                if key not in ("env_step", "agent_step", "episode"):
                    logger.log_scalar(f"{table}/{key}", float(value), step=int(row["env_step"]))
