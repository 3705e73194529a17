"""Data augmentation from a symmetry declaration, for agents without equivariant networks.

A transition (s, a, r, s') of a Geometric MDP has the same probability as
(g.s, g.a, r, g.s') for every g of its exact group, so an off-policy agent can
train on transformed copies of its replay data. Works on numpy arrays and on
torch tensors.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from geomdp_envs import groups
from geomdp_envs.symmetry import Symmetry, as_float


def default_augmentation_group(symmetry: Symmetry) -> str:
    """The largest group that is exact for the task and keeps box actions in the box.

    A box [-1, 1]^d of actions is closed only under signed permutations, so when
    actions contain vector fields the exact group is cut down to them (D4 in the
    plane, the full octahedral group in space). Scalar-only actions (e.g.
    Reacher's torques) keep the whole exact group.
    """
    if all(f.rep in ("trivial", "sign") for f in symmetry.action):
        return symmetry.exact_group
    signed_permutations = "D4" if symmetry.dim == 2 else "full_octahedral"
    if groups.is_subgroup(signed_permutations, symmetry.exact_group):
        return signed_permutations
    return "C4" if groups.is_subgroup("C4", symmetry.exact_group) else "octahedral"


def augment_transitions(symmetry: Symmetry, obs: Any, action: Any, next_obs: Any,
                        rng: np.random.Generator, group: str | None = None,
                        ) -> tuple[Any, Any, Any]:
    """Transform a batch [B, ...] of transitions, one random group element each.

    Rewards are invariant and need no change. ``group`` defaults to
    ``default_augmentation_group``; a group that can take actions out of the
    box [-1, 1]^d is refused unless every action lies in the declared action
    domain (unit ball per vector field).
    """
    group = group or default_augmentation_group(symmetry)
    if not groups.is_subgroup(group, symmetry.exact_group):
        raise ValueError(f"{group} is not a symmetry of this task (exact group: "
                         f"{symmetry.exact_group}); try {default_augmentation_group(symmetry)}")
    batch = obs.shape[0]
    if group != default_augmentation_group(symmetry):
        in_domain = symmetry.action_in_domain(np.asarray(_to_numpy(action)))
        if not np.all(in_domain):
            raise ValueError(f"{group} may move box actions out of [-1, 1]; "
                             f"{int((~in_domain).sum())} of {batch} actions lie outside "
                             f"the declared action domain ({symmetry.action_domain})")
    elements = groups.sample(group, rng, batch)
    rho_s = np.stack([symmetry.observation_matrix(g) for g in elements])
    rho_a = np.stack([symmetry.action_matrix(g) for g in elements])
    return _batched(rho_s, obs), _batched(rho_a, action), _batched(rho_s, next_obs)


def _to_numpy(x: Any) -> Any:
    return x.detach().cpu().numpy() if hasattr(x, "detach") else x


def _batched(matrices: np.ndarray, x: Any) -> Any:
    """y[b] = matrices[b] @ x[b], keeping x's type, device and float dtype (ints become float64)."""
    x = as_float(x)
    if isinstance(x, np.ndarray):
        return np.einsum("bij,bj->bi", matrices, x).astype(x.dtype, copy=False)
    import torch

    m = torch.as_tensor(matrices, dtype=x.dtype, device=x.device)
    return torch.einsum("bij,bj->bi", m, x)
