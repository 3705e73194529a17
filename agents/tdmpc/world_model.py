"""TD-MPC's task-oriented latent dynamics model (TOLD), over plain or equivariant networks."""

from __future__ import annotations

import torch
from torch import nn

from agents.nn.networks import Networks, project, squash
from geomdp_envs.symmetry import Field


class WorldModel(nn.Module):
    """Encoder h, latent dynamics d, reward R, Q ensemble and policy pi.

    Equivariance is a property of the networks it is given; the model itself
    only adds TD-MPC's action handling, in the equivariant form: the policy's
    output is squashed into the action domain by ``squash`` (unit ball per
    vector field), and exploration noise is isotropic per vector field,
    projected back onto the domain.
    """

    def __init__(self, networks: Networks, action_fields: tuple[Field, ...],
                 noise_clip: float = 0.3, straight_through: bool = False) -> None:
        super().__init__()
        self.noise_clip, self.straight_through = noise_clip, straight_through
        self.encoder = networks.encoder
        self.dynamics = networks.dynamics
        self.reward_net = networks.reward
        self.qs = networks.qs
        self.policy = networks.policy
        self.action_fields = action_fields
        self.action_dim = action_fields[-1].stop

    def encode(self, obs: torch.Tensor) -> torch.Tensor:
        return self.encoder(obs)

    def next(self, z: torch.Tensor, action: torch.Tensor) -> torch.Tensor:
        return self.dynamics(torch.cat([z, action], dim=-1))

    def reward(self, z: torch.Tensor, action: torch.Tensor) -> torch.Tensor:
        return self.reward_net(torch.cat([z, action], dim=-1))

    def q(self, z: torch.Tensor, action: torch.Tensor) -> torch.Tensor:
        """All Q estimates, stacked: [num_q, ..., 1]."""
        za = torch.cat([z, action], dim=-1)
        return torch.stack([q(za) for q in self.qs])

    def min_q(self, z: torch.Tensor, action: torch.Tensor) -> torch.Tensor:
        """The ensemble's pessimistic estimate min_i Q_i(z, action): [..., 1]. What TD-MPC's
        TD targets, policy loss and planner's terminal value all use."""
        return self.q(z, action).min(dim=0).values

    def pi(self, z: torch.Tensor, std: float = 0.0,
           noise: torch.Tensor | None = None) -> torch.Tensor:
        """The policy's action, plus ``std`` times ``noise`` (standard normal) if given.

        As TD-MPC's truncated normal: the noise is clipped to ``noise_clip`` (by norm
        for a vector field, which keeps the clip equivariant), and the sum is
        projected back onto the action domain; with ``straight_through`` the gradient
        passes that projection as if it were the identity (TD-MPC's; equivariant too).
        """
        mean = squash(self.policy(z), self.action_fields)
        if std <= 0 or noise is None:
            return mean
        noisy = mean + project(std * noise, self.action_fields, radius=self.noise_clip)
        action = project(noisy, self.action_fields)
        if not self.straight_through:
            return action
        return noisy - noisy.detach() + action.detach()  # exactly ``action``, noisy's gradient
