import json
import pickle

import gymnasium
import numpy as np
import pytest
import torch
from conftest import TASK_CONFIGS

from geomdp_envs import Symmetry, groups
from geomdp_envs.symmetry import layout


@pytest.mark.parametrize("config", TASK_CONFIGS)
def test_declaration_is_plain_data_and_a_representation(config):
    env_id, kwargs = config
    sym = gymnasium.make(env_id, **kwargs).unwrapped.symmetry
    # Plain data: JSON and pickle round trips give the same declaration.
    assert Symmetry.from_dict(json.loads(json.dumps(sym.to_dict()))) == sym
    assert pickle.loads(pickle.dumps(sym)) == sym
    # rho(g h) = rho(g) rho(h), and rho(g) is orthogonal, for observations and actions.
    g, h = groups.sample(sym.continuous_group, np.random.default_rng(1), 2)
    for rho in (sym.observation_matrix, sym.action_matrix):
        np.testing.assert_allclose(rho(g @ h), rho(g) @ rho(h), atol=1e-12)
        np.testing.assert_allclose(rho(g) @ rho(g).T, np.eye(len(rho(g))), atol=1e-12)


def test_transform_works_on_batches_of_numpy_and_torch():
    sym = gymnasium.make("GeoMDP/PointMass3D-v0", n_balls=2).unwrapped.symmetry
    g = groups.sample("SO(3)", np.random.default_rng(0), 1)[0]
    obs = np.random.default_rng(1).normal(size=(5, sym.observation_size)).astype(np.float32)
    out = sym.transform_observation(obs, g)
    assert out.dtype == np.float32 and out.shape == obs.shape
    np.testing.assert_allclose(out[:, :3], obs[:, :3] @ g.T, atol=1e-6)
    out_t = sym.transform_observation(torch.from_numpy(obs), g)
    np.testing.assert_allclose(out_t.numpy(), out, atol=1e-6)
    with pytest.raises(ValueError, match="last dimension 4, expected 12"):
        sym.transform_observation(np.zeros(4), g)


def test_sampled_actions_fill_the_unit_ball_per_vector_field():
    sym = gymnasium.make("GeoMDP/PointMass3D-v0", n_balls=2).unwrapped.symmetry
    actions = sym.sample_action(np.random.default_rng(0), 4000)
    norms = np.linalg.norm(actions.reshape(-1, 2, 3), axis=-1)
    assert norms.max() <= 1 and norms.max() > 0.99
    assert abs(np.mean(norms**3) - 0.5) < 0.03  # uniform in the ball: |a|^3 ~ U(0, 1)
    assert sym.action_in_domain(actions).all()
    assert not sym.action_in_domain(np.ones(6))


def test_particle_permutations_move_whole_balls():
    sym = gymnasium.make("GeoMDP/PointMass3D-v0", n_balls=3).unwrapped.symmetry
    obs = np.arange(18.0)
    moved = sym.observation_permutation_matrix(np.array([2, 0, 1])) @ obs
    # ball 0's position goes to ball 2's slot, and its velocity likewise
    np.testing.assert_array_equal(moved[6:9], obs[0:3])
    np.testing.assert_array_equal(moved[15:18], obs[9:12])
    with pytest.raises(ValueError, match="not a permutation of 3 particles"):
        sym.action_permutation_matrix(np.array([0, 0, 1]))


def test_malformed_declarations_are_refused():
    with pytest.raises(ValueError, match="does not continue the layout"):
        from geomdp_envs.symmetry import Field
        Symmetry(2, "O(2)", "O(2)", (Field("p", "vector", 0, 3),), layout(2, [("f", "vector")]))
    with pytest.raises(ValueError, match="unknown representation 'spinor'"):
        layout(2, [("p", "spinor")])
    with pytest.raises(ValueError, match="D4 is not a subgroup of SO\\(2\\)"):
        Symmetry(2, "SO(2)", "D4", layout(2, [("p", "vector")]), layout(2, [("f", "vector")]))
    with pytest.raises(ValueError, match="does not act on R\\^3"):
        Symmetry(3, "O(2)", "O(2)", layout(3, [("p", "vector")]), layout(3, [("f", "vector")]))
