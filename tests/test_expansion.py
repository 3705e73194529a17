"""Equivariant weights are never stale: every way a parameter can be written is seen.

``EquivariantLinear`` expands its weight from escnn's basis coefficients; the agent
reuses an expansion only inside an explicit ``expansion_scope``. Each test writes
the parameters one way (optimisers, TorchRL's SoftUpdate, loads, writes through
``.data``, ``TensorDict.to_module``) and compares what the network computes (with
and without gradients, inside and outside a scope) against a fresh expansion.
"""

import copy
import itertools

import gymnasium
import pytest
import torch
import torch.nn.functional as F
from escnn import group as escnn_group
from escnn import gspaces
from escnn import nn as enn
from tensordict import TensorDict
from torchrl.objectives import SoftUpdate

from agents import Architecture, NetworkConfig, build_networks
from agents.nn.expansion import ScopedExpansion, expansion_scope
from agents.nn.layers import EquivariantLinear
from agents.nn.parameters import detached_parameters, parameter_slots
from agents.tdmpc.agent import TDMPCAgent, TDMPCConfig
from agents.tdmpc.loss import LossConfig, TDMPCLoss
from agents.tdmpc.world_model import WorldModel

SMALL = dict(hidden_dim=32, latent_dim=16, hidden_layers=2)
IN = 66  # the D8 dynamics input: 4 latent regular fields and the action


def pointmass2d():
    return gymnasium.make("GeoMDP/PointMass2D-v0").unwrapped.symmetry


def dynamics_net(group="D8", seed=0):
    torch.manual_seed(seed)
    return build_networks(NetworkConfig(group=group, networks=Architecture(**SMALL)), pointmass2d()).dynamics


def fresh_forward(net, x):
    """The network's function computed from its parameters as they are now."""
    for m in net.net:
        if isinstance(m, EquivariantLinear):
            weight, bias = m.layer.expand_parameters()
            x = F.linear(x, weight, bias)
        else:
            x = m(x)
    return x


def assert_uses_current_parameters(net, x):
    with torch.no_grad():
        expected = fresh_forward(net, x)
        outside = net(x)
        with expansion_scope(net):
            scoped = net(x)
    with expansion_scope(net):
        with_grad = net(x).detach()
    for name, got in (("no-grad call", outside), ("scoped no-grad call", scoped),
                      ("scoped call with gradients", with_grad)):
        torch.testing.assert_close(got, expected, atol=1e-6, rtol=1e-5, msg=name)


def step(net, optimizer, x):
    optimizer.zero_grad()
    with expansion_scope(net):
        net(x).pow(2).sum().backward()
    optimizer.step()


@pytest.mark.parametrize("kind", ["foreach", "fused"])
def test_adam_steps_are_seen(kind):
    net, x = dynamics_net(), torch.randn(16, IN)
    with torch.no_grad():
        before = net(x)
    optimizer = torch.optim.Adam(net.parameters(), lr=1e-2, **{kind: True})
    for _ in range(3):
        step(net, optimizer, x)
        assert_uses_current_parameters(net, x)
    with torch.no_grad():
        assert (net(x) - before).abs().max() > 1e-3


def test_writes_through_data_are_seen():
    net, x = dynamics_net(), torch.randn(16, IN)
    with torch.no_grad():
        net(x)  # any earlier use
    for p in net.parameters():
        p.data.add_(0.05)
    assert_uses_current_parameters(net, x)


def test_load_state_dict_is_seen():
    net, other, x = dynamics_net(seed=0), dynamics_net(seed=1), torch.randn(16, IN)
    with torch.no_grad():
        net(x)
    net.load_state_dict(other.state_dict())
    assert_uses_current_parameters(net, x)
    with torch.no_grad():
        torch.testing.assert_close(net(x), fresh_forward(other, x))


def test_swapped_in_parameters_are_seen_inside_and_outside_a_scope():
    net, other, x = dynamics_net(seed=0), dynamics_net(seed=1), torch.randn(16, IN)
    with torch.no_grad():
        expected, own = fresh_forward(other, x), fresh_forward(net, x)
    with expansion_scope(net):
        with TensorDict.from_module(other).detach().to_module(net):
            torch.testing.assert_close(net(x).detach(), expected)  # not the scope's weights
        # detached aliases of its own parameters (the policy loss's frozen Q): the
        # scope's weights, without a path to the parameters
        with TensorDict.from_module(net).detach().to_module(net):
            y = net(x.requires_grad_())
            y.sum().backward()
    torch.testing.assert_close(y.detach(), own)
    assert all(p.grad is None for p in net.parameters())
    assert x.grad is not None and x.grad.abs().max() > 0


def agent(group="D8", seed=0):
    cfg = TDMPCConfig.from_dict({"group": group, "networks": SMALL, "batch_size": 16,
                                 "horizon": 3, "tau": 0.2, "target_update_every": 1})
    sym = pointmass2d()
    return TDMPCAgent(cfg, sym, sym.observation_size, sym.action_size, seed=seed)


def batch(n=16, horizon=3, seed=0):
    g = torch.Generator().manual_seed(seed)
    return TensorDict({
        "observation": torch.randn(n, horizon, 4, generator=g) * 0.2,
        "action": torch.rand(n, horizon, 2, generator=g) * 1.4 - 0.7,
        "next": {"observation": torch.randn(n, horizon, 4, generator=g) * 0.2,
                 "reward": torch.rand(n, horizon, 1, generator=g),
                 "terminated": torch.zeros(n, horizon, 1, dtype=torch.bool)},
    }, batch_size=[n, horizon])


def target_heads(a):
    m = a.loss.target_model
    return {"encoder": m.encoder, "dynamics": m.dynamics, "reward": m.reward_net,
            "q0": m.qs[0], "q1": m.qs[1], "policy": m.policy}


def test_soft_update_moves_the_target_network_the_loss_uses():
    a, data = agent(), batch()
    inputs = {name: torch.randn(8, net.in_layout.size) for name, net in target_heads(a).items()}
    with torch.no_grad():
        initial = {name: net(inputs[name]) for name, net in target_heads(a).items()}
    lags = []
    for _ in range(5):
        a.update(data)
        lags.append(a.target_lag())
    for name, net in target_heads(a).items():
        assert_uses_current_parameters(net, inputs[name])
        with torch.no_grad():
            assert (net(inputs[name]) - initial[name]).abs().max() > 1e-4, f"target {name} frozen"
    assert 0 < lags[-1] < 1


def test_soft_update_through_torchrl_alone():
    """TorchRL's SoftUpdate writes with ``.data.lerp_``; the target follows."""
    sym = pointmass2d()
    nets = build_networks(NetworkConfig(group="D4", networks=Architecture(**SMALL)), sym)
    loss = TDMPCLoss(WorldModel(nets, sym.action), LossConfig())
    updater = SoftUpdate(loss, tau=0.5)
    x = torch.randn(8, loss.target_model.encoder.in_layout.size)
    with torch.no_grad():
        loss.target_model.encoder(x)  # used before the update, as in training
        for p in loss.model.parameters():
            p.add_(0.1)
    updater.step()
    assert_uses_current_parameters(loss.target_model.encoder, x)
    with torch.no_grad():
        assert (loss.target_model.encoder(x) - loss.model.encoder(x)).abs().max() > 1e-4


def test_checkpoint_round_trip_gives_the_same_networks(tmp_path):
    from agents.run import checkpoint
    from agents.tdmpc.replay import ReplayConfig, make_replay_buffer

    a, data = agent(), batch()
    for _ in range(4):
        a.update(data)
    buffer = make_replay_buffer(ReplayConfig(capacity=100), 3, 16)
    stored = data.reshape(-1)
    stored.set("episode", torch.zeros(stored.shape[0], dtype=torch.int64))
    buffer.extend(stored)
    checkpoint.save(tmp_path, a, buffer, {"env_step": 0})
    b = agent(seed=5)
    checkpoint.load(tmp_path, b, make_replay_buffer(ReplayConfig(capacity=100), 3, 16))
    for (name, net_a), net_b in zip(target_heads(a).items(), target_heads(b).values()):
        x = torch.randn(8, net_a.in_layout.size)
        assert_uses_current_parameters(net_b, x)
        with torch.no_grad():
            torch.testing.assert_close(net_b(x), net_a(x), msg=name)
    obs = torch.tensor([0.1, -0.2, 0.3, 0.0])
    a.generator.manual_seed(1), b.generator.manual_seed(1)
    torch.testing.assert_close(b.act(obs, step=10**6, explore=True),
                               a.act(obs, step=10**6, explore=True))


def test_scope_restores_the_outer_expansion_and_sees_grad_mode():
    net, x = dynamics_net(), torch.randn(4, IN)
    with torch.no_grad(), expansion_scope(net):
        with torch.enable_grad():
            # a no-grad scope must not cut gradients of a call that wants them
            net(x).sum().backward()
        assert all(p.grad is not None for p in net.parameters())
        with expansion_scope(net):
            pass
        assert all(m._scoped is not None for m in net.modules() if isinstance(m, ScopedExpansion))
    assert all(m._scoped is None for m in net.modules() if isinstance(m, ScopedExpansion))
    copy.deepcopy(net)  # no scope state travels


GROUPS = {"D8": lambda: escnn_group.dihedral_group(8), "C8": lambda: escnn_group.cyclic_group(8),
          "octahedral": escnn_group.octa_group, "icosahedral": escnn_group.ico_group,
          "SO2": lambda: escnn_group.so2_group(3), "O2": lambda: escnn_group.o2_group(3),
          "SO3": lambda: escnn_group.so3_group(2), "O3": lambda: escnn_group.o3_group(2)}


@pytest.mark.parametrize("name", GROUPS)
def test_expansion_equals_escnns(name):
    """``EquivariantLinear.expand`` (one GEMM per pair of field types) gives escnn's
    ``expand_parameters`` matrix, bias and coefficient gradients, for hidden, input and
    output layers, with the fields of one type adjacent or interleaved with others."""
    group = GROUPS[name]()
    space = gspaces.no_base_space(group)
    hidden = (group.bl_regular_representation(2) if group.continuous
              else group.regular_representation)
    vector = next(r for r in group.irreps() if r.size > 1)
    trivial = group.trivial_representation
    layouts = [([hidden] * 3, [hidden] * 3), ([vector, trivial, vector, hidden], [hidden] * 3),
               ([hidden] * 3 + [vector], [hidden] * 2), ([hidden] * 2, [trivial, vector, trivial]),
               ([vector, hidden, vector], [vector, trivial])]
    for (ins, outs), bias in itertools.product(layouts, (True, False)):
        layer = EquivariantLinear(enn.FieldType(space, ins), enn.FieldType(space, outs), bias=bias)
        with torch.no_grad():
            layer.layer.weights.normal_()
        weight, expanded_bias = layer.expand()
        reference, reference_bias = layer.layer.expand_parameters()
        torch.testing.assert_close(weight, reference, atol=1e-5, rtol=1e-5)
        assert (expanded_bias is None) == (reference_bias is None)
        probe = torch.randn_like(weight)
        ours = torch.autograd.grad((weight * probe).sum(), layer.layer.weights)[0]
        theirs = torch.autograd.grad((reference * probe).sum(), layer.layer.weights)[0]
        torch.testing.assert_close(ours, theirs, atol=1e-4, rtol=1e-4)


@pytest.mark.parametrize("group, layers", [(None, "dense"), ("D8", "dense"), ("D8", "fourier"),
                                           ("SO2", "dense")])
def test_detached_parameters_freeze_every_layer_kind(group, layers):
    """The policy loss's frozen Q: inside ``detached_parameters`` (and a scope) a network
    computes its usual values and sends gradients to its input only, whatever its layers
    (nn.Linear, EquivariantLinear, FourierLinear, FieldLayerNorm, SpectralLayerNorm);
    on exit its own Parameter objects are back and gradients reach them again."""
    torch.manual_seed(0)
    config = NetworkConfig(group=group, allow_approximate=True,
                           networks=Architecture(layers=layers, **SMALL))
    net = build_networks(config, pointmass2d()).qs[0]
    with torch.no_grad():
        for p in net.parameters():  # the output layer starts at zero
            p.add_(0.1 * torch.randn_like(p))
    params = list(net.parameters())
    x = torch.randn(16, net.in_layout if isinstance(net.in_layout, int) else net.in_layout.size)
    with expansion_scope(net):
        expected = net(x)
        with detached_parameters(parameter_slots(net)):
            frozen_x = x.clone().requires_grad_()
            y = net(frozen_x)
            y.sum().backward()
    torch.testing.assert_close(y.detach(), expected.detach())
    assert all(p.grad is None for p in params)
    assert frozen_x.grad is not None and frozen_x.grad.abs().max() > 0
    assert all(a is b for a, b in zip(net.parameters(), params))
    net(x).sum().backward()
    assert all(p.grad is not None for p in params)
