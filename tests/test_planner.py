"""plan(g.s) = g.plan(s) for the assembled equivariant agent, given g-transformed noise."""

import gymnasium
import numpy as np
import pytest
import torch

from agents.nn.expansion import expansion_scope
from agents.tdmpc.agent import TDMPCAgent, TDMPCConfig
from agents.tdmpc.planner import NoiseSource
from geomdp_envs import declare, groups, symmetry_of


class RecordingNoise(NoiseSource):
    def __init__(self, seed):
        super().__init__(torch.Generator().manual_seed(seed))
        self.normals, self.choices = [], []

    def normal(self, shape, like):
        x = super().normal(shape, like)
        self.normals.append(x)
        return x

    def choice(self, probs):
        self.choices.append(super().choice(probs))
        return self.choices[-1]


class TransformedNoise(NoiseSource):
    """Replays recorded noise with the action dimension moved by rho_A(g)."""

    def __init__(self, recording, rho_a):
        self.normals, self.choices = list(recording.normals), list(recording.choices)
        self.rho_a = torch.as_tensor(rho_a)

    def normal(self, shape, like):
        x = self.normals.pop(0)
        assert x.shape == shape
        return x @ self.rho_a.to(x).T

    def choice(self, probs):
        return self.choices.pop(0)


@pytest.fixture
def make_agent(randomise_heads):
    return lambda env_id, kwargs, group: _make_agent(env_id, kwargs, group, randomise_heads)


# third-party envs, with the declaration they are trained with (geomdp_envs.declare)
DECLARED = {"Reacher-v5": "reacher_v5", "InvertedPendulum-v5": "inverted_pendulum_v5"}


def _make_agent(env_id, kwargs, group, randomise_heads):
    env = gymnasium.make(env_id, **kwargs)
    if env_id in DECLARED:
        env = declare(env, DECLARED[env_id])
    sym = symmetry_of(env)
    cfg = TDMPCConfig.from_dict({
        "group": group, "networks": {"hidden_dim": 32, "latent_dim": 16},
        "planner": {"num_samples": 64, "num_elites": 8, "num_pi_trajs": 8, "iterations": 3},
        "horizon": 3, "batch_size": 8})
    torch.manual_seed(0)  # the same networks whichever tests ran before
    agent = TDMPCAgent(cfg, sym, sym.observation_size, sym.action_size)
    randomise_heads(agent.networks)
    agent.model.double()
    return env, sym, agent


def plan_twice(agent, obs, noise):
    """Two consecutive plans: the second is warm-started from the first."""
    agent.planner.reset()
    return [agent.planner.plan(o, horizon=3, min_std=0.1, explore=True, noise=noise)
            for o in obs]


EQUIVARIANT_CASES = pytest.mark.parametrize("env_id, kwargs, group, element", [
    ("GeoMDP/PointMass2D-v0", {}, "D8", groups.rotation_2d(3 * np.pi / 4) @ np.diag([1.0, -1])),
    ("GeoMDP/Reacher-v0", {}, "D4", np.diag([1.0, -1])),
    ("GeoMDP/PointMass3D-v0", {"n_balls": 2}, "octahedral", None),
    ("GeoMDP/PointMass3D-v0", {}, "icosahedral", None),
    ("Reacher-v5", {}, "D8", groups.rotation_2d(np.pi / 4) @ np.diag([1.0, -1])),
    ("InvertedPendulum-v5", {}, "D1", np.diag([1.0, -1])),
])


def _element(agent, element):
    """The given group element, or the 8th of the agent's group (3D groups)."""
    return element if element is not None else agent.networks.group.element_matrix(
        agent.networks.group.elements()[7])


@EQUIVARIANT_CASES
def test_planner_is_equivariant(env_id, kwargs, group, element, make_agent):
    env, sym, agent = make_agent(env_id, kwargs, group)
    g = _element(agent, element)
    obs = [torch.as_tensor(env.reset(seed=s)[0], dtype=torch.float64) for s in (0, 1)]
    recording = RecordingNoise(seed=0)
    actions = plan_twice(agent, obs, recording)
    moved = [torch.as_tensor(sym.transform_observation(o.numpy(), g)) for o in obs]
    moved_actions = plan_twice(agent, moved, TransformedNoise(recording, sym.action_matrix(g)))
    for a, b in zip(actions, moved_actions):
        np.testing.assert_allclose(b.numpy(), sym.transform_action(a.numpy(), g), atol=1e-8)
    assert sym.action_in_domain(np.stack([a.numpy() for a in actions])).all()


def test_plain_planner_is_not_equivariant(make_agent):
    """The same test fails for a plain agent: it can tell."""
    env, sym, agent = make_agent("GeoMDP/PointMass2D-v0", {}, None)
    g = groups.rotation_2d(np.pi / 2)
    obs = [torch.as_tensor(env.reset(seed=0)[0], dtype=torch.float64)]
    recording = RecordingNoise(seed=0)
    a = plan_twice(agent, obs, recording)[0]
    moved = [torch.as_tensor(sym.transform_observation(o.numpy(), g)) for o in obs]
    b = plan_twice(agent, moved, TransformedNoise(recording, sym.action_matrix(g)))[0]
    assert np.abs(b.numpy() - sym.transform_action(a.numpy(), g)).max() > 1e-3


@pytest.mark.parametrize("group", [None, "D8"])
def test_q_heads_are_each_online_head_and_value_their_minimum(make_agent, group):
    """q_heads: every online Q head at (h(obs), pi(h(obs))), one row per head; value is
    their minimum, bitwise (what TD targets and the planner use), for one state and a batch."""
    env, sym, agent = make_agent("GeoMDP/PointMass2D-v0", {}, group)
    batch = torch.stack([torch.as_tensor(env.reset(seed=i)[0], dtype=torch.float64)
                         for i in range(5)])
    for obs in (batch, batch[0]):
        heads = agent.q_heads(obs)
        assert heads.shape == (len(agent.model.qs), *obs.shape[:-1])
        with torch.no_grad(), expansion_scope(agent.model):
            z = agent.model.encode(obs)
            expected = torch.stack([q(torch.cat([z, agent.model.pi(z)], -1)) for q in agent.model.qs])
        torch.testing.assert_close(heads, expected.squeeze(-1), rtol=0, atol=1e-12)
        assert torch.equal(agent.value(obs), heads.min(dim=0).values)
    assert (heads[0] != heads[1]).any()  # randomised heads: the minimum picks one of two


def test_plan_values_are_the_last_iteration_best_sample_and_best_proposal(make_agent, monkeypatch):
    """plan_with_values: the same action as plan, and the best value among the Gaussian
    samples and among the policy's proposals, split where the candidates are split."""
    env, sym, agent = make_agent("GeoMDP/PointMass2D-v0", {}, None)
    obs = torch.as_tensor(env.reset(seed=0)[0], dtype=torch.float64)
    planner, cfg = agent.planner, agent.planner.config
    planner.reset()
    action = planner.plan(obs, horizon=3, min_std=0.1, explore=True, noise=RecordingNoise(1))
    planner.reset()
    same, values = planner.plan_with_values(obs, horizon=3, min_std=0.1, explore=True,
                                            noise=RecordingNoise(1))
    assert torch.equal(action, same)
    assert values.best_sampled.ndim == 0 and torch.isfinite(values.best_sampled)
    # candidates valued by position: samples 0..num_samples-1, then the proposals; the last
    # iteration's best sample is the last sample, its best proposal the last proposal
    count = cfg.num_samples + cfg.num_pi_trajs
    ranked = torch.arange(count, dtype=torch.float64).unsqueeze(1)
    monkeypatch.setattr(planner, "estimate_value", lambda z, actions, noise: ranked.clone())
    _, values = planner.plan_with_values(obs, horizon=3, min_std=0.1, explore=False,
                                         noise=RecordingNoise(2))
    assert values.best_sampled == cfg.num_samples - 1 and values.best_proposed == count - 1
    monkeypatch.setattr(cfg, "num_pi_trajs", 0)
    monkeypatch.setattr(planner, "estimate_value",
                        lambda z, actions, noise: ranked[:cfg.num_samples].clone())
    _, values = planner.plan_with_values(obs, horizon=3, min_std=0.1, explore=False,
                                         noise=RecordingNoise(3))
    assert values.best_proposed is None and values.best_sampled == cfg.num_samples - 1


@EQUIVARIANT_CASES
def test_value_is_invariant_and_policy_action_equivariant(env_id, kwargs, group, element,
                                                         make_agent):
    """What inspect_run compares with the returns: V(g.s) = V(s), pi(g.s) = g.pi(s), the
    predicted reward R(g.s, g.a) = R(s, a); and V is the TD targets' min_i Q_i(z, pi(z))."""
    env, sym, agent = make_agent(env_id, kwargs, group)
    g = _element(agent, element)
    obs = torch.as_tensor(np.stack([env.reset(seed=s)[0] for s in (0, 1, 2)]), dtype=torch.float64)
    moved = torch.as_tensor(sym.transform_observation(obs.numpy(), g))
    value, action = agent.value(obs), agent.policy_action(obs)
    assert value.shape == (3,) and value.dtype == torch.float64
    np.testing.assert_allclose(agent.value(moved).numpy(), value.numpy(), atol=1e-8)
    # escnn's bases are float32 (a double model holds them rounded), so equivariance holds
    # to float32's relative precision, not double's
    np.testing.assert_allclose(agent.policy_action(moved).numpy(),
                               sym.transform_action(action.numpy(), g), rtol=1e-6, atol=1e-8)
    z = agent.model.encode(obs)
    q = agent.model.q(z, agent.model.pi(z))
    assert q.shape[0] == agent.config.networks.num_q
    np.testing.assert_allclose(value.numpy(), q.min(dim=0).values.squeeze(-1).detach().numpy())
    assert (q.max(dim=0).values.squeeze(-1).detach() - value).abs().max() > 1e-6  # the min, not any
    # and the reward model inspect_run compares with the rewards: R(g.s, g.a) = R(s, a)
    reward = agent.predicted_reward(obs, action)
    assert reward.shape == (3,) and reward.abs().max() > 1e-6  # randomised heads: not the zero init
    moved_action = torch.as_tensor(sym.transform_action(action.numpy(), g))
    np.testing.assert_allclose(agent.predicted_reward(moved, moved_action).numpy(), reward.numpy(),
                               atol=1e-8)
    np.testing.assert_allclose(reward.numpy(),
                               agent.model.reward(z, action).squeeze(-1).detach().numpy())


def test_plain_value_is_not_invariant(make_agent):
    env, sym, agent = make_agent("GeoMDP/PointMass2D-v0", {}, None)
    obs = torch.as_tensor(env.reset(seed=0)[0], dtype=torch.float64)
    g = groups.rotation_2d(np.pi / 2)
    moved = torch.as_tensor(sym.transform_observation(obs.numpy(), g))
    assert abs(float(agent.value(moved)) - float(agent.value(obs))) > 1e-4
    # the plain agent's reward read is its reward head too (inspect_run's line), and not invariant
    action = agent.policy_action(obs)
    reward = agent.predicted_reward(obs, action)
    np.testing.assert_allclose(float(reward),
                               float(agent.model.reward(agent.model.encode(obs), action).detach()))
    moved_action = torch.as_tensor(sym.transform_action(action.numpy(), g))
    assert abs(float(agent.predicted_reward(moved, moved_action)) - float(reward)) > 1e-6
