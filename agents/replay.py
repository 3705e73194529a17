"""Replay of horizon-length slices of episodes, with TorchRL's buffers and samplers."""

from __future__ import annotations

from dataclasses import dataclass

import torch
from tensordict import TensorDictBase
from torchrl.data import (
    LazyTensorStorage,
    PrioritizedSliceSampler,
    SliceSampler,
    TensorDictReplayBuffer,
)

EPISODE_KEY = "episode"


@dataclass
class ReplayConfig:
    capacity: int = 1_000_000
    prioritized: bool = True  # TD-MPC's prioritised replay
    alpha: float = 0.6
    beta: float = 0.4

    def __post_init__(self) -> None:
        if self.capacity < 1:
            raise ValueError(f"replay.capacity must be >= 1, got {self.capacity}")


def make_replay_buffer(config: ReplayConfig, horizon: int, batch_size: int,
                       device: torch.device | str = "cpu") -> TensorDictReplayBuffer:
    """A buffer whose ``sample()`` returns ``batch_size`` slices of ``horizon`` steps,
    never crossing an episode boundary (transitions carry an ``episode`` id)."""
    common = dict(slice_len=horizon, traj_key=EPISODE_KEY, strict_length=True)
    if config.prioritized:
        sampler = PrioritizedSliceSampler(max_capacity=config.capacity, alpha=config.alpha,
                                          beta=config.beta, **common)
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
