"""Replay of horizon-length slices of episodes, with TorchRL's buffers and samplers."""

from __future__ import annotations

import typing
from dataclasses import dataclass
from pathlib import Path

import torch
from tensordict import TensorDictBase
from torchrl.data import (
    LazyTensorStorage,
    PrioritizedSliceSampler,
    SliceSampler,
    TensorDictReplayBuffer,
)

from agents.compat.torchrl import prioritized_replay_refusal, priority_state, restore_priority_state
from agents.options import OptionError, check, key, option

EPISODE_KEY = "episode"


@dataclass
class ReplayConfig:
    KEY: typing.ClassVar[str] = "agent.replay"
    capacity: int = option(1_000_000, low=1)
    prioritized: bool = True  # TD-MPC's prioritised replay
    alpha: float = option(0.6, low=0)  # priority exponent (0: uniform)
    beta: float = option(0.4, low=0, high=1)  # importance-sampling exponent
    # New data's priority: false, the largest ever given (TorchRL's default); true, the
    # largest among the slots the buffer holds (TD-MPC's)
    max_priority_within_buffer: bool = False
    # Added to every priority before the exponent alpha: (TD error + eps)^alpha. A slot
    # whose TD error is 0 (every slot of the first update: zero-initialised Q heads and no
    # reward) is drawn eps^alpha / p^alpha as often as one of priority p until a sample
    # rewrites it. TorchRL's default 1e-8; TD-MPC's 1e-6
    priority_eps: float = option(1e-8, low=0, low_open=True)

    def __post_init__(self) -> None:
        check(self)
        if self.max_priority_within_buffer and not self.prioritized:
            raise OptionError(f"{key(ReplayConfig, 'max_priority_within_buffer')}=true needs "
                              f"{key(ReplayConfig, 'prioritized')}=true (uniform replay has no "
                              "priorities)")


def make_replay_buffer(config: ReplayConfig, horizon: int, batch_size: int,
                       device: torch.device | str = "cpu") -> TensorDictReplayBuffer:
    """A buffer whose ``sample()`` returns ``batch_size`` slices of ``horizon`` steps,
    never crossing an episode boundary (transitions carry an ``episode`` id)."""
    if config.prioritized and (refusal := prioritized_replay_refusal()):
        raise ValueError(refusal)  # rather than TorchRL's error from inside its sampler
    common = dict(slice_len=horizon, traj_key=EPISODE_KEY, strict_length=True)
    if config.prioritized:
        sampler = PrioritizedSliceSampler(max_capacity=config.capacity, alpha=config.alpha,
                                          beta=config.beta,
                                          eps=config.priority_eps,
                                          max_priority_within_buffer=config.max_priority_within_buffer,
                                          **common)
    else:
        sampler = SliceSampler(**common)
    return TensorDictReplayBuffer(storage=LazyTensorStorage(config.capacity, device=device),
                                  sampler=sampler, batch_size=batch_size * horizon)


def sample_slices(buffer: TensorDictReplayBuffer, horizon: int) -> TensorDictBase:
    """A sample reshaped to [batch, horizon]."""
    return buffer.sample().reshape(-1, horizon)


def update_priorities(buffer: TensorDictReplayBuffer, batch: TensorDictBase,
                      priority: torch.Tensor) -> None:
    """Give every step of each sampled slice that slice's priority (TD-MPC's TD error)."""
    if isinstance(buffer.sampler, PrioritizedSliceSampler):
        horizon = batch.shape[1]
        buffer.update_priority(batch["index"].reshape(-1),
                               priority.clamp(max=1e4).repeat_interleave(horizon))


def save_replay(buffer: TensorDictReplayBuffer, path: Path) -> None:
    """Write what the buffer holds, and no more: the stored transitions, the writer's
    cursor and, for prioritised replay, the priorities of the stored slots.

    TorchRL's ``dumps`` writes the whole capacity (and reads the priority trees one
    slot at a time in Python): 7.7 MB for a nearly empty CPU-preset buffer, 80 MB
    for the paper preset, at every checkpoint.
    """
    n = len(buffer.storage)
    state: dict = {"len": n, "writer": buffer.writer.state_dict(),
                   "data": buffer.storage[:n].clone() if n else None}
    sampler = buffer.sampler
    if isinstance(sampler, PrioritizedSliceSampler) and n:
        state["priorities"] = priority_state(sampler, n)
    torch.save(state, path)


def load_replay(buffer: TensorDictReplayBuffer, path: Path) -> None:
    """Restore what ``save_replay`` wrote into a new, empty buffer of the same configuration."""
    state = torch.load(path, weights_only=False)
    n = state["len"]
    if n > buffer.storage.max_size:
        raise ValueError(f"the saved replay holds {n} steps, more than this buffer's capacity "
                         f"({buffer.storage.max_size})")
    if n:
        index = torch.arange(n)
        buffer.storage.set(index, state["data"])
        if "priorities" in state:
            restore_priority_state(buffer.sampler, n, state["priorities"])
    buffer.writer.load_state_dict(state["writer"])
