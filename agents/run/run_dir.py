"""The run directory: refused in one line when it cannot hold the run (not writable,
disk too full, made with other options, in use by another process), and its records
(``config.yaml``, ``.hydra/``) written only once the run is accepted."""

from __future__ import annotations

import fcntl
import os
import shutil
from pathlib import Path
from typing import IO, Any

from omegaconf import DictConfig, OmegaConf

from agents.options import OptionError, show
from agents.run.checkpoint_state import LOCK_FILE, WRITE_PROBE, checkpoint_paths
from agents.run.config import RESUMABLE_KEYS, fixed_options
from agents.run.nested import differences, flatten, with_added_later


class RunDirError(OptionError):
    """The run directory cannot hold the run (not writable, disk too full, in use)."""


def make_run_dir(run_dir: Path) -> None:
    """Create the run directory (and its parents), or refuse in one line: a path that
    cannot be a directory is bad input (exit status 2), not a directory that cannot
    hold the run."""
    try:
        run_dir.mkdir(parents=True, exist_ok=True)
    except OSError as err:
        raise OptionError(f"cannot create the run directory {run_dir} ({err.strerror}); "
                          "choose another hydra.run.dir") from None


def check_writable(run_dir: Path) -> None:
    """Refuse, in one line, a run directory (or left-over checkpoint) that cannot be written."""
    probe = run_dir / WRITE_PROBE
    try:
        probe.write_text("ok")
        probe.unlink()
    except OSError as err:
        raise RunDirError(f"cannot write in the run directory {run_dir} ({err.strerror}); "
                          "choose another hydra.run.dir or fix its permissions") from None
    for checkpoint in checkpoint_paths(run_dir):
        for path in [checkpoint, *checkpoint.rglob("*")]:
            if path.is_dir() and not os.access(path, os.W_OK | os.X_OK):
                raise RunDirError(f"{path} is not writable: the run could not replace its "
                                  "checkpoint; fix its permissions")


def check_disk_space(run_dir: Path, state_bytes: int, capacity: int, obs_size: int,
                     action_size: int) -> None:
    """Refuse to start when the disk cannot hold two checkpoints (the new one is written
    beside the old); estimated from the agent's state and the replay's full capacity."""
    replay_bytes = capacity * (4 * (2 * obs_size + action_size + 2) + 8 * 2 + 16)
    need = 2 * (state_bytes + replay_bytes) + (16 << 20)
    free = shutil.disk_usage(run_dir).free
    if free < need:
        raise RunDirError(f"not enough disk space in {run_dir}: {free >> 20} MB free, a run of "
                          f"this size needs about {need >> 20} MB for its checkpoints")


def check_same_options(run_dir: Path, resolved: dict[str, Any]) -> None:
    """Refuse to continue a run directory that was made with different options."""
    saved = _saved_options(run_dir)
    if saved is None:
        return
    diffs = [f"{k}: {a!r} -> {b!r}"
             for k, a, b in differences(fixed_options(saved), fixed_options(flatten(resolved)))]
    if diffs:
        raise OptionError(f"{run_dir} holds a run with other options ({'; '.join(diffs)}); "
                          "use another hydra.run.dir, or the run's own options")


def _saved_options(run_dir: Path) -> dict[str, Any] | None:
    """The flattened options in the run directory's ``config.yaml`` (None: a new run)."""
    saved_path = run_dir / "config.yaml"
    if not saved_path.exists():
        return None
    return with_added_later(flatten(OmegaConf.to_container(OmegaConf.load(saved_path),
                                                           resolve=True)))


def changed_options(run_dir: Path, resolved: dict[str, Any]) -> str:
    """The options this session changes from those the run was made with (budgets and
    display only: ``check_same_options`` refuses the rest), e.g. ``train.steps: 3000 ->
    6000``; empty for a new run or an unchanged rerun. ``sessions.csv`` records it."""
    saved = _saved_options(run_dir)
    if saved is None:
        return ""
    def resumable(flat: dict[str, Any]) -> dict[str, Any]:
        return {k: v for k, v in flat.items() if k.startswith(RESUMABLE_KEYS)}

    return "; ".join(f"{k}: {show(a)} -> {show(b)}" for k, a, b
                     in differences(resumable(saved), resumable(with_added_later(flatten(resolved)))))


def write_records(run_dir: Path, resolved: dict[str, Any], composed: DictConfig | None = None,
                  hydra: DictConfig | None = None, overrides: list[str] | None = None) -> None:
    """The options the run was made with: ``config.yaml`` (resolved) and, from the command
    line, Hydra's ``.hydra/`` records, written once, when a new run is accepted (a resume
    keeps them; what a resume changes goes to ``sessions.csv``). Hydra's own writing is
    off: it would run before the checks and overwrite the records with options never used."""
    if (run_dir / "config.yaml").exists():
        return
    OmegaConf.save(OmegaConf.create(resolved), run_dir / "config.yaml")
    if composed is None:
        return
    records = run_dir / ".hydra"
    records.mkdir(exist_ok=True)
    OmegaConf.save(composed, records / "config.yaml")
    if hydra is not None:
        OmegaConf.save(OmegaConf.create({"hydra": hydra}), records / "hydra.yaml")
    OmegaConf.save(OmegaConf.create(list(overrides or [])), records / "overrides.yaml")


class RunDirLock:
    """An exclusive lock on the run directory for the run's life: a second process on
    the same directory is refused in one line instead of interleaving its log rows.
    ``flock`` is released by the kernel when the process ends, however it ends."""

    def __init__(self, run_dir: Path) -> None:
        self.path = run_dir / LOCK_FILE
        self._file: IO[str] | None = None

    def __enter__(self) -> RunDirLock:
        try:
            handle = self.path.open("a+")
        except OSError as err:
            raise RunDirError(f"cannot write in the run directory {self.path.parent} "
                              f"({err.strerror}); choose another hydra.run.dir or fix its "
                              "permissions") from None
        try:
            fcntl.flock(handle, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except OSError:
            handle.seek(0)
            holder = handle.read().strip() or "unknown"
            handle.close()
            raise RunDirError(f"{self.path.parent} is in use by another geomdp-train (pid "
                              f"{holder}); wait for it to end, or use another hydra.run.dir") from None
        handle.seek(0)
        handle.truncate()
        handle.write(str(os.getpid()))
        handle.flush()
        self._file = handle
        return self

    def __exit__(self, *exc: object) -> None:
        if self._file is not None:
            self._file.close()  # closing releases the lock
            self._file = None


def remove_if_only_hydra_files(run_dir: Path) -> None:
    """A run refused before any work leaves no directory behind (Hydra makes it first)."""
    if not run_dir.is_dir():
        return
    entries = {p.name for p in run_dir.iterdir()}
    log = run_dir / "train.log"
    if entries <= {".hydra", "train.log"} and (not log.exists() or log.stat().st_size == 0):
        shutil.rmtree(run_dir, ignore_errors=True)
