"""Equivariance of the networks built from the declarations, per group and per head."""

from dataclasses import replace

import gymnasium
import numpy as np
import pytest
import torch

from agents import Architecture, NetworkConfig, build_networks, group_for_task, make_group, squash
from agents.nn.layers import EquivariantLinear, FieldLayerNorm
from agents.nn.layout import layout_size
from agents.nn.networks import project, regular_copies
from agents.nn.parameters import submodules
from agents.options import OptionError
from geomdp_envs import groups
from geomdp_envs.declare import declare

SMALL = Architecture(hidden_dim=24, latent_dim=16, hidden_layers=2)
TASKS_2D = {"pointmass2d": ("GeoMDP/PointMass2D-v0", {}),
            "reacher": ("GeoMDP/Reacher-v0", {})}
TASK_3D = ("GeoMDP/PointMass3D-v0", {"n_balls": 2})
# Third-party envs with a shipped declaration (non-contiguous fields, reordered by declare)
DECLARED = {"reacher_v5": "Reacher-v5", "inverted_pendulum_v5": "InvertedPendulum-v5"}


def declaration(env_id, kwargs):
    return gymnasium.make(env_id, **kwargs).unwrapped.symmetry


def task_symmetry(task):
    if task in DECLARED:
        return declare(gymnasium.make(DECLARED[task]), task).symmetry
    return declaration(*TASK_3D) if task == "pointmass3d" else declaration(*TASKS_2D[task])


def rep(layout, element):
    return torch.as_tensor(np.asarray(layout.representation(element)), dtype=torch.float32)


def elements_of(group, max_elements=16, seed=0):
    elements = group.elements()
    if len(elements) > max_elements:
        idx = np.random.default_rng(seed).choice(len(elements), max_elements, replace=False)
        elements = [elements[i] for i in idx]
    return elements


def relative_error(a, b):
    return ((a - b).norm() / b.norm().clamp_min(1e-12)).item()


def heads(nets):
    """(name, network) of every head, each Q of the ensemble on its own."""
    for name, net in nets.modules().items():
        yield from ((f"{name}{i}", q) for i, q in enumerate(net)) if name == "qs" else [(name, net)]


def assert_every_head_equivariant(nets):
    torch.manual_seed(0)
    for name, net in heads(nets):
        x = torch.randn(32, net.in_layout.size)
        y = net(x)
        for e in elements_of(nets.group):
            err = relative_error(net(x @ rep(net.in_layout, e).T), y @ rep(net.out_layout, e).T)
            assert err < 1e-4, f"{name} not equivariant to {e}: relative error {err:.1e}"


CASES = [(g, "pointmass2d") for g in ("C4", "C8", "C16", "D4", "D8", "D16")] + \
        [("D8", "reacher"), ("C8", "reacher"), ("D1", "pointmass2d")] + \
        [("D8", "reacher_v5"), ("D1", "inverted_pendulum_v5")] + \
        [(g, "pointmass3d") for g in ("octahedral", "icosahedral")]


@pytest.mark.parametrize("group_name, task", CASES)
@pytest.mark.parametrize("strategy", ["sqrt", "linear"])
def test_every_network_is_equivariant_for_every_group_element(group_name, task, strategy,
                                                            randomise_heads):
    sym = task_symmetry(task)
    assert_every_head_equivariant(randomise_heads(build_networks(
        NetworkConfig(group=group_name, width_strategy=strategy, networks=SMALL), sym)))


@pytest.mark.parametrize("group_name, task, outside", [
    ("D4", "pointmass2d", groups.rotation_2d(np.pi / 4)),
    ("D8", "reacher", groups.rotation_2d(np.pi / 8)),
    ("C16", "pointmass2d", groups.rotation_2d(np.pi / 16)),
    ("octahedral", "pointmass3d", groups.rotation_3d([1.0, 2.0, 3.0], 0.7)),
    ("icosahedral", "pointmass3d", groups.rotation_3d([1.0, 2.0, 3.0], 0.7)),
])
def test_reward_is_invariant_inside_the_group_and_not_outside(group_name, task, outside,
                                                             randomise_heads):
    """r(h(g.o), g.a) = r(h(o), a), through the declared observation and action maps."""
    sym = declaration(*TASK_3D) if task == "pointmass3d" else declaration(*TASKS_2D[task])
    nets = randomise_heads(build_networks(NetworkConfig(group=group_name, networks=SMALL), sym))
    torch.manual_seed(1)
    obs, act = torch.randn(64, sym.observation_size), torch.randn(64, sym.action_size)

    def reward(g):
        o = torch.as_tensor(sym.transform_observation(obs.numpy(), g))
        a = torch.as_tensor(sym.transform_action(act.numpy(), g))
        return nets.reward(torch.cat([nets.encoder(o), a], -1))

    base = reward(np.eye(sym.dim))
    inside = max(relative_error(reward(nets.group.element_matrix(e)), base)
                 for e in elements_of(nets.group))
    assert inside < 1e-4
    # The test can fail: outside the group the error is far above float noise
    # (but small for C16, whose networks are smooth and nearly SO(2)-invariant).
    assert relative_error(reward(outside), base) > 100 * max(inside, 1e-7)


def test_declared_fields_become_the_matching_escnn_representations():
    sym = declaration(*TASKS_2D["reacher"])
    group, exact = group_for_task("D8", sym)
    assert exact
    nets = build_networks(NetworkConfig(group="D8", networks=SMALL), sym)
    for e in group.elements():
        g = group.element_matrix(e)
        np.testing.assert_allclose(nets.encoder.in_layout.representation(e),
                                   sym.observation_matrix(g), atol=1e-6)
        np.testing.assert_allclose(nets.policy.out_layout.representation(e),
                                   sym.action_matrix(g), atol=1e-6)
    # rotation-only groups treat the reflection-odd ("sign") fields as invariant
    c8 = make_group("C8")
    assert all(np.allclose(c8.representation("sign")(e), 1) for e in c8.elements())


def test_exactness_and_bad_groups():
    pm2 = declaration("GeoMDP/PointMass2D-v0", {})
    assert group_for_task("D4", pm2)[1] and not group_for_task("D8", pm2)[1]
    assert group_for_task("icosahedral", declaration(*TASK_3D))[1]
    assert not group_for_task("icosahedral",
                              declaration("GeoMDP/PointMass3D-v0", {"walls": True}))[1]
    with pytest.raises(ValueError, match="acts in 3D but the task is 2D; valid groups for this "
                                         "task: C4, C8, C16, D4, D8, D16"):
        group_for_task("octahedral", pm2)
    with pytest.raises(ValueError, match="acts in 2D but the task is 3D; valid groups for this "
                                         "task: octahedral, icosahedral"):
        group_for_task("D8", declaration(*TASK_3D))
    with pytest.raises(ValueError, match="unknown group 'SO\\(5\\)'; valid groups for this 2D"):
        group_for_task("SO(5)", pm2)
    with pytest.raises(ValueError, match="equivariant latent"):
        build_networks(NetworkConfig(group="D4", equivariant={"transition": False}, networks=SMALL), pm2)
    with pytest.raises(ValueError, match="width_strategy='cube'; valid: sqrt, linear"):
        NetworkConfig(width_strategy="cube")


def test_plain_networks_have_the_same_interface_and_mix_with_equivariant_ones():
    sym = declaration("GeoMDP/PointMass2D-v0", {})
    plain = build_networks(NetworkConfig(group=None, networks=SMALL), sym)
    assert all(isinstance(m, torch.nn.Linear) for m in plain.encoder.modules()
               if isinstance(m, (torch.nn.Linear, EquivariantLinear)))
    assert plain.encoder(torch.randn(5, 4)).shape == (5, 16)
    mixed = build_networks(NetworkConfig(group="D8", equivariant={"q": False}, networks=SMALL), sym)
    z = mixed.encoder(torch.randn(5, 4))
    assert mixed.qs[0](torch.cat([z, torch.randn(5, 2)], -1)).shape == (5, 1)
    assert not any(isinstance(m, EquivariantLinear) for m in mixed.qs.modules())


def test_width_strategies_and_parameter_counts():
    sym = declaration("GeoMDP/PointMass2D-v0", {})
    sizes = Architecture(hidden_dim=128, latent_dim=32, hidden_layers=2)
    plain = build_networks(NetworkConfig(networks=sizes), sym).parameter_counts()
    sqrt = build_networks(NetworkConfig(group="D8", width_strategy="sqrt", networks=sizes), sym)
    linear = build_networks(NetworkConfig(group="D8", width_strategy="linear", networks=sizes), sym)
    assert sqrt.encoder.net[0].out_type.size == round(128 / 4) * 16  # 32 copies of a 16-dim field
    assert linear.encoder.net[0].out_type.size == 128  # 8 copies: the plain width
    ratio_sqrt = sqrt.parameter_counts()["dynamics"] / plain["dynamics"]
    ratio_linear = linear.parameter_counts()["dynamics"] / plain["dynamics"]
    assert 0.5 < ratio_sqrt < 1.5  # about as many free parameters as the plain network
    assert ratio_linear < 0.15  # about |G| = 16 times fewer


def test_inference_form_equals_training_form_and_is_never_stale():
    sym = declaration(*TASK_3D)
    nets = build_networks(NetworkConfig(group="octahedral", networks=SMALL), sym)
    net = nets.dynamics
    x = torch.randn(16, net.in_layout.size)
    trained = net(x)  # gradients on: escnn expands the weights in the graph
    with torch.no_grad():
        cached = net(x)
        np.testing.assert_allclose(cached.numpy(), trained.detach().numpy(), atol=1e-6)
    exported = torch.nn.Sequential(*[m.export() if isinstance(m, EquivariantLinear) else m
                                     for m in net.net])
    with torch.no_grad():
        np.testing.assert_allclose(exported(x).numpy(), cached.numpy(), atol=1e-5)
    # an optimiser step changes the parameters in place: the cache follows
    optimizer = torch.optim.Adam(net.parameters(), lr=1e-2)
    net(x).pow(2).sum().backward()
    optimizer.step()
    with torch.no_grad():
        after = net(x)
    np.testing.assert_allclose(after.numpy(), net(x).detach().numpy(), atol=1e-6)
    assert (after - cached).abs().max() > 1e-4
    # eval() does not change the state_dict keys
    keys = set(net.state_dict())
    net.eval()
    assert set(net.state_dict()) == keys


def test_field_layer_norm_is_layer_norm_on_plain_layouts():
    torch.manual_seed(0)
    ours, ref = FieldLayerNorm(10), torch.nn.LayerNorm(10)
    x = torch.randn(4, 10)
    torch.testing.assert_close(ours(x), ref(x))


@pytest.mark.parametrize("sizes", [[16] * 4, [1, 16, 1, 16]])
def test_field_layer_norm_ties_scale_and_shift_within_each_field(sizes):
    """Each field's scale and shift repeated over its channels (a broadcast when all
    fields have one size, a gather otherwise), with the gradients summed per field."""
    space = make_group("D8").gspace
    reps = {1: space.trivial_repr, 16: space.regular_repr}
    norm = FieldLayerNorm(space.type(*[reps[n] for n in sizes]))
    with torch.no_grad():
        norm.weight.normal_()
        norm.bias.normal_()
    weight, bias = norm.expand()
    index = torch.repeat_interleave(torch.arange(len(sizes)), torch.tensor(sizes))
    assert torch.equal(weight, norm.weight[index]) and torch.equal(bias, norm.bias[index])
    probe = torch.randn(sum(sizes))
    (weight * probe + bias * probe).sum().backward()
    summed = torch.zeros(len(sizes)).index_add_(0, index, probe)
    torch.testing.assert_close(norm.weight.grad, summed)
    torch.testing.assert_close(norm.bias.grad, summed)


@pytest.mark.parametrize("group_name, task", [("D8", "pointmass2d"), ("icosahedral", "pointmass3d")])
def test_policy_squash_keeps_vectors_in_the_unit_ball_and_is_equivariant(group_name, task):
    sym = declaration(*TASK_3D) if task == "pointmass3d" else declaration(*TASKS_2D[task])
    group = make_group(group_name)
    x = 3 * torch.randn(256, sym.action_size, dtype=torch.float64)
    a = squash(x, sym.action).numpy()
    assert sym.action_in_domain(a).all()
    for e in elements_of(group):
        g = group.element_matrix(e)
        moved = squash(torch.as_tensor(sym.transform_action(x.numpy(), g)), sym.action).numpy()
        np.testing.assert_allclose(moved, sym.transform_action(a, g), atol=1e-12)
    # projection onto the domain: identity inside, equivariant, and never outside
    p = project(x, sym.action).numpy()
    assert sym.action_in_domain(p).all()
    np.testing.assert_allclose(project(torch.as_tensor(a), sym.action).numpy(), a)
    g = group.element_matrix(elements_of(group)[-1])
    np.testing.assert_allclose(project(torch.as_tensor(sym.transform_action(x.numpy(), g)),
                                       sym.action).numpy(), sym.transform_action(p, g), atol=1e-12)


def test_networks_do_not_share_escnn_buffers():
    """escnn shares basis modules between layers; .double() on one network must not
    reach another built for the same group."""
    sym = declaration("GeoMDP/PointMass2D-v0", {})
    a = build_networks(NetworkConfig(group="D4", networks=SMALL), sym)
    b = build_networks(NetworkConfig(group="D4", networks=SMALL), sym)
    a.encoder.double()
    assert b.encoder(torch.randn(3, 4)).dtype == torch.float32
    assert a.encoder(torch.randn(3, 4, dtype=torch.float64)).dtype == torch.float64


def test_swapped_in_parameters_are_the_ones_used():
    """TensorDict.to_module (the policy loss's frozen Q) swaps parameters in; the
    layer must use them, with gradients to the input and none to the parameters."""
    from tensordict import TensorDict

    sym = declaration(*TASK_3D)
    config = NetworkConfig(group="octahedral", networks=SMALL)
    net, other = build_networks(config, sym).dynamics, build_networks(config, sym).dynamics
    x = torch.randn(8, net.in_layout.size, requires_grad=True)
    own, expected = net(x).detach(), other(x).detach()
    assert (own - expected).abs().max() > 1e-3
    with torch.no_grad():
        net(x)  # fill the inference cache with its own weights
    with TensorDict.from_module(other).detach().to_module(net):
        with torch.no_grad():
            np.testing.assert_allclose(net(x).numpy(), expected.numpy(), atol=1e-6)
        swapped = net(x)
        swapped.sum().backward()
    np.testing.assert_allclose(swapped.detach().numpy(), expected.numpy(), atol=1e-6)
    assert x.grad is not None and x.grad.abs().max() > 0
    assert all(p.grad is None for p in net.parameters())
    with torch.no_grad():  # restored: its own parameters again, through the cache too
        np.testing.assert_allclose(net(x).numpy(), own.numpy(), atol=1e-6)


GROUPS = [("C4", "pointmass2d"), ("C8", "pointmass2d"), ("C16", "pointmass2d"),
          ("D4", "pointmass2d"), ("D8", "pointmass2d"), ("D16", "pointmass2d"),
          ("D8", "reacher"), ("octahedral", "pointmass3d"), ("icosahedral", "pointmass3d")]


def relative_latent_change(encoder, directions, small, large):
    with torch.no_grad():
        z_small, z_large = encoder(small * directions), encoder(large * directions)
    return ((z_large - z_small).norm(dim=-1) / z_small.norm(dim=-1)).mean().item()


@pytest.mark.parametrize("group_name, task", GROUPS)
@pytest.mark.parametrize("strategy", ["sqrt", "linear"])
def test_encoder_keeps_the_magnitude_of_vector_observations(group_name, task, strategy):
    """An equivariant map from vector fields has zero mean over its output channels;
    the LayerNorm after it must not divide out |obs|. Scaling an observation must
    move the latent state at least as much as it moves the plain encoder's."""
    sym = declaration(*TASK_3D) if task == "pointmass3d" else declaration(*TASKS_2D[task])
    sizes = Architecture(hidden_dim=128, latent_dim=32, hidden_layers=2)
    directions = torch.randn(64, sym.observation_size, generator=torch.Generator().manual_seed(0))
    directions = directions / directions.norm(dim=-1, keepdim=True)
    for small, large in ((1e-3, 1e-2), (0.05, 0.1), (0.2, 0.4)):
        changes = {}
        for name in (None, group_name):
            torch.manual_seed(0)
            config = NetworkConfig(group=name, width_strategy=strategy, networks=sizes)
            encoder = build_networks(config, sym).encoder
            changes[name] = relative_latent_change(encoder, directions, small, large)
        assert changes[group_name] >= 0.5 * changes[None], (small, large, changes)


@pytest.mark.parametrize("group_name, task", GROUPS)
def test_gradients_are_finite_with_states_exactly_on_target(group_name, task):
    """Exactly-zero observations (on the target, at rest) in a batch: every gradient
    of TD-MPC's loss stays finite."""
    from tensordict import TensorDict

    from agents.tdmpc.loss import LossConfig, TDMPCLoss
    from agents.tdmpc.world_model import WorldModel

    sym = declaration(*TASK_3D) if task == "pointmass3d" else declaration(*TASKS_2D[task])
    nets = build_networks(NetworkConfig(group=group_name, networks=SMALL), sym)
    loss = TDMPCLoss(WorldModel(nets, sym.action), LossConfig())
    n, horizon = 8, 3
    obs = torch.randn(n, horizon, sym.observation_size) * 0.1
    obs[:4] = 0.0
    action = torch.zeros(n, horizon, sym.action_size)
    action[4:] = 0.1
    batch = TensorDict({"observation": obs, "action": action,
                        "next": {"observation": obs.clone(), "reward": torch.ones(n, horizon, 1),
                                 "terminated": torch.zeros(n, horizon, 1, dtype=torch.bool)}},
                       batch_size=[n, horizon])
    losses = loss(batch)
    (losses["loss_model"] + losses["loss_pi"]).backward()
    grads = [p.grad for p in loss.model.parameters() if p.grad is not None]
    assert grads and all(torch.isfinite(g).all() for g in grads)


@pytest.mark.parametrize("group_name, task", [("D8", "pointmass2d"), ("octahedral", "pointmass3d")])
def test_irrep_basis_layers_give_the_same_networks_as_dense_ones(group_name, task, randomise_heads):
    """layers=fourier (auto for sqrt width) and layers=dense: the same parameter counts,
    and both exactly equivariant."""
    from agents.nn.fourier import FourierLinear

    sym = declaration(*TASK_3D) if task == "pointmass3d" else declaration(*TASKS_2D[task])
    counts = {}
    for kind in ("dense", "fourier"):
        config = NetworkConfig(group=group_name, width_strategy="sqrt", networks=replace(SMALL, layers=kind))
        nets = randomise_heads(build_networks(config, sym))
        counts[kind] = nets.parameter_counts()
        uses_fourier = any(isinstance(m, FourierLinear) for m in nets.dynamics.modules())
        assert uses_fourier == (kind == "fourier")
        net = nets.dynamics
        x = torch.randn(16, net.in_layout.size)
        for e in elements_of(nets.group, max_elements=6):
            err = relative_error(net(x @ rep(net.in_layout, e).T), net(x) @ rep(net.out_layout, e).T)
            assert err < 1e-4, (kind, e, err)
    assert counts["dense"] == counts["fourier"]
    assert NetworkConfig(width_strategy="sqrt").linear_kind() == "fourier"
    assert NetworkConfig(width_strategy="linear").linear_kind() == "dense"


@pytest.mark.parametrize("group", [None, "D8", "icosahedral", "SO3"])
def test_submodules_walks_like_modules(group):
    """``submodules`` (the agent's walk, without hashing escnn's modules) visits exactly
    ``Module.modules()``, in its order, shared modules once."""
    sym = declaration(*TASK_3D) if group in ("icosahedral", "SO3") else declaration(
        *TASKS_2D["pointmass2d"])
    nets = build_networks(NetworkConfig(group=group, width_strategy="linear", networks=SMALL), sym)
    shared = torch.nn.ModuleList([nets.encoder, nets.qs, nets.encoder])
    for module in [*nets.modules().values(), shared]:
        assert [id(m) for m in submodules(module)] == [id(m) for m in module.modules()]


# TD-MPC's own network choices (issue 37's step 4), each an option of agent.networks.
TDMPC_LIKE = replace(SMALL, encoder_layers=1, encoder_dim=12, layer_norm="q_input")


def layer_kinds(net):
    """The hidden blocks' module names, in order: Linear/EquivariantLinear -> 'linear'."""
    names = []
    for m in net.net:
        name = type(m).__name__
        names.append("linear" if name in ("Linear", "EquivariantLinear", "SplitLinear",
                                          "FourierLinear") else name)
    return names


@pytest.mark.parametrize("group_name, task", [(None, "reacher"), ("D8", "reacher"),
                                              ("icosahedral", "pointmass3d"), ("SO3", "pointmass3d")])
def test_tdmpc_layer_norm_placement_and_encoder_depth(group_name, task):
    """layer_norm=q_input: LayerNorm and tanh after the Q's first layer only, activation alone
    elsewhere; encoder_layers/encoder_dim shape the encoder alone."""
    nets = build_networks(NetworkConfig(group=group_name, width_strategy="linear",
                                        networks=TDMPC_LIKE, allow_approximate=True),
                          task_symmetry(task))
    norm = "FieldLayerNorm" if group_name != "SO3" else "SpectralLayerNorm"
    act = "ELU" if group_name != "SO3" else "GridActivation"
    tanh = "Tanh" if group_name != "SO3" else "GridActivation"
    assert layer_kinds(nets.encoder) == ["linear", act, "linear"]
    for head in (nets.dynamics, nets.reward, nets.policy):
        assert layer_kinds(head) == ["linear", act, "linear", act, "linear"]
    for q in nets.qs:
        assert layer_kinds(q) == ["linear", norm, tanh, "linear", act, "linear"]
        if group_name == "SO3":
            assert isinstance(q.net[2].function, torch.nn.Tanh)
    widths = [layout_size(head.net[0].out_features if group_name is None else head.net[0].out_type)
              for head in (nets.encoder, nets.dynamics)]
    field = 1 if group_name is None else nets.group.field_size
    assert widths == [field * (12 if group_name is None else regular_copies(12, nets.group, "linear")),
                      field * (24 if group_name is None else regular_copies(24, nets.group, "linear"))]


@pytest.mark.parametrize("group_name, task", [("D8", "reacher"), ("C8", "pointmass2d"),
                                              ("icosahedral", "pointmass3d")])
def test_tdmpc_layout_networks_are_equivariant(group_name, task, randomise_heads):
    assert_every_head_equivariant(randomise_heads(build_networks(
        NetworkConfig(group=group_name, width_strategy="linear", networks=TDMPC_LIKE),
        task_symmetry(task))))


def test_orthogonal_init_is_tdmpcs_and_plain_only():
    sym = task_symmetry("reacher")
    torch.manual_seed(0)
    nets = build_networks(NetworkConfig(networks=replace(SMALL, init="orthogonal")), sym)
    for name, head in heads(nets):
        linears = [m for m in head.net if isinstance(m, torch.nn.Linear)]
        zeroed = name.startswith(("reward", "qs"))
        for i, layer in enumerate(linears):
            w = layer.weight.detach()
            if zeroed and i == len(linears) - 1:  # TD-MPC's zero output layers still
                assert not w.any() and not layer.bias.any()
                continue
            gram = w @ w.T if w.shape[0] <= w.shape[1] else w.T @ w
            torch.testing.assert_close(gram, torch.eye(len(gram)), atol=1e-5, rtol=0)
            assert not layer.bias.any(), f"{name}: biases start at zero"
    with pytest.raises(OptionError, match="agent.networks.init=orthogonal applies to plain layers"):
        NetworkConfig(group="D8", networks=replace(SMALL, init="orthogonal"))
    # a plain component beside an equivariant one is still refused: one rule per agent
    with pytest.raises(OptionError, match="use agent.networks.init=default"):
        NetworkConfig(group="D8", equivariant={"q": False},
                      networks=replace(SMALL, init="orthogonal"))
    NetworkConfig(group="D8", equivariant=dict.fromkeys(("transition", "q", "policy"), False),
                  networks=replace(SMALL, init="orthogonal"))


@pytest.mark.parametrize("group_name, keys_sha, parameter_sum", [
    (None, "42d865d128bfa88b", 1044.9268056568806), ("D8", "4554329bfb9c7dc4", 334.97846363435383)])
def test_the_default_architecture_is_the_one_the_committed_runs_used(group_name, keys_sha,
                                                                    parameter_sum):
    """With the TD-MPC options at their defaults the networks are those of commit e6a9522,
    which made or matches every committed run: the same state-dict entries (sorted: escnn
    orders some buffers by string hashes, which change from process to process) and the same
    initial weights (their absolute sum, seeded; the values were taken from e6a9522)."""
    import hashlib

    torch.manual_seed(3)
    nets = build_networks(NetworkConfig(group=group_name, width_strategy="linear", networks=SMALL),
                          task_symmetry("reacher"))
    keys = sorted(k for m in nets.modules().values() for k in m.state_dict())
    assert hashlib.sha256("\n".join(keys).encode()).hexdigest()[:16] == keys_sha
    total = sum(float(p.detach().double().abs().sum()) for m in nets.modules().values()
                for p in m.parameters())
    assert total == pytest.approx(parameter_sum, rel=1e-9)
    assert layer_kinds(nets.encoder) == ["linear", "FieldLayerNorm", "ELU"] * 2 + ["linear"]
