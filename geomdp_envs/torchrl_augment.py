"""Symmetry data augmentation as a TorchRL replay-buffer transform.

``SymmetryAugment`` is the TorchRL counterpart of ``augment_transitions``: put it
on a replay buffer and every sampled transition comes back moved by a random
element g of the task's exact group,

    (s, a, r, s', done)  ->  (g.s, g.a, r, g.s', done),

which has the same probability under the task's dynamics as the original::

    rb = TensorDictReplayBuffer(storage=LazyTensorStorage(100_000),
                                transform=SymmetryAugment(env.unwrapped.symmetry, seed=0))

Nothing is changed on write (``inv`` is the identity, as ``ReplayBuffer.extend``
calls it): the storage keeps the data as collected and each ``sample`` draws
fresh elements. It is not an env transform: moving an env's observations
without moving the state would make the agent act on a state it is not in.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import torch
from tensordict import NestedKey, TensorDictBase
from torchrl.envs.transforms import Transform

from geomdp_envs import groups
from geomdp_envs.augment import default_augmentation_group
from geomdp_envs.symmetry import Field, Symmetry

ENV_ERROR = ("SymmetryAugment is a replay-buffer transform (it moves sampled transitions); "
             "pass it to ReplayBuffer(transform=...) or rb.append_transform(...), not to an env")


class SymmetryAugment(Transform):
    """Moves each sampled transition by an independent random element of a symmetry group.

    Args:
        symmetry: the task's declaration (``gym_env.unwrapped.symmetry``).
        group: the group to draw elements from, a subgroup of the task's exact
            group; defaults to ``default_augmentation_group(symmetry)``, the
            largest one that keeps box actions in [-1, 1]. Another subgroup is
            accepted as in ``augment_transitions``: every sampled action must
            then lie in the declared action domain, or ``forward`` raises.
        observation_keys: entries moved by rho_S(g) (observation and next observation).
        action_keys: entries moved by rho_A(g).
        slice_key: for flat samples of trajectory slices (``SliceSampler``), a key
            whose value is constant along a slice, e.g. ``("collector", "traj_ids")``:
            each contiguous run of equal values gets one element. Without it a
            tensordict of shape [B] gets one element per transition and one of
            shape [B, T, ...] one element per row, shared by all its T steps,
            so a trajectory stays a trajectory.
        seed: seed of the transform's own ``torch.Generator`` (``None``: random).

    Rewards, done flags and all other entries are left as they are. Outputs keep
    the device and floating dtype of the inputs (integer entries become float64,
    as in ``augment_transitions``).
    """

    def __init__(
        self,
        symmetry: Symmetry,
        group: str | None = None,
        *,
        observation_keys: Sequence[NestedKey] = ("observation", ("next", "observation")),
        action_keys: Sequence[NestedKey] = ("action",),
        slice_key: NestedKey | None = None,
        seed: int | None = None,
    ) -> None:
        default = default_augmentation_group(symmetry)
        group = group or default
        if not groups.is_subgroup(group, symmetry.exact_group):
            raise ValueError(
                f"{group} is not an exact symmetry of this task; valid: {symmetry.exact_group} or a "
                f"subgroup of it (default {default}, which keeps box actions in [-1, 1])")
        observation_keys, action_keys = list(observation_keys), list(action_keys)
        keys = observation_keys + action_keys
        super().__init__(in_keys=keys, out_keys=keys)
        self.symmetry = symmetry
        self.group = group
        self.observation_keys = self.in_keys[: len(observation_keys)]
        self.action_keys = self.in_keys[len(observation_keys):]
        self.slice_key = slice_key
        self.check_action_domain = group != default
        self.generator = torch.Generator()
        self.manual_seed(seed)
        self._finite = groups.is_finite(group)
        if self._finite:  # every rho(g) once, as float64 [|G|, n, n]
            self._elements = groups.group_elements(group)
            self._rho_s, self._rho_a = self._matrices(self._elements)

    def manual_seed(self, seed: int | None) -> SymmetryAugment:
        """Reseeds the transform's generator (``None``: a non-deterministic seed)."""
        if seed is None:
            self.generator.seed()
        else:
            self.generator.manual_seed(seed)
        return self

    def sample_elements(self, n: int) -> tuple[np.ndarray, torch.Tensor, torch.Tensor]:
        """``n`` random elements: g [n, d, d], rho_S(g) and rho_A(g) (float64, CPU)."""
        if self._finite:
            index = torch.randint(len(self._elements), (n,), generator=self.generator)
            return self._elements[index.numpy()], self._rho_s[index], self._rho_a[index]
        seed = int(torch.randint(2**31 - 1, (), generator=self.generator))
        g = groups.sample(self.group, np.random.default_rng(seed), n)
        return (g, *self._matrices(g))

    def _matrices(self, g: np.ndarray) -> tuple[torch.Tensor, torch.Tensor]:
        sym = self.symmetry
        if all(f.rep in _BATCHED_REPS for f in sym.observation + sym.action):
            rho_s = _batched_block_matrices(sym.observation, sym.observation_size, g)
            rho_a = _batched_block_matrices(sym.action, sym.action_size, g)
        else:  # a representation added to the declaration format later: its own code
            rho_s = np.stack([sym.observation_matrix(h) for h in g])
            rho_a = np.stack([sym.action_matrix(h) for h in g])
        return torch.from_numpy(rho_s), torch.from_numpy(rho_a)

    def _slice_index(self, tensordict: TensorDictBase) -> tuple[torch.Tensor, int]:
        """Which element each entry of the batch gets (shape: the batch shape), and how many."""
        shape = tensordict.batch_size
        if self.slice_key is not None:
            ids = tensordict.get(self.slice_key).reshape(shape.numel(), -1)[:, 0].cpu()
            starts = torch.ones(len(ids), dtype=torch.long)
            starts[1:] = (ids[1:] != ids[:-1]).long()
            index = torch.cumsum(starts, 0) - 1
            return index.reshape(shape), int(index[-1]) + 1 if len(index) else 0
        if not shape:
            return torch.zeros((), dtype=torch.long), 1
        index = torch.arange(shape[0]).reshape(-1, *([1] * (len(shape) - 1))).expand(shape)
        return index, shape[0]

    def forward(self, tensordict: TensorDictBase) -> TensorDictBase:
        index, n = self._slice_index(tensordict)
        _, rho_s, rho_a = self.sample_elements(n)
        if self.check_action_domain:
            self._check_action_domain(tensordict)
        for keys, rho in ((self.observation_keys, rho_s), (self.action_keys, rho_a)):
            for key in keys:
                x = tensordict.get(key, None)
                if x is None:
                    raise KeyError(f"SymmetryAugment: {key!r} not in the sampled tensordict; "
                                   f"set observation_keys/action_keys (keys: {list(tensordict.keys(True))})")
                if not x.is_floating_point():  # a rotated integer vector is not an integer vector
                    x = x.to(torch.float64)
                if x.shape[-1] != rho.shape[-1]:
                    raise ValueError(f"{key!r} has last dimension {x.shape[-1]}, "
                                     f"the declaration {rho.shape[-1]}")
                m = rho.to(device=x.device, dtype=x.dtype)[index.to(x.device)]
                m = m.reshape(*index.shape, *[1] * (x.ndim - 1 - index.ndim), *m.shape[-2:])
                tensordict.set(key, (m @ x.unsqueeze(-1)).squeeze(-1))
        return tensordict

    def _check_action_domain(self, tensordict: TensorDictBase) -> None:
        for key in self.action_keys:
            action = tensordict.get(key).detach().cpu().numpy()
            in_domain = self.symmetry.action_in_domain(action)
            if not np.all(in_domain):
                raise ValueError(f"{self.group} may move box actions out of [-1, 1]; "
                                 f"{int((~in_domain).sum())} of {in_domain.size} sampled actions lie "
                                 f"outside the declared action domain ({self.symmetry.action_domain})")

    # ``ReplayBuffer.extend`` calls ``inv``: the base class's is the identity (no
    # ``in_keys_inv``), which is what a sample-time augmentation wants.

    def _call(self, next_tensordict: TensorDictBase) -> TensorDictBase:
        raise ValueError(ENV_ERROR)

    def _reset(self, tensordict: TensorDictBase, tensordict_reset: TensorDictBase) -> TensorDictBase:
        raise ValueError(ENV_ERROR)

    def _step(self, tensordict: TensorDictBase, next_tensordict: TensorDictBase) -> TensorDictBase:
        raise ValueError(ENV_ERROR)

    def __repr__(self) -> str:
        return (f"{type(self).__name__}(group={self.group}, observation_keys={self.observation_keys}, "
                f"action_keys={self.action_keys})")


_BATCHED_REPS = ("trivial", "sign", "vector", "pseudovector")


def _batched_block_matrices(fields: Sequence[Field], size: int, g: np.ndarray) -> np.ndarray:
    """``Symmetry.observation_matrix``/``action_matrix`` for a batch g [n, d, d] at once."""
    sign = np.sign(np.linalg.det(g))[:, None, None]
    out = np.zeros((len(g), size, size))
    for f in fields:
        block = {"trivial": np.ones_like(sign), "sign": sign, "vector": g, "pseudovector": sign * g}[f.rep]
        out[:, f.start : f.stop, f.start : f.stop] = block
    return out
