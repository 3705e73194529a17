"""Reduction numbers and the LQR view, computed from the declarations and checked."""

import gymnasium
import numpy as np
import pytest
from conftest import TASK_CONFIGS

from geomdp_envs import groups, lqr
from geomdp_envs.theory import character_hom_dimension, dimension_table, hom_dimension


def declaration(env_id, **kwargs):
    return gymnasium.make(env_id, **kwargs).unwrapped.symmetry


@pytest.mark.parametrize("config", TASK_CONFIGS)
def test_null_space_dimension_equals_character_inner_product(config):
    env_id, kwargs = config
    sym = declaration(env_id, **kwargs)
    finite = ["C4", "C8", "D4", "D8", "D16"] if sym.dim == 2 else ["octahedral", "icosahedral"]
    for group in finite:
        for fields_in, fields_out in [(sym.observation, sym.observation),
                                      (sym.action, sym.observation),
                                      (sym.observation, sym.action)]:
            assert hom_dimension(group, fields_in, fields_out) == \
                character_hom_dimension(group, fields_in, fields_out)


def test_known_dimensions():
    pm2 = declaration("GeoMDP/PointMass2D-v0")
    # rho_S = 2 vectors, rho_A = 1 vector. A rotation-equivariant map between planar
    # vectors is a*I + b*J (2 parameters); with reflections only a*I (1 parameter).
    so2, o2 = dimension_table(pm2, "SO(2)"), dimension_table(pm2, "O(2)")
    assert (so2["A"], so2["B"], so2["K"], so2["P"]) == (8, 4, 4, 4)
    assert (o2["A"], o2["B"], o2["K"], o2["P"]) == (4, 2, 2, 3)
    assert (o2["A plain"], o2["B plain"], o2["P plain"]) == (16, 8, 10)
    assert (so2["dim S×A"], so2["orbit"], so2["dim (S×A)/G"]) == (6, 1, 5)
    assert dimension_table(pm2, "D8")["orbit"] == 0
    # In 3D, the standard representation is absolutely irreducible for SO(3) and
    # its finite subgroups used here: Hom(R^3, R^3) = scalars.
    pm3 = declaration("GeoMDP/PointMass3D-v0", n_balls=3)
    for group in ("SO(3)", "octahedral", "icosahedral"):
        t = dimension_table(pm3, group)
        assert (t["A"], t["B"], t["P"]) == (36, 18, 21)
    t = dimension_table(pm3, "SO(3)")
    assert (t["dim S×A"], t["orbit"], t["dim (S×A)/G"]) == (27, 3, 24)
    # Reacher's sign fields are invariant under rotations only.
    reacher = declaration("GeoMDP/Reacher-v0")
    assert hom_dimension("SO(2)", reacher.action, reacher.action) == 4
    assert hom_dimension("O(2)", reacher.action, reacher.action) == 4
    assert hom_dimension("O(2)", reacher.action, reacher.observation[1:2]) == 0  # torque -> cos


@pytest.mark.parametrize("config", TASK_CONFIGS)
def test_linearisation_is_steerable(config):
    env_id, kwargs = config
    env = gymnasium.make(env_id, **kwargs)
    env.reset(seed=0)
    report = lqr.check_linearization(env, n_trials=6)
    assert report.max_error < 1e-7, report


@pytest.mark.parametrize("env_id, perturb", [
    ("GeoMDP/PointMass2D-v0", lambda m: m.dof_damping.__setitem__(0, 2.0)),
    ("GeoMDP/PointMass3D-v0", lambda m: m.dof_damping.__setitem__(2, 1.5)),
    ("GeoMDP/Reacher-v0", lambda m: m.opt.gravity.__setitem__(slice(None), [0, -9.81, 0])),
])
def test_an_asymmetric_model_fails_the_check(env_id, perturb):
    env = gymnasium.make(env_id)
    env.reset(seed=0)
    perturb(env.unwrapped.model)
    assert lqr.check_linearization(env, n_trials=6).max_error > 1e-3


@pytest.mark.parametrize("env_id, kwargs", [("GeoMDP/PointMass2D-v0", {}),
                                            ("GeoMDP/PointMass3D-v0", {"n_balls": 2})])
def test_lqr_gain_and_value_are_equivariant_maps(env_id, kwargs):
    env = gymnasium.make(env_id, **kwargs)
    env.reset(seed=0)
    sym = env.unwrapped.symmetry
    policy = lqr.LQRPolicy(env)
    for g in groups.sample(sym.continuous_group, np.random.default_rng(0), 8):
        if not groups.contains(sym.exact_group, g):
            continue
        rs, ra = sym.observation_matrix(g), sym.action_matrix(g)
        np.testing.assert_allclose(ra @ policy.k @ rs.T, policy.k, atol=1e-8)
        np.testing.assert_allclose(rs @ policy.p @ rs.T, policy.p, atol=1e-6 * np.abs(policy.p).max())
    # and the same for a model whose x axis is damped more: K is then not steerable
    env.unwrapped.model.dof_damping[0] = 3.0
    skewed = lqr.LQRPolicy(env)
    g = groups.group_elements("D4")[1] if sym.dim == 2 else groups.group_elements("octahedral")[5]
    rs, ra = sym.observation_matrix(g), sym.action_matrix(g)
    assert np.abs(ra @ skewed.k @ rs.T - skewed.k).max() > 1e-2


def test_lqr_oracle_solves_pointmass2d():
    env = gymnasium.make("GeoMDP/PointMass2D-v0")
    mean, _ = lqr.evaluate_policy(env, lqr.LQRPolicy(env), range(3))
    assert mean > 800


@pytest.mark.slow  # computes every table of the report
def test_theory_report_command_runs(capsys):
    from agents.cli import theory as theory_report

    theory_report.main(["--quick", "--hidden", "32", "--latent", "8"])
    out = capsys.readouterr().out
    assert "| PointMass2D | O(2) | 6 | 1 | 5 | 4 / 16 | 2 / 8 | 2 / 8 | 3 / 10 |" in out
    assert out.count("LQR oracle return") == 1
