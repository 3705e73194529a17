"""Continuous groups SO(2), O(2), SO(3), O(3): quadratures, exact LayerNorm, and
equivariance of the networks and the planner under random elements of the whole
group, with errors that shrink as the nonlinearity's grid gets finer."""

import gymnasium
import numpy as np
import pytest
import torch

from agents import Architecture, NetworkConfig, build_networks, group_for_task, make_group
from agents.nn.spectral import GridActivation, SpectralLayerNorm, sampling_matrix
from geomdp_envs import groups
from tests.test_planner import RecordingNoise, TransformedNoise, plan_twice

SMALL = dict(hidden_dim=24, latent_dim=16, hidden_layers=2)
TASKS = {"SO2": ("GeoMDP/PointMass2D-v0", {}), "O2": ("GeoMDP/Reacher-v0", {}),
         "SO3": ("GeoMDP/PointMass3D-v0", {"n_balls": 2}), "O3": ("GeoMDP/PointMass3D-v0", {})}


def declaration(group_name):
    env_id, kwargs = TASKS[group_name]
    return gymnasium.make(env_id, **kwargs).unwrapped.symmetry


def random_elements(group, n=6, seed=1):
    """Haar-random elements of the whole group (not the fixed sample of ``elements()``)."""
    matrices = groups.sample(group.declared_name, np.random.default_rng(seed), n)
    return [group.element(m) for m in matrices]


def rep(layout, element):
    return torch.as_tensor(np.asarray(layout.representation(element)), dtype=torch.float64)


def equivariance_error(net, elements, seed=0):
    """Largest relative error |net(g x) - g net(x)| / |g net(x)| over ``elements``."""
    x = torch.randn(32, net.in_layout.size, dtype=torch.float64,
                    generator=torch.Generator().manual_seed(seed))
    y = net(x)
    return max(((net(x @ rep(net.in_layout, e).T) - y @ rep(net.out_layout, e).T).norm()
                / y.norm()).item() for e in elements)


def networks(group_name, randomise_heads, **options):
    nets = build_networks(NetworkConfig(group=group_name, allow_approximate=True,
                                        networks=Architecture(**SMALL, **options)), declaration(group_name))
    randomise_heads(nets)
    for module in nets.modules().values():
        module.double()
    return nets


@pytest.mark.parametrize("group_name, frequency", [
    ("SO2", 4), ("O2", 4), ("SO3", 5), ("SO3", 7), ("O3", 5), ("O3", 6)])
def test_quadrature_integrates_every_irrep_up_to_its_frequency(group_name, frequency):
    """(SO(3) up to 5: the icosahedral group; above: Euler angles with Gauss-Legendre.)"""
    group = make_group(group_name, max_frequency=1, grid_frequency=frequency)
    grid = group.quadrature
    assert np.isclose(grid.weights.sum(), 1)
    for irrep_id in group.escnn.bl_irreps(frequency):
        irrep = group.escnn.irrep(*irrep_id)
        mean = sum(w * irrep(g) for g, w in zip(grid.elements, grid.weights))
        expected = np.ones((1, 1)) if irrep.is_trivial() else np.zeros(mean.shape)
        np.testing.assert_allclose(mean, expected, atol=1e-10, err_msg=str(irrep_id))


@pytest.mark.parametrize("group_name", ["SO2", "O3"])
def test_spectral_layer_norm_is_layer_norm_of_the_sampled_functions(group_name):
    group = make_group(group_name)
    layout = group.gspace.type(*[group.regular] * 3)
    norm = SpectralLayerNorm(layout, group.quadrature).double()
    with torch.no_grad():
        norm.weight.copy_(torch.tensor([0.5, 1.5, -2.0]))
        norm.bias.copy_(torch.tensor([0.3, -0.1, 0.7]))
    x = torch.randn(5, layout.size, dtype=torch.float64)
    samples = torch.as_tensor(sampling_matrix(group.regular, group.quadrature))  # [N, D]
    w = torch.as_tensor(group.quadrature.weights)

    def functions(v):  # [5, fields, N]
        return v.view(5, 3, -1) @ samples.T

    f = functions(x)
    mean = (f * w).sum(-1).mean(-1)[:, None, None]
    var = (((f - mean) ** 2) * w).sum(-1).mean(-1)[:, None, None]
    expected = (f - mean) / torch.sqrt(var + norm.eps) * norm.weight[:, None] + norm.bias[:, None]
    torch.testing.assert_close(functions(norm(x)), expected)
    # exact: no sampling is involved
    for e in random_elements(group):
        g = rep(layout, e)
        torch.testing.assert_close(norm(x @ g.T), norm(x) @ g.T)


@pytest.mark.parametrize("group_name, grids", [
    ("SO2", (7, None, 63)), ("O2", (7, None, 63)), ("SO3", (None, 7, 11)), ("O3", (None, 7, 11))])
def test_every_network_is_equivariant_under_random_elements_of_the_whole_group(
        group_name, grids, randomise_heads):
    """Bounded error at the default grid (None), and finer grids shrink it (the error
    is the nonlinearity's aliasing, reported here against the grid's exactness)."""
    nets = [networks(group_name, randomise_heads, grid_frequency=g) for g in grids]
    labels = [f"grid {n.group.grid_frequency}" + (" (default)" if g is None else "")
              for g, n in zip(grids, nets)]
    elements = random_elements(nets[0].group)
    for name in ("encoder", "dynamics", "reward", "policy", "qs"):
        errors = [equivariance_error(n.qs[0] if name == "qs" else n.modules()[name], elements)
                  for n in nets]
        print(f"{group_name} {name}: relative error "
              + ", ".join(f"{e:.1e} ({label})" for e, label in zip(errors, labels)))
        assert errors[grids.index(None)] < 3e-2, (name, errors)
        assert errors[0] > errors[1] > errors[2], (name, errors)


def test_rotations_that_map_the_grid_to_itself_are_exact(randomise_heads):
    nets = networks("SO2", randomise_heads)
    n = len(nets.group.quadrature)  # 16 angles
    on_grid = [nets.group.element(groups.rotation_2d(2 * np.pi * k / n)) for k in (1, 5, 11)]
    off_grid = [nets.group.element(groups.rotation_2d(2 * np.pi * (k + 0.5) / n)) for k in (1, 5)]
    # (the grid's matrices are float32 buffers: the exactness is float32's)
    assert equivariance_error(nets.dynamics, on_grid) < 1e-6
    assert equivariance_error(nets.dynamics, off_grid) > 1e-4


def test_hidden_layers_use_band_limited_fields_and_comparable_widths():
    sym = declaration("SO2")
    cfg = dict(allow_approximate=True, networks=Architecture(hidden_dim=128, latent_dim=32, hidden_layers=2))
    plain = build_networks(NetworkConfig(**cfg), sym).parameter_counts()["dynamics"]
    sqrt = build_networks(NetworkConfig(group="SO2", width_strategy="sqrt", **cfg), sym)
    linear = build_networks(NetworkConfig(group="SO2", width_strategy="linear", **cfg), sym)
    assert sqrt.group.field_size == 7  # frequencies 0..3: 1 + 2 * 3 coefficients
    assert linear.encoder.net[0].out_type.size == round(128 / 7) * 7  # the plain width
    assert 0.5 < sqrt.parameter_counts()["dynamics"] / plain < 1.5
    assert any(isinstance(m, GridActivation) for m in sqrt.dynamics.modules())


def planner_error(group_name, element, grid_frequency, randomise_heads):
    """max |plan(g s) - g plan(s)| over two consecutive plans, given g-transformed noise."""
    from agents.tdmpc.agent import TDMPCAgent, TDMPCConfig

    env_id, kwargs = TASKS[group_name]
    env = gymnasium.make(env_id, **kwargs)
    sym = env.unwrapped.symmetry
    cfg = TDMPCConfig.from_dict({
        "group": group_name, "allow_approximate": True,
        "networks": {"hidden_dim": 32, "latent_dim": 16, "grid_frequency": grid_frequency},
        "planner": {"num_samples": 64, "num_elites": 8, "num_pi_trajs": 8, "iterations": 3},
        "horizon": 3, "batch_size": 8})
    torch.manual_seed(0)
    agent = TDMPCAgent(cfg, sym, sym.observation_size, sym.action_size)
    randomise_heads(agent.networks)
    agent.model.double()
    obs = [torch.as_tensor(env.reset(seed=s)[0], dtype=torch.float64) for s in (0, 1)]
    recording = RecordingNoise(seed=0)
    actions = plan_twice(agent, obs, recording)
    moved = [torch.as_tensor(sym.transform_observation(o.numpy(), element)) for o in obs]
    moved_actions = plan_twice(agent, moved, TransformedNoise(recording, sym.action_matrix(element)))
    return max(np.abs(b.numpy() - sym.transform_action(a.numpy(), element)).max()
               for a, b in zip(actions, moved_actions))


@pytest.mark.parametrize("group_name, element, coarse_grid, fine_grid", [
    ("SO2", groups.rotation_2d(0.7), 7, 63),
    ("O3", -groups.rotation_3d([1.0, 2.0, 3.0], 0.7), 5, 15),
])
def test_planner_is_equivariant_under_random_elements(group_name, element, coarse_grid,
                                                      fine_grid, randomise_heads):
    """The planner's own steps (noise per field, projection, elites, refit, warm start)
    commute with any element, so the plan's error is the networks': large on a coarse
    grid (where it can reorder the elites), small on a fine one."""
    coarse = planner_error(group_name, element, coarse_grid, randomise_heads)
    fine = planner_error(group_name, element, fine_grid, randomise_heads)
    print(f"{group_name}: planner error {coarse:.1e} (grid {coarse_grid}), "
          f"{fine:.1e} (grid {fine_grid})")
    assert fine < 1e-4 < coarse


def test_continuous_group_names_and_options_are_checked():
    pm2, reacher, pm3 = declaration("SO2"), declaration("O2"), declaration("O3")
    assert group_for_task("O2", reacher)[1] and group_for_task("SO3", pm3)[1]
    assert not group_for_task("O2", pm2)[1]  # the walls keep only D4
    with pytest.raises(ValueError, match="only an approximate symmetry of this task \\(exact "
                                         "group: D4\\); set agent.allow_approximate=true"):
        build_networks(NetworkConfig(group="O2", networks=Architecture(**SMALL)), pm2)
    with pytest.raises(ValueError, match="acts in 3D but the task is 2D; valid groups for this "
                                         "task: C4, C8, C16, D4, D8, D16, SO2, O2"):
        group_for_task("SO3", pm2)
    with pytest.raises(ValueError, match="apply to the continuous groups"):
        make_group("D8", max_frequency=2)
    with pytest.raises(ValueError, match="grid_frequency must be >= 2 \\* max_frequency = 6"):
        make_group("SO2", max_frequency=3, grid_frequency=5)
    with pytest.raises(ValueError, match="max_frequency must be >= 1"):
        make_group("SO3", max_frequency=0)
    with pytest.raises(ValueError, match="is a continuous group: it has no order"):
        make_group("SO2").order  # noqa: B018


def test_tdmpc_layout_is_exact_on_grid_rotations_and_bounded_elsewhere(randomise_heads):
    """agent.networks.layer_norm=q_input with a continuous group: the Q's tanh (and every
    ELU, without LayerNorm) is sampled on the grid as any nonlinearity, so rotations that map
    the grid to itself stay exact and the others keep the default layout's bound."""
    nets = networks("SO2", randomise_heads, layer_norm="q_input", encoder_layers=1)
    assert [type(m).__name__ for m in nets.qs[0].net][1:3] == ["SpectralLayerNorm", "GridActivation"]
    n = len(nets.group.quadrature)
    on_grid = [nets.group.element(groups.rotation_2d(2 * np.pi * k / n)) for k in (1, 5, 11)]
    for name, net in (("encoder", nets.encoder), ("dynamics", nets.dynamics), ("q", nets.qs[0]),
                      ("policy", nets.policy)):
        assert equivariance_error(net, on_grid) < 1e-6, name
        assert equivariance_error(net, random_elements(nets.group)) < 3e-2, name
