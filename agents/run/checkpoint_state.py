"""Where a run's checkpoint stands, read without torch.

The names of the files a run directory holds beside its logs (the checkpoint and its swap
partners, the lock, the write probe) and the checkpoint's loop state (``state.json``), for
the code that only needs to know how far a run got or which files are not logs: the run
queue (which must not import torch), the trainer's resume and interrupt messages. Writing
and verifying checkpoints is ``agents.run.checkpoint``'s job.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

LOCK_FILE = "run.lock"  # held by the trainer for as long as it uses the directory
WRITE_PROBE = ".geomdp-write-test"  # written and removed to test that the directory is writable


def checkpoint_paths(run_dir: Path) -> tuple[Path, Path, Path]:
    """The checkpoint, the one being written and the one a save is replacing."""
    return run_dir / "checkpoint", run_dir / "checkpoint.tmp", run_dir / "checkpoint.old"


def saved_state(run_dir: Path) -> dict[str, Any] | None:
    """The loop state of the checkpoint a rerun will resume from (None: none, or a
    ``state.json`` that cannot be read, which the rerun refuses); a save interrupted
    mid-swap leaves it under ``checkpoint.old``."""
    final, _, old = checkpoint_paths(run_dir)
    for path in (final, old):
        state = path / "state.json"
        if state.exists():
            try:
                loaded = json.loads(state.read_text())
                int(loaded["env_step"])
            except (OSError, ValueError, KeyError, TypeError):
                return None
            return loaded
    return None


def saved_step(run_dir: Path) -> int | None:
    """The env step a rerun resumes from (None: no usable checkpoint)."""
    state = saved_state(run_dir)
    return None if state is None else int(state["env_step"])


def describe(state: dict[str, Any]) -> str:
    """Where a checkpoint stands: ``env step 20000`` or, inside the burst of updates after
    the warm-up, ``env step 20000, 2750 of its 5000 updates done``."""
    episode = state.get("unfinished_episode")
    inside = ("" if not episode else
              f", {episode['updates_done']} of its {state['pending_updates']} updates done")
    return f"env step {state['env_step']}{inside}"
