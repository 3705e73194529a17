"""Symmetry augmentation of replayed slices (``agent.augment``): the cheapest use of a
declared symmetry, for a plain agent to be compared with an equivariant one.

Each sampled slice, its whole horizon as one, is moved by one random element g of a
subgroup of the task's exact group: observations and next observations by rho_S(g),
actions by rho_A(g); rewards and done flags stay. That is a slice the task could have
produced (``tests/test_augmentation.py`` replays it in the simulator). The group action
is the task's declaration applied by ``geomdp_envs``' ``SymmetryAugment``; this module
only chooses the group and keeps the generator's state for checkpoints.
"""

from __future__ import annotations

import torch
from tensordict import TensorDictBase

from agents.nn.escnn_groups import CONTINUOUS_GROUPS
from agents.options import OptionError
from geomdp_envs import groups
from geomdp_envs.augment import default_augmentation_group
from geomdp_envs.symmetry import Symmetry
from geomdp_envs.torchrl_augment import SymmetryAugment


def is_augmentation_group_name(name: str) -> bool:
    """Whether ``agent.augment=<name>`` names a group at all (the task decides if it fits)."""
    try:
        groups.group_dim(CONTINUOUS_GROUPS.get(name, (name,))[0])
    except ValueError:
        return False
    return True


def augmentation_group(name: str, symmetry: Symmetry | None) -> str:
    """The group ``agent.augment=<name>`` draws from: ``auto`` is the largest subgroup of
    the task's exact group that keeps every action in its domain (box actions in the box,
    ``default_augmentation_group``); a named group must be a subgroup of that one."""
    if symmetry is None:
        raise OptionError(f"agent.augment={name} needs a task that declares its symmetry; this "
                          "one does not: use agent.augment=none")
    largest = default_augmentation_group(symmetry)
    group = largest if name == "auto" else CONTINUOUS_GROUPS.get(name, (name,))[0]
    try:
        valid = groups.is_subgroup(group, largest)
    except ValueError:  # not a group name
        valid = False
    if not valid:
        raise OptionError(f"agent.augment={name} is not a subgroup of {largest}, the largest "
                          f"group that is exact for this task (exact group: "
                          f"{symmetry.exact_group}) and keeps actions in their domain; valid: "
                          f"none, auto (= {largest}), or a subgroup of it such as "
                          f"{'C4, D2' if symmetry.dim == 2 else 'octahedral'}")
    return group


class SliceAugmentation:
    """Moves a [batch, horizon] TensorDict of slices, one group element per slice."""

    def __init__(self, name: str, symmetry: Symmetry | None, seed: int) -> None:
        self.group = augmentation_group(name, symmetry)
        self.transform = SymmetryAugment(symmetry, self.group, seed=seed)

    def __call__(self, batch: TensorDictBase) -> TensorDictBase:
        return self.transform(batch.clone(recurse=False))  # new entries, the same storage

    @property
    def generator(self) -> torch.Generator:
        """The generator the elements are drawn with (saved in checkpoints)."""
        return self.transform.generator
