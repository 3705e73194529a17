"""The GeoMDP tasks reproduce dm_control bit for bit from the same state and actions."""

import gymnasium
import numpy as np
import pytest
from dm_control import suite


def _drive_both(env_id, env_kwargs, domain, task, set_task_state):
    env = gymnasium.make(env_id, **env_kwargs)
    env.reset(seed=3)
    base = env.unwrapped
    dm = suite.load(domain, task, task_kwargs={"random": 0})
    dm.reset()
    with dm.physics.reset_context():
        dm.physics.data.qpos[:] = base.data.qpos
        set_task_state(dm.physics, base)
    rng = np.random.default_rng(0)
    steps = 0
    while True:
        action = rng.uniform(-1, 1, size=base.action_space.shape)
        ts = dm.step(action)
        _, reward, terminated, truncated, _ = env.step(action)
        steps += 1
        yield dm.physics, base, ts, reward
        assert not terminated
        assert truncated == ts.last()
        if ts.last():
            break
    assert steps == 1000


def test_pointmass2d_matches_dm_control_point_mass_easy():
    rewards = []
    for _, base, ts, reward in _drive_both(
            "GeoMDP/PointMass2D-v0", {}, "point_mass", "easy", lambda p, b: None):
        np.testing.assert_array_equal(base.observe(),
                                      np.concatenate([ts.observation["position"],
                                                      ts.observation["velocity"]]))
        assert reward == ts.reward
        rewards.append(reward)
    assert np.mean(rewards) > 0  # the comparison saw non-zero rewards too


@pytest.mark.parametrize("difficulty", ["easy", "hard"])
def test_reacher_matches_dm_control_reacher(difficulty):
    def copy_target(physics, base):
        physics.named.model.geom_pos["target", :2] = base.model.geom("target").pos[:2]

    n = 0
    for physics, base, ts, reward in _drive_both(
            "GeoMDP/Reacher-v0", {"difficulty": difficulty}, "reacher", difficulty, copy_target):
        assert physics.named.model.geom_size["target", 0] == base.model.geom("target").size[0]
        np.testing.assert_array_equal(base.data.qpos, ts.observation["position"])
        obs = base.observe()
        q1, q2 = ts.observation["position"]
        np.testing.assert_array_equal(obs[:4], [np.cos(q1), np.sin(q1), np.cos(q2), np.sin(q2)])
        np.testing.assert_array_equal(obs[4:6], ts.observation["velocity"])
        np.testing.assert_array_equal(obs[6:8], ts.observation["to_target"])
        assert reward == ts.reward
        n += 1
    assert n == 1000


def test_pointmass3d_single_ball_is_point_mass_lifted_to_3d():
    """With the ball kept in the plane z = 0 and clear of the walls, PointMass3D
    (walls on) follows point_mass: same mass, damping, gear and time step."""
    env = gymnasium.make("GeoMDP/PointMass3D-v0", walls=True)
    env.reset(seed=0)
    base = env.unwrapped
    dm = suite.load("point_mass", "easy", task_kwargs={"random": 0})
    dm.reset()
    with dm.physics.reset_context():
        dm.physics.data.qpos[:] = [0.05, -0.1]
    base.data.qpos[:] = [0.05, -0.1, 0.0]
    base.set_state(base.get_state())
    rng = np.random.default_rng(1)
    for _ in range(100):
        a = rng.uniform(-0.3, 0.3, size=2)
        ts = dm.step(a)
        base.simulate(np.array([a[0], a[1], 0.0]))
        np.testing.assert_allclose(base.data.qpos[:2], ts.observation["position"], atol=1e-12)
        np.testing.assert_allclose(base.data.qvel[:2], ts.observation["velocity"], atol=1e-12)
