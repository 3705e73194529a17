"""TD-MPC's loss, batched over the horizon, against TD-MPC's per-step loop.

``TDMPCLoss`` evaluates Q and the reward for all horizon steps in one call;
``reference_losses`` below is the loop of TD-MPC's ``update`` (Hansen et al.
2022, Algorithm 1), one network call per step. Both must give the same losses,
priorities and gradients, plain and equivariant.
"""

import gymnasium
import pytest
import torch
import torch.nn.functional as F
from tensordict import TensorDict

from agents import Architecture, NetworkConfig, build_networks
from agents.nn.expansion import expansion_scope
from agents.tdmpc.loss import LossConfig, TDMPCLoss
from agents.tdmpc.world_model import WorldModel

BATCH, HORIZON = 16, 4


def make_loss(group: str) -> TDMPCLoss:
    symmetry = gymnasium.make("GeoMDP/PointMass2D-v0").unwrapped.symmetry
    torch.manual_seed(0)
    networks = build_networks(NetworkConfig(group=group, networks=Architecture(
        hidden_dim=32, latent_dim=16, hidden_layers=2)), symmetry)
    model = WorldModel(networks, symmetry.action)
    loss = TDMPCLoss(model, LossConfig())
    with torch.no_grad():  # a target that differs from the online model
        for p in loss.target_model.parameters():
            p.add_(0.05 * torch.randn_like(p))
    return loss


def make_batch() -> TensorDict:
    g = torch.Generator().manual_seed(1)
    obs = torch.randn(BATCH, HORIZON + 1, 4, generator=g)
    return TensorDict({
        "observation": obs[:, :-1],
        "action": torch.rand(BATCH, HORIZON, 2, generator=g) * 1.4 - 0.7,
        "next": {"observation": obs[:, 1:], "reward": torch.rand(BATCH, HORIZON, 1, generator=g),
                 "terminated": torch.rand(BATCH, HORIZON, 1, generator=g) < 0.1},
        "priority_weight": torch.rand(BATCH, HORIZON, generator=g) + 0.5,
    }, batch_size=[BATCH, HORIZON])


def reference_losses(loss: TDMPCLoss, batch: TensorDict) -> dict[str, torch.Tensor]:
    """TD-MPC's loop: per step t, Q(z_t, a_t), R(z_t, a_t), z_{t+1} = d(z_t, a_t)."""
    cfg, model = loss.config, loss.model
    obs, action = batch["observation"], batch["action"]
    next_obs, reward = batch["next", "observation"], batch["next", "reward"]
    not_done = 1.0 - batch["next", "terminated"].float()
    with torch.no_grad():
        z_next = model.encode(next_obs)
        target_z = loss.target_model.encode(next_obs)
        noise = torch.randn(*z_next.shape[:-1], model.action_dim)
        next_action = model.pi(z_next, cfg.policy_noise, noise)
        td_target = reward + cfg.discount * not_done * loss.target_model.q(
            z_next, next_action).min(dim=0).values
    z = model.encode(obs[:, 0])
    consistency = reward_loss = value_loss = priority = 0.0
    latents = []
    for t in range(HORIZON):
        latents.append(z.detach())
        q = model.q(z, action[:, t])
        reward_pred = model.reward(z, action[:, t])
        z = model.next(z, action[:, t])
        rho = cfg.rho ** t
        consistency = consistency + rho * ((z - target_z[:, t]) ** 2).mean(-1)
        reward_loss = reward_loss + rho * ((reward_pred - reward[:, t]) ** 2).squeeze(-1)
        value_loss = value_loss + rho * ((q - td_target[:, t]) ** 2).sum(0).squeeze(-1)
        priority = priority + rho * (q - td_target[:, t]).abs().sum(0).squeeze(-1)
    model_loss = (cfg.consistency_coef * consistency + cfg.reward_coef * reward_loss
                  + cfg.value_coef * value_loss)
    return {"loss_model": (model_loss * batch["priority_weight"][:, 0]).mean() / HORIZON,
            "loss_pi": loss.policy_loss(torch.stack(latents, dim=1)),
            "consistency": consistency.mean(), "reward_error": reward_loss.mean(),
            "value_error": value_loss.mean(), "priority": priority}


def gradients(loss: TDMPCLoss, total: torch.Tensor) -> list[torch.Tensor]:
    params = [p for p in loss.model.parameters() if p.requires_grad]
    return torch.autograd.grad(total, params, allow_unused=True, materialize_grads=True)


@pytest.mark.parametrize("group", ["none", "D4"])
def test_batched_horizon_equals_tdmpc_per_step_loop(group: str) -> None:
    loss, batch = make_loss(group), make_batch()
    torch.manual_seed(2)
    got = loss(batch)
    torch.manual_seed(2)  # the same noise for pi in the TD target and the policy loss
    with expansion_scope(loss.model, loss.target_model):
        want = reference_losses(loss, batch)
    for key, value in want.items():
        torch.testing.assert_close(got[key], value.detach() if key != "loss_model" else value,
                                   rtol=1e-5, atol=1e-6, msg=key)
    assert got["loss_model"] > 0 and got["value_error"] > 0  # not a vacuous comparison
    ours = gradients(loss, got["loss_model"] + got["loss_pi"])
    theirs = gradients(loss, want["loss_model"] + want["loss_pi"])
    for a, b in zip(ours, theirs, strict=True):
        torch.testing.assert_close(a, b, rtol=1e-4, atol=1e-6)
    assert any(a.abs().sum() > 0 for a in ours)


def test_a_wrong_step_weight_is_detected() -> None:
    """The comparison above can fail: the reference with rho^(t+1) differs."""
    loss, batch = make_loss("none"), make_batch()
    torch.manual_seed(2)
    got = loss(batch)
    loss.config.rho = 0.25  # what the loop would compute with a mis-indexed weight
    torch.manual_seed(2)
    with expansion_scope(loss.model, loss.target_model):
        want = reference_losses(loss, batch)
    assert not torch.allclose(got["loss_model"], want["loss_model"], rtol=1e-3)
    assert F.l1_loss(got["priority"], want["priority"]) > 1e-4


@pytest.mark.parametrize("group", ["none", "D4"])
def test_straight_through_passes_the_gradient_of_pis_mean_where_the_domain_clips(group: str) -> None:
    """agent.loss.straight_through (TD-MPC's): pi's noisy action has the same value, and its
    gradient is the mean's, also where the projection onto the action domain clips it;
    without it the projection's own gradient (zero where a coordinate is clipped) stays."""
    loss = make_loss(group)
    model = loss.model
    with torch.no_grad():  # a policy pushed to the edge of the domain, so that noise leaves it
        for p in model.policy.net[-1].parameters():
            p.mul_(30.0)
        z = model.encode(torch.randn(64, 4, generator=torch.Generator().manual_seed(5)))
    z.requires_grad_(True)
    noise = torch.randn(64, model.action_dim, generator=torch.Generator().manual_seed(6))

    def gradient_and_value(straight_through: bool, std: float = 1.0):
        model.straight_through = straight_through
        action = model.pi(z, std, noise)
        (grad,) = torch.autograd.grad(action.sum(), z)
        return grad, action.detach()

    mean_grad, _ = gradient_and_value(False, std=0.0)
    through, value = gradient_and_value(True)
    clipped, same_value = gradient_and_value(False)
    torch.testing.assert_close(value, same_value, rtol=0, atol=0)
    torch.testing.assert_close(through, mean_grad)
    assert (clipped - mean_grad).abs().max() > 1e-3, "the projection clipped nothing: no test"


def test_the_agent_passes_straight_through_to_its_model() -> None:
    from agents.tdmpc.agent import TDMPCAgent, TDMPCConfig

    for flag in (False, True):
        config = TDMPCConfig.from_dict({"networks": {"hidden_dim": 16, "latent_dim": 8},
                                        "loss": {"straight_through": flag}, "batch_size": 4})
        assert TDMPCAgent(config, None, 4, 2).model.straight_through is flag


@pytest.mark.parametrize("group", ["none", "D4"])
def test_without_reward_the_heads_stay_zero_and_any_reward_wakes_them(group: str) -> None:
    """Before any reward TD-MPC's zero-initialised reward and Q heads stay exactly 0 (so
    every plan ties); a reward of 1e-25 anywhere in the batch is enough to wake them:
    Adam divides a gradient far below its eps (1e-8) by eps, a step of lr/eps = 1e5
    times the gradient, so the heads grow about that much per update until their
    gradients reach eps's scale (RESULTS.md, C4, "What acts is the planner")."""
    from agents.tdmpc.agent import TDMPCAgent, TDMPCConfig

    symmetry = gymnasium.make("GeoMDP/PointMass2D-v0").unwrapped.symmetry
    batch = make_batch()
    batch["next", "terminated"].zero_()
    heads = {}
    for reward in (0.0, 1e-25):
        config = TDMPCConfig.from_dict({"group": group, "batch_size": BATCH, "networks": {
            "hidden_dim": 32, "latent_dim": 16}})
        agent = TDMPCAgent(config, symmetry, 4, 2, seed=0)
        batch["next", "reward"].fill_(reward)
        for _ in range(8):
            agent.update(batch.exclude("priority_weight"))
        obs = batch["observation"][:, 0]
        heads[reward] = max(float(agent.value(obs).abs().max()), float(agent.predicted_reward(
            obs, batch["action"][:, 0]).abs().max()))
    assert heads[0.0] == 0.0
    assert heads[1e-25] > 1e-6, heads  # 1e19 times the reward after 8 updates (measured: 6e-3, 9e-3)
