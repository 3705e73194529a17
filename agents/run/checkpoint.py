"""Checkpoints that survive interruption and refuse what they cannot trust.

A checkpoint is a directory ``checkpoint/`` in the run directory holding the
agent (parameters, target network, optimisers, RNG), the replay buffer (what
it holds, not its capacity: ``agents.tdmpc.replay.save_replay``), the loop state and
``manifest.json``: the SHA-256 of every file and the run's options (seed
included). It is written whole to ``checkpoint.tmp/`` (the manifest last)
and swapped in by renames, so a kill
at any moment leaves a complete checkpoint under ``checkpoint/`` or
``checkpoint.old/``; whatever an interrupted swap left behind is cleaned up
by the next load or save. On load every file is checked against the
manifest, and the options against the current run's: flipped bytes, a
truncated or deleted file, or a checkpoint copied from another run (another
seed) are refused with one line, and never overwritten.

escnn's basis buffers are not written: they are rebuilt from the group when
the agent is built, and they are most of an equivariant agent's bytes.
"""

from __future__ import annotations

import hashlib
import json
import shutil
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import gymnasium
import numpy as np
import torch
from torchrl.data import TensorDictReplayBuffer

from agents.run import faults
from agents.run.checkpoint_state import checkpoint_paths
from agents.run.config import RunOptions
from agents.run.envs import make_gym_env
from agents.run.nested import differences, with_added_later
from agents.tdmpc.agent import TDMPCAgent
from agents.tdmpc.replay import load_replay, make_replay_buffer, save_replay
from geomdp_envs import symmetry_of

FORMAT_VERSION = 3
# A checkpoint inside a block of updates (its loop state has an ``unfinished_episode``):
# a format of its own, so that code from before it refuses it instead of redoing the
# whole block on top of the updates already made.
INSIDE_UPDATES_FORMAT = 4
FORMATS = (FORMAT_VERSION, INSIDE_UPDATES_FORMAT)
MANIFEST = "manifest.json"


class CheckpointError(RuntimeError):
    """A checkpoint that cannot be used; the run refuses to start (and to overwrite it)."""


class CheckpointWriteError(CheckpointError):
    """A checkpoint that could not be written (disk full, permissions); the last one stays."""


def _sha256(path: Path) -> str:
    digest = hashlib.sha256()
    with path.open("rb") as f:
        for block in iter(lambda: f.read(1 << 20), b""):
            digest.update(block)
    return digest.hexdigest()


def _files(root: Path) -> list[str]:
    return sorted(str(p.relative_to(root)) for p in root.rglob("*") if p.is_file() and p.name != MANIFEST)


def save(run_dir: Path, agent: TDMPCAgent, buffer: TensorDictReplayBuffer,
         loop_state: dict[str, Any], options: dict[str, Any] | None = None) -> None:
    """Write a checkpoint atomically; ``options`` (the run's config) must match on load."""
    final, tmp, old = checkpoint_paths(run_dir)
    try:
        shutil.rmtree(tmp, ignore_errors=True)
        tmp.mkdir()
        cuda_rng = torch.cuda.get_rng_state_all() if agent.device.type == "cuda" else None
        torch.save({"agent": agent.state_dict(), "torch_rng": torch.get_rng_state(),
                    "cuda_rng": cuda_rng, "numpy_rng": np.random.get_state()}, tmp / "agent.pt")
        faults.point("checkpoint_write")
        save_replay(buffer, tmp / "replay.pt")
        version = INSIDE_UPDATES_FORMAT if loop_state.get("unfinished_episode") else FORMAT_VERSION
        (tmp / "state.json").write_text(json.dumps({"format": version, **loop_state}, indent=1))
        manifest = {"format": version, "options": options or {},
                    "files": {name: _sha256(tmp / name) for name in _files(tmp)}}
        (tmp / MANIFEST).write_text(json.dumps(manifest, indent=1))
        if final.exists():
            if old.exists():  # left by a save interrupted after its swap
                shutil.rmtree(old)
            final.rename(old)
            faults.point("checkpoint_swap")
        tmp.rename(final)
        faults.point("checkpoint_cleanup")
        shutil.rmtree(old, ignore_errors=True)
    except (OSError, RuntimeError) as err:  # torch.save reports a full disk as RuntimeError
        reason = getattr(err, "strerror", None) or str(err).splitlines()[0][:200]
        raise CheckpointWriteError(f"cannot write the checkpoint in {run_dir} ({reason}); "
                              "the previous checkpoint is intact: free space or fix permissions, "
                              "then run the same command to continue") from None


def recover(run_dir: Path) -> Path | None:
    """The directory of the last complete checkpoint, after undoing an interrupted swap."""
    final, tmp, old = checkpoint_paths(run_dir)
    if final.exists():
        for stale in (old, tmp):
            shutil.rmtree(stale, ignore_errors=True)
        return final
    if old.exists():  # interrupted between the two renames of a save
        old.rename(final)
        shutil.rmtree(tmp, ignore_errors=True)
        return final
    return None


def verify(path: Path, options: dict[str, Any] | None = None) -> dict[str, Any]:
    """Check every file against the manifest, and the options; returns the loop state."""
    manifest_path = path / MANIFEST
    if not manifest_path.exists():
        raise CheckpointError(f"checkpoint {path} has no {MANIFEST} (written by an older "
                              "version, or damaged); delete it to start over")
    try:
        manifest = json.loads(manifest_path.read_text())
        files = manifest["files"]
    except (ValueError, KeyError, TypeError):
        raise CheckpointError(f"checkpoint {path}: {MANIFEST} is unreadable; delete the "
                              "checkpoint to start over") from None
    if manifest.get("format") not in FORMATS:
        raise CheckpointError(f"checkpoint {path} has format {manifest.get('format')}, expected "
                              f"{' or '.join(map(str, FORMATS))}; delete it to start over")
    missing = sorted(set(files) - set(_files(path)))
    if missing:
        raise CheckpointError(f"checkpoint {path} is incomplete: missing {', '.join(missing[:3])}; "
                              "delete it to start over")
    for name, digest in files.items():
        if _sha256(path / name) != digest:
            raise CheckpointError(f"checkpoint {path} is corrupted: {name} does not match its "
                                  "checksum; delete it to start over")
    saved = with_added_later(manifest.get("options") or {})
    # differences, not !=: a key one side lacks compares as None (an option added later)
    diffs = [] if options is None else [f"{k}: {a!r} there, {b!r} here"
                                        for k, a, b in differences(saved, options)]
    if diffs:
        raise CheckpointError(f"checkpoint {path} belongs to another run ({'; '.join(diffs[:3])}); "
                              "use that run's options, or delete the checkpoint to start over")
    return json.loads((path / "state.json").read_text())


def load(run_dir: Path, agent: TDMPCAgent, buffer: TensorDictReplayBuffer,
         options: dict[str, Any] | None = None) -> dict[str, Any] | None:
    """Restore the agent and buffer in place; returns the loop state, or None if fresh."""
    path = recover(run_dir)
    if path is None:
        return None
    state = verify(path, options)
    try:
        # On the CPU: the RNG states must stay CPU byte tensors; load_state_dict copies
        # the networks onto the agent's device.
        saved = torch.load(path / "agent.pt", map_location="cpu", weights_only=False)
        agent.load_state_dict(saved["agent"])
        load_replay(buffer, path / "replay.pt")
    except Exception as err:  # noqa: BLE001  (any failure to read means the same thing)
        raise CheckpointError(f"checkpoint {path} is from another agent or unreadable "
                              f"({type(err).__name__}: {str(err).splitlines()[0][:200]}); "
                              "delete it to start over, or choose another hydra.run.dir") from None
    torch.set_rng_state(saved["torch_rng"])
    if saved.get("cuda_rng") and torch.cuda.is_available():
        torch.cuda.set_rng_state_all(saved["cuda_rng"])
    np.random.set_state(saved["numpy_rng"])
    return state


@dataclass
class RestoredRun:
    """A run's agent as its last checkpoint left it, beside the run's task."""

    options: RunOptions
    env: gymnasium.Env
    agent: TDMPCAgent
    state: dict[str, Any]  # the loop state: env_step, agent_step (the schedules' step), ...


def restore_run(run_dir: Path, render_mode: str | None = None) -> RestoredRun:
    """The agent of ``run_dir`` from its checkpoint and the task it was trained on, to act
    with or inspect (its replay buffer is read and dropped). Like a resume, it also sets
    torch's and numpy's global random states (and CUDA's, on a GPU) to those the checkpoint
    saved: draws made after it depend on the run. An OptionError or a CheckpointError in
    one line when the run has no readable options or checkpoint."""
    options = RunOptions.from_run_dir(run_dir)
    env = make_gym_env(options.env, render_mode=render_mode)
    agent = TDMPCAgent(options.agent, symmetry_of(env), env.observation_space.shape[0],
                       env.action_space.shape[0])
    replay = options.agent.replay
    state = load(run_dir, agent, make_replay_buffer(replay, options.agent.horizon,
                                                    options.agent.batch_size))
    if state is None:
        raise CheckpointError(f"no checkpoint in {run_dir} (a run directory that geomdp-train "
                              "has checkpointed)")
    return RestoredRun(options, env, agent, state)
