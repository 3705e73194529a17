"""TD-MPC's objective as a TorchRL ``LossModule``, with a target model for ``SoftUpdate``.

For a batch of horizon-length slices (obs_0, a_0, r_0, obs_1, ..., obs_H) it
unrolls the latent dynamics from h(obs_0) and sums, weighted by rho^t:

* latent consistency: |d(z_t, a_t) - h_target(obs_{t+1})|^2 (mean over latent),
* reward: |R(z_t, a_t) - r_t|^2,
* value: sum_i |Q_i(z_t, a_t) - (r_t + gamma (1 - terminated) min_j Q_target_j(z', pi(z')))|^2
  with z' = h(obs_{t+1}),
* policy: -min_i Q_i(z_t, pi(z_t) + noise) on detached latents, with Q's parameters
  detached, so this term trains the policy only.

Model terms are weighted by the replay's importance weights and scaled by
1/H as in TD-MPC. Unlike TD-MPC, which steps the model's optimiser before
computing the policy loss, both are computed in one pass (TorchRL's usual
single backward); the policy then sees the Q of before the step.
"""

from __future__ import annotations

import copy
import typing
from dataclasses import dataclass

import torch
import torch.nn.functional as F
from tensordict import TensorDict, TensorDictBase
from tensordict.nn import TensorDictParams
from torchrl.objectives import LossModule

from agents.compat.torchrl import expect_target_updater
from agents.nn.expansion import expansion_scope
from agents.nn.parameters import detached_parameters, parameter_slots
from agents.options import check, option
from agents.tdmpc.world_model import WorldModel


@dataclass
class LossConfig:
    """TD-MPC's loss coefficients (its defaults)."""

    KEY: typing.ClassVar[str] = "agent.loss"
    consistency_coef: float = option(2.0, low=0)
    reward_coef: float = option(0.5, low=0)
    value_coef: float = option(0.1, low=0)
    rho: float = option(0.5, low=0, low_open=True, high=1)
    discount: float = option(0.99, low=0, low_open=True, high=1)
    # TD-MPC's min_std: pi's noise in the TD target, pi loss and planner
    policy_noise: float = option(0.05, low=0)
    # TD-MPC clips that noise to +-0.3 (by norm for a vector field)
    noise_clip: float = option(0.3, low=0, low_open=True)
    # The policy loss's gradient through the projection of pi's noisy action onto the action
    # domain: false, the projection's own (zero where it clips); true, TD-MPC's straight-through
    # (as if nothing were clipped)
    straight_through: bool = False

    def __post_init__(self) -> None:
        check(self)


class TDMPCLoss(LossModule):
    """TD-MPC's losses over a [batch, horizon] TensorDict of transitions.

    Expected keys: ``observation``, ``action``, ``("next", "observation")``,
    ``("next", "reward")``, ``("next", "terminated")``, and optionally
    ``priority_weight`` (importance weights from prioritised replay).
    """

    def __init__(self, model: WorldModel, config: LossConfig) -> None:
        super().__init__()
        self.model, self.config = model, config
        self.target_model = copy.deepcopy(model).requires_grad_(False)
        # What TorchRL's SoftUpdate looks for: "<name>_params" and "target_<name>_params".
        self.model_params = TensorDict.from_module(model)
        self.target_model_params = TensorDictParams(
            TensorDict.from_module(self.target_model), no_convert=True)
        expect_target_updater(self, "model")  # until SoftUpdate registers itself
        self._q_slots = parameter_slots(model.qs)  # frozen in the policy loss

    def forward(self, batch: TensorDictBase) -> TensorDict:
        # One expansion of every equivariant weight of both models per call: the online
        # ones inside the graph, the target's from its current (SoftUpdate-written) values.
        with expansion_scope(self.model, self.target_model):
            return self._losses(batch)

    def _losses(self, batch: TensorDictBase) -> TensorDict:
        cfg, model = self.config, self.model
        obs, action = batch["observation"], batch["action"]
        next_obs, reward = batch["next", "observation"], batch["next", "reward"]
        not_done = 1.0 - batch["next", "terminated"].to(obs.dtype)
        horizon = obs.shape[1]
        weights = (batch["priority_weight"][:, 0] if "priority_weight" in batch.keys()
                   else torch.ones(obs.shape[0], device=obs.device))

        with torch.no_grad():
            z_next = model.encode(next_obs)
            target_z = self.target_model.encode(next_obs)
            next_action = model.pi(z_next, cfg.policy_noise, torch.randn(
                *z_next.shape[:-1], model.action_dim, dtype=z_next.dtype, device=z_next.device))
            target_q = self.target_model.min_q(z_next, next_action)
            td_target = reward + cfg.discount * not_done * target_q

        # The latent rollout is sequential; everything evaluated along it (Q, reward,
        # the losses) takes all horizon steps in one batch: the same sums as TD-MPC's
        # per-step loop, in a fifth of the network calls.
        z = model.encode(obs[:, 0])
        rollout = [z]
        for t in range(horizon):
            rollout.append(model.next(rollout[-1], action[:, t]))
        latents = torch.stack(rollout[:-1], dim=1)  # z_0 .. z_{H-1}: [batch, horizon, latent]
        predicted = torch.stack(rollout[1:], dim=1)  # d(z_t, a_t)
        q = model.q(latents, action)  # [num_q, batch, horizon, 1]
        reward_pred = model.reward(latents, action)
        rho = self._rho(horizon, obs)
        consistency = (rho * F.mse_loss(predicted, target_z, reduction="none").mean(-1)).sum(-1)
        reward_loss = (rho * F.mse_loss(reward_pred, reward, reduction="none").squeeze(-1)).sum(-1)
        td_error = q - td_target
        value_loss = (rho * td_error.square().sum(0).squeeze(-1)).sum(-1)
        priority = (rho * td_error.abs().sum(0).squeeze(-1)).sum(-1)
        q_first = q[:, :, 0].detach()

        model_loss = (cfg.consistency_coef * consistency + cfg.reward_coef * reward_loss
                      + cfg.value_coef * value_loss)
        return TensorDict({
            "loss_model": (model_loss * weights).mean() / horizon,
            "loss_pi": self.policy_loss(latents.detach()),
            "consistency": consistency.mean().detach(),
            "reward_error": reward_loss.mean().detach(),
            "value_error": value_loss.mean().detach(),
            "q_mean": q_first.mean(),
            "td_target_mean": td_target[:, 0].mean(),
            "priority": priority.detach(),
        }, batch_size=[])

    def policy_loss(self, latents: torch.Tensor) -> torch.Tensor:
        """-sum_t rho^t mean_batch min Q(z_t, pi(z_t)); trains pi only."""
        noise = torch.randn(*latents.shape[:-1], self.model.action_dim, dtype=latents.dtype,
                            device=latents.device)
        action = self.model.pi(latents, self.config.policy_noise, noise)
        with detached_parameters(self._q_slots):
            q = self.model.min_q(latents, action).squeeze(-1)
        return -(q.mean(0) * self._rho(latents.shape[1], latents)).sum()

    def _rho(self, horizon: int, like: torch.Tensor) -> torch.Tensor:
        """TD-MPC's per-step weights rho^t, t < horizon, on ``like``'s device and dtype."""
        return self.config.rho ** torch.arange(horizon, device=like.device, dtype=like.dtype)
