import pickle
import subprocess
import sys

import gymnasium
import numpy as np
import pytest
from conftest import TASK_CONFIGS
from gymnasium.utils.env_checker import check_env


@pytest.mark.parametrize("config", TASK_CONFIGS)
def test_gymnasium_env_checker_passes(config):
    env_id, kwargs = config
    env = gymnasium.make(env_id, render_mode="rgb_array", width=32, height=32, **kwargs)
    check_env(env.unwrapped, skip_render_check=False)
    assert env.observation_space.dtype == np.float32 and env.action_space.dtype == np.float32
    assert env.spec.max_episode_steps == 1000


@pytest.mark.parametrize("config", TASK_CONFIGS)
def test_reset_with_a_seed_is_deterministic(config):
    env_id, kwargs = config
    runs = []
    for _ in range(2):
        env = gymnasium.make(env_id, **kwargs)
        obs, _ = env.reset(seed=42)
        env.action_space.seed(0)
        trajectory = [obs] + [env.step(env.action_space.sample())[0] for _ in range(20)]
        runs.append(np.stack(trajectory))
    np.testing.assert_array_equal(runs[0], runs[1])
    assert not np.array_equal(gymnasium.make(env_id, **kwargs).reset(seed=43)[0], runs[0][0])


def test_pointmass3d_initial_state_is_rotation_invariant_in_distribution():
    env = gymnasium.make("GeoMDP/PointMass3D-v0", n_balls=5)
    starts = np.concatenate([env.reset(seed=s)[0][:15].reshape(5, 3) for s in range(400)])
    radii = np.linalg.norm(starts, axis=1)
    assert radii.max() <= 0.29 + 1e-6
    assert abs(np.mean((radii / 0.29) ** 3) - 0.5) < 0.03  # uniform in the ball
    # Directions as isotropic as Gaussian ones (a cube would favour its corners).
    def largest_component(x):
        return np.mean(np.abs(x / np.linalg.norm(x, axis=1, keepdims=True)).max(axis=1))

    isotropic = largest_component(np.random.default_rng(0).normal(size=(200_000, 3)))
    assert abs(largest_component(starts) - isotropic) < 0.015
    cube = np.random.default_rng(0).uniform(-1, 1, size=(200_000, 3))
    assert abs(largest_component(cube) - isotropic) > 0.03  # the test can tell the difference
    np.testing.assert_array_equal(env.reset(seed=0)[0][15:], 0.0)  # zero initial velocity


def test_pointmass3d_reward_averages_the_balls():
    env = gymnasium.make("GeoMDP/PointMass3D-v0", n_balls=2)
    env.reset(seed=0)
    base = env.unwrapped
    state = base.get_state()
    state.qpos[:] = [0, 0, 0, 1, 1, 1]  # ball 0 on the target, ball 1 far away
    state.qvel[:] = 0
    base.set_state(state)
    _, reward = base.simulate(np.zeros(6))
    assert reward == pytest.approx(0.5, abs=1e-3)


@pytest.mark.parametrize("config", TASK_CONFIGS)
def test_info_says_how_far_each_rewarded_body_is_from_its_target(config):
    """info["distance_to_target"], checked against the observation: the point masses'
    targets are at the origin, Reacher observes the finger-to-target vector last."""
    env_id, kwargs = config
    env = gymnasium.make(env_id, **kwargs)
    env.action_space.seed(0)
    obs, info = env.reset(seed=1)
    for _ in range(5):
        if env_id.startswith("GeoMDP/Reacher"):
            expected = [np.linalg.norm(obs[-2:])]
        else:
            dim = 2 if "PointMass2D" in env_id else 3
            n_bodies = kwargs.get("n_balls", 1)
            expected = np.linalg.norm(obs[:dim * n_bodies].reshape(n_bodies, dim), axis=1)
        assert info["distance_to_target"].shape == (len(expected),)
        np.testing.assert_allclose(info["distance_to_target"], expected, rtol=1e-5, atol=1e-6)
        obs, _, _, _, info = env.step(env.action_space.sample())


def test_reacher_target_sizes_and_frames():
    hard = gymnasium.make("GeoMDP/Reacher-v0", difficulty="hard", frame="global").unwrapped
    assert hard.model.geom("target").size[0] == 0.015
    obs = hard.reset(seed=0)[0]
    q1, q2 = hard.data.qpos
    np.testing.assert_allclose(obs[2:4], [np.cos(q1 + q2), np.sin(q1 + q2)], atol=1e-6)


@pytest.mark.parametrize("mode", ["sync", "async"])
def test_make_vec(mode):
    envs = gymnasium.make_vec("GeoMDP/PointMass3D-v0", num_envs=2, vectorization_mode=mode,
                              n_balls=2)
    obs, _ = envs.reset(seed=0)
    assert obs.shape == (2, 12)
    obs, reward, *_ = envs.step(np.zeros((2, 6), dtype=np.float32))
    assert reward.shape == (2,)
    envs.close()


def test_env_and_declaration_pickle():
    env = gymnasium.make("GeoMDP/Reacher-v0", frame="global")
    assert pickle.loads(pickle.dumps(env.unwrapped.symmetry)) == env.unwrapped.symmetry
    assert pickle.loads(pickle.dumps(env.spec)).kwargs == {"frame": "global"}


@pytest.mark.parametrize("config", TASK_CONFIGS)
def test_torchrl_gymenv_specs(config):
    from torchrl.envs import GymEnv
    from torchrl.envs.utils import check_env_specs

    env_id, kwargs = config
    env = GymEnv(env_id, **kwargs)
    check_env_specs(env)
    rollout = env.rollout(5)
    assert rollout["next", "reward"].shape == (5, 1)


@pytest.mark.parametrize("config", TASK_CONFIGS)
def test_headless_rgb_array_rendering(config):
    env_id, kwargs = config
    env = gymnasium.make(env_id, render_mode="rgb_array", width=64, height=48, **kwargs)
    env.reset(seed=0)
    frame = env.render()
    assert frame.shape == (48, 64, 3) and frame.dtype == np.uint8
    assert frame.std() > 5  # not a blank image
    env.close()


@pytest.mark.slow
def test_make_with_module_prefix_registers_without_import():
    code = ("import gymnasium; e = gymnasium.make('geomdp_envs:GeoMDP/PointMass3D-v0', n_balls=3);"
            "print(e.observation_space.shape)")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "(18,)"


@pytest.mark.parametrize("env_id, kwargs, message", [
    ("GeoMDP/Reacher-v0", {"difficulty": "medium"}, "difficulty='medium'; valid: 'easy', 'hard'"),
    ("GeoMDP/Reacher-v0", {"frame": "body"}, "frame='body'; valid: 'local', 'global'"),
    ("GeoMDP/PointMass3D-v0", {"n_balls": 0}, "n_balls must be an integer >= 1, got 0"),
    ("GeoMDP/PointMass3D-v0", {"n_balls": 2.5}, "n_balls must be an integer >= 1, got 2.5"),
    ("GeoMDP/PointMass3D-v0", {"target_size": -0.1}, "target_size must be a positive number"),
    ("GeoMDP/PointMass3D-v0", {"walls": "yes"}, "walls must be True or False"),
    ("GeoMDP/PointMass3D-v0", {"nballs": 3}, "unexpected keyword argument 'nballs'; valid "
                                             "arguments: n_balls, target_size, walls"),
    ("GeoMDP/PointMass2D-v0", {"difficulty": "hard"}, "unexpected keyword argument 'difficulty'"),
    ("GeoMDP/PointMass2D-v0", {"render_mode": "ansi"}, "render_mode='ansi'; valid"),
])
def test_bad_arguments_raise_a_clear_value_error(env_id, kwargs, message):
    with pytest.raises(ValueError, match=message):
        gymnasium.make(env_id, **kwargs)


@pytest.mark.parametrize("action, message", [
    (np.zeros(3), "shape \\(3,\\), expected \\(2,\\)"),
    (np.array([np.nan, 0.0]), "NaN or inf"),
    (np.array([np.inf, 0.0]), "NaN or inf"),
    ("left", "array of 2 numbers"),
])
def test_malformed_actions_are_refused_and_leave_the_state_untouched(action, message):
    env = gymnasium.make("GeoMDP/PointMass2D-v0").unwrapped
    env.reset(seed=0)
    env.step(np.array([0.5, 0.5]))
    before = env.get_state()
    ctrl = env.data.ctrl.copy()
    with pytest.raises(ValueError, match=message):
        env.step(action)
    after = env.get_state()
    np.testing.assert_array_equal(after.qpos, before.qpos)
    np.testing.assert_array_equal(after.qvel, before.qvel)
    np.testing.assert_array_equal(env.data.ctrl, ctrl)
