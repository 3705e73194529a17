"""Checkpoints that survive interruption: written whole or not at all, checked on load.

A checkpoint is a directory ``checkpoint/`` in the run directory holding the
agent (networks, target networks, optimisers, RNG), the replay buffer (TorchRL's
``dumps``) and the loop state. It is written to ``checkpoint.tmp/`` and then
swapped in by renames, so an interruption at any moment leaves either the old
or the new checkpoint, never a half-written one.
"""

from __future__ import annotations

import json
import shutil
from pathlib import Path
from typing import Any

import numpy as np
import torch
from torchrl.data import TensorDictReplayBuffer

from agents.tdmpc import TDMPCAgent

FORMAT_VERSION = 1


class CheckpointError(RuntimeError):
    """A checkpoint that cannot be used; the run refuses to start (and to overwrite it)."""


def checkpoint_dir(run_dir: Path) -> Path:
    return run_dir / "checkpoint"


def save(run_dir: Path, agent: TDMPCAgent, buffer: TensorDictReplayBuffer,
         loop_state: dict[str, Any]) -> None:
    final, tmp, old = (checkpoint_dir(run_dir), run_dir / "checkpoint.tmp",
                       run_dir / "checkpoint.old")
    shutil.rmtree(tmp, ignore_errors=True)
    tmp.mkdir()
    torch.save({"agent": agent.state_dict(), "torch_rng": torch.get_rng_state(),
                "numpy_rng": np.random.get_state()}, tmp / "agent.pt")
    buffer.dumps(tmp / "replay")
    (tmp / "state.json").write_text(json.dumps({"format": FORMAT_VERSION, **loop_state},
                                               indent=1))
    if final.exists():
        final.rename(old)
    tmp.rename(final)
    shutil.rmtree(old, ignore_errors=True)


def load(run_dir: Path, agent: TDMPCAgent, buffer: TensorDictReplayBuffer) -> dict[str, Any] | None:
    """Restore the agent and buffer in place; returns the loop state, or None if fresh."""
    path = checkpoint_dir(run_dir)
    if not path.exists() and (run_dir / "checkpoint.old").exists():
        (run_dir / "checkpoint.old").rename(path)  # interrupted between the two renames
    if not path.exists():
        return None
    try:
        state = json.loads((path / "state.json").read_text())
        if state.get("format") != FORMAT_VERSION:
            raise CheckpointError(f"format {state.get('format')}, expected {FORMAT_VERSION}")
        saved = torch.load(path / "agent.pt", map_location=agent.device, weights_only=False)
        agent.load_state_dict(saved["agent"])
        buffer.loads(path / "replay")
    except CheckpointError as err:
        raise CheckpointError(f"checkpoint {path} cannot be used: {err}; delete it to start "
                              "over, or choose another hydra.run.dir") from None
    except Exception as err:  # noqa: BLE001  (any failure to read means the same thing)
        raise CheckpointError(f"checkpoint {path} is corrupted or from another agent "
                              f"({type(err).__name__}: {str(err).splitlines()[0][:200]}); "
                              "delete it to start over, or choose another hydra.run.dir") from None
    torch.set_rng_state(saved["torch_rng"])
    np.random.set_state(saved["numpy_rng"])
    return state
