import gymnasium
import numpy as np
import pytest
import torch

from geomdp_envs import SimState, augment_transitions, default_augmentation_group, groups


def test_default_groups_keep_box_actions_in_the_box():
    def sym(env_id, **kw):
        return gymnasium.make(env_id, **kw).unwrapped.symmetry

    assert default_augmentation_group(sym("GeoMDP/PointMass2D-v0")) == "D4"
    assert default_augmentation_group(sym("GeoMDP/PointMass3D-v0")) == "full_octahedral"
    assert default_augmentation_group(sym("GeoMDP/Reacher-v0")) == "O(2)"  # torques are scalars


def test_augmented_transitions_are_transitions_of_the_task():
    """(g.s, g.a, r, g.s') is what the simulator produces from g.s and g.a."""
    env = gymnasium.make("GeoMDP/PointMass3D-v0", n_balls=2)
    base = env.unwrapped
    rng = np.random.default_rng(0)
    obs, actions, next_obs, rewards = [], [], [], []
    for _ in range(16):
        state = base.sample_state(rng)
        base.set_state(state)
        obs.append(base.observe())
        actions.append(rng.uniform(-1, 1, 6))
        o, r = base.simulate(actions[-1])
        next_obs.append(o)
        rewards.append(r)
    aug = augment_transitions(base.symmetry, np.stack(obs), np.stack(actions),
                              np.stack(next_obs), rng)
    assert np.abs(aug[1]).max() <= 1 + 1e-12  # box actions stay in the box
    for o, a, o_next, r in zip(*aug, rewards):
        base.set_state(SimState(o[:6], o[6:]))  # for point masses the state is the observation
        o_sim, r_sim = base.simulate(a)
        np.testing.assert_allclose(o_sim, o_next, atol=1e-12)
        assert r_sim == pytest.approx(r, abs=1e-12)


def test_torch_batches_and_refusals():
    sym = gymnasium.make("GeoMDP/PointMass2D-v0").unwrapped.symmetry
    rng = np.random.default_rng(0)
    obs = torch.randn(8, 4)
    action = torch.rand(8, 2) * 2 - 1
    out = augment_transitions(sym, obs, action, obs.clone(), rng)
    assert all(isinstance(x, torch.Tensor) and x.shape == y.shape
               for x, y in zip(out, (obs, action, obs)))
    # norms are preserved: each row was moved by an orthogonal matrix
    torch.testing.assert_close(out[0].norm(dim=1), obs.norm(dim=1))
    with pytest.raises(ValueError, match="D8 is not a symmetry of this task.*try D4"):
        augment_transitions(sym, obs, action, obs, rng, group="D8")
    sym3 = gymnasium.make("GeoMDP/PointMass3D-v0").unwrapped.symmetry
    box_actions = np.ones((4, 3))
    with pytest.raises(ValueError, match="may move box actions out of"):
        augment_transitions(sym3, np.zeros((4, 6)), box_actions, np.zeros((4, 6)), rng,
                            group="icosahedral")
    ball_actions = box_actions / np.sqrt(3)
    out = augment_transitions(sym3, np.zeros((4, 6)), ball_actions, np.zeros((4, 6)), rng,
                              group="icosahedral")
    np.testing.assert_allclose(np.linalg.norm(out[1], axis=1), 1.0)
    assert groups.is_subgroup("icosahedral", sym3.exact_group)
