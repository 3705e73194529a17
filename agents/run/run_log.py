"""Writing a run's logs: its tables (``agents.run.run_tables``), plus TorchRL's loggers.

The tables are the run's record (one row per evaluation / per update round, fixed
columns), read by plotting and by resume: on resume, rows logged after the last
checkpoint are dropped, since the run will log them again. Every row is also sent to
TorchRL's ``CSVLogger`` (one file per scalar) and, when the ``tensorboard`` package is
installed, its ``TensorboardLogger``.
"""

from __future__ import annotations

import datetime
import importlib.metadata
import importlib.util
import platform
import subprocess
from pathlib import Path

import torch
from torchrl.record.loggers import CSVLogger, Logger, TensorboardLogger

from agents.run.machine import cpu_model
from agents.run.run_tables import EVAL_COLUMNS, SESSION_COLUMNS, TRAIN_COLUMNS, CsvTable

_CODE_ROOT = Path(__file__).resolve().parents[2]


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


def session_record(env_step: int) -> dict[str, str | int]:
    """Who runs a run from ``env_step`` on: code (commit, or GeoMDP's version from a
    wheel), the versions of the libraries that decide its numbers, the host, its CPU
    and torch's thread count."""
    return {
        "env_step": env_step,
        "started": datetime.datetime.now(datetime.timezone.utc).isoformat(timespec="seconds"),
        **code_version(), **{name: _version(name) for name in ("torch", "escnn", "torchrl")},
        "host": platform.node(), "geomdp": _version("geomdp"),
        **{name: _version(dist) for name, dist in (("numpy", "numpy"), ("mujoco", "mujoco"),
                                                   ("dm_control", "dm-control"),
                                                   ("gymnasium", "gymnasium"))},
        "cpu": cpu_model(), "torch_threads": torch.get_num_threads()}


class RunLog:
    """Writes the run's tables and forwards every value to TorchRL's loggers."""

    def __init__(self, run_dir: Path, tensorboard: str | bool = "auto") -> None:
        self.run_dir = run_dir
        self.eval = CsvTable(run_dir / "eval.csv", EVAL_COLUMNS, grows=True)
        self.train = CsvTable(run_dir / "train.csv", TRAIN_COLUMNS)
        self.sessions = CsvTable(run_dir / "sessions.csv", SESSION_COLUMNS, grows=True)
        have_tb = importlib.util.find_spec("tensorboard") is not None
        if tensorboard is True and not have_tb:
            raise ValueError("logger.tensorboard=true but the tensorboard package is not "
                             "installed (pip install tensorboard), or use auto/false")
        self.tensorboard = tensorboard is True or (tensorboard == "auto" and have_tb)
        self._loggers: list[Logger] | None = None  # made with the first row: nothing before

    @property
    def loggers(self) -> list[Logger]:
        """TorchRL's loggers (they create their folders when made)."""
        if self._loggers is None:
            self._loggers = [CSVLogger(exp_name="torchrl_csv", log_dir=str(self.run_dir))]
            if self.tensorboard:
                self._loggers.append(TensorboardLogger(exp_name="tensorboard",
                                                       log_dir=str(self.run_dir)))
        return self._loggers

    def record_session(self, env_step: int, symmetry_check: str = "",
                       changed_options: str = "") -> None:
        """Append who ran this run from ``env_step`` on (``session_record``), whether the
        task's declaration was checked, and the options changed since ``config.yaml``.
        Kept across resumes (not truncated): it is the run's provenance."""
        self.sessions.append({**session_record(env_step), "symmetry_check": symmetry_check,
                              "changed_options": changed_options})

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
        for logger in self._loggers or []:
            close = getattr(logger.experiment, "close", None)
            if isinstance(logger, TensorboardLogger) and close is not None:
                close()

    def log(self, table: str, row: dict[str, float]) -> None:
        getattr(self, table).append(row)
        for logger in self.loggers:
            for key, value in row.items():
                if key not in ("env_step", "agent_step", "episode"):
                    logger.log_scalar(f"{table}/{key}", float(value), step=int(row["env_step"]))
