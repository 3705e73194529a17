"""Bad inputs to the environments: each gives one clear error naming the argument,
and the env keeps working afterwards."""

import copy
import gc
import pickle
import sys
import time

import gymnasium
import mujoco
import numpy as np
import pytest
import torch

from geomdp_envs import PhysicsError, SimState, augment_transitions, groups
from geomdp_envs.tasks.point_mass_3d import MAX_BALLS


def _one_line(err: pytest.ExceptionInfo) -> str:
    message = str(err.value)
    assert "\n" not in message
    return message


def _twins(env_id, **kwargs):
    """Two envs of the same task in the same state: one gets the bad input, the
    other shows what the next step should give."""
    envs = [gymnasium.make(env_id, **kwargs).unwrapped for _ in range(2)]
    for env in envs:
        env.reset(seed=0)
        env.step(np.full(env.action_space.shape, 0.5))
    return envs


def _assert_same_next_step(env, reference):
    np.testing.assert_array_equal(env.data.qpos, reference.data.qpos)
    np.testing.assert_array_equal(env.data.qvel, reference.data.qvel)
    action = np.full(env.action_space.shape, -0.3)
    obs, reward, *_ = env.step(action)
    ref_obs, ref_reward, *_ = reference.step(action)
    np.testing.assert_array_equal(obs, ref_obs)
    assert reward == ref_reward and np.all(np.isfinite(obs))


# --- 1. transforming integer arrays ---------------------------------------------
def test_transform_of_integer_arrays_is_floating_point():
    sym = gymnasium.make("GeoMDP/PointMass2D-v0").unwrapped.symmetry
    g = groups.rotation_2d(np.deg2rad(40))
    ints = np.array([1, 2, 3, 4])
    expected = sym.transform_observation(ints.astype(np.float64), g)
    out = sym.transform_observation(ints, g)
    assert out.dtype == np.float64
    np.testing.assert_array_equal(out, expected)  # was [0, 2, 0, 4]
    action = sym.transform_action(np.array([[1, 0]], dtype=np.int32), g)
    assert action.dtype == np.float64
    np.testing.assert_allclose(action, [[np.cos(0.7), np.sin(0.7)]], atol=0.01)
    # Float inputs keep their dtype; torch integer tensors become float64 too.
    assert sym.transform_observation(ints.astype(np.float32), g).dtype == np.float32
    tensor = sym.transform_observation(torch.tensor([1, 2, 3, 4]), g)
    assert tensor.dtype == torch.float64
    np.testing.assert_allclose(tensor.numpy(), expected)


def test_augmenting_integer_transitions_is_floating_point():
    sym = gymnasium.make("GeoMDP/Reacher-v0").unwrapped.symmetry  # exact group O(2)
    obs, action = np.tile(np.arange(1, 9), (16, 1)), np.tile([1, -1], (16, 1))
    for batch in [(obs, action, obs), tuple(torch.tensor(x) for x in (obs, action, obs))]:
        moved_obs, moved_action, _ = augment_transitions(sym, *batch, np.random.default_rng(0))
        moved_obs = np.asarray(moved_obs)
        assert moved_obs.dtype == np.float64 and np.asarray(moved_action).dtype == np.float64
        np.testing.assert_allclose(np.linalg.norm(moved_obs[:, :2], axis=1), np.sqrt(5))
        np.testing.assert_allclose(np.linalg.norm(moved_obs[:, 6:], axis=1), np.sqrt(113))


# --- 2. numpy scalars are numbers ---------------------------------------------
@pytest.mark.parametrize("kwargs", [
    {"target_size": np.float32(0.02)},
    {"target_size": np.float64(0.02)},
    {"target_size": np.int64(1)},
    {"n_balls": np.int64(2), "width": np.int32(32), "height": np.uint16(24)},
])
def test_numpy_scalars_are_accepted_as_numbers(kwargs):
    env = gymnasium.make("GeoMDP/PointMass3D-v0", **kwargs).unwrapped
    if "target_size" in kwargs:
        assert env.target_size == pytest.approx(float(kwargs["target_size"]))
        assert env.model.geom("target").size[0] == pytest.approx(float(kwargs["target_size"]))
    env.reset(seed=0)
    assert np.all(np.isfinite(env.step(np.zeros(env.action_space.shape))[0]))


@pytest.mark.parametrize("kwargs, message", [
    ({"target_size": True}, "target_size must be a positive number .* got True"),
    ({"target_size": np.float32("nan")}, "target_size must be a positive number"),
    ({"n_balls": True}, "n_balls must be an integer >= 1, got True"),
    ({"n_balls": np.float64(2.0)}, "n_balls must be an integer >= 1"),
    ({"width": np.True_}, "width must be an integer >= 1"),
])
def test_bools_and_non_integers_are_still_refused(kwargs, message):
    with pytest.raises(ValueError, match=message) as err:
        gymnasium.make("GeoMDP/PointMass3D-v0", **kwargs)
    _one_line(err)


# --- 3. pickling and copying after render() -----------------------------------
def test_pickle_and_deepcopy_after_render(monkeypatch):
    unraisable = []
    monkeypatch.setattr(sys, "unraisablehook", unraisable.append)  # "Exception ignored in ..."
    env = gymnasium.make("GeoMDP/PointMass2D-v0", render_mode="rgb_array", width=32, height=24)
    env.reset(seed=0)
    assert env.render().shape == (24, 32, 3)
    clones = [pickle.loads(pickle.dumps(env)), copy.deepcopy(env)]
    gc.collect()
    assert not unraisable
    rng = np.random.default_rng(0)
    for _ in range(5):
        action = rng.uniform(-1, 1, size=2).astype(np.float32)
        obs = env.step(action)[0]
        for clone in clones:
            np.testing.assert_array_equal(clone.step(action)[0], obs)
    frame = env.render()
    for clone in clones:
        np.testing.assert_array_equal(clone.render(), frame)
        clone.close()
    env.close()
    assert env.unwrapped._renderer is None
    gc.collect()
    assert not unraisable


# --- 4. non-finite states and diverging simulations ---------------------------
@pytest.mark.parametrize("field, value", [
    ("qpos", np.nan), ("qpos", np.inf), ("qpos", 1e300), ("qvel", -np.inf), ("qvel", 1e11),
])
def test_set_state_refuses_non_finite_states(field, value, monkeypatch, tmp_path):
    monkeypatch.chdir(tmp_path)
    env, reference = _twins("GeoMDP/PointMass2D-v0")
    state = env.get_state()
    getattr(state, field)[1] = value
    with pytest.raises(ValueError, match=f"set_state: state.{field} has NaN, inf or .* "
                                         "at index \\[1\\]") as err:
        env.set_state(state)
    _one_line(err)
    _assert_same_next_step(env, reference)
    assert not list(tmp_path.iterdir())  # no MUJOCO_LOG.TXT


def test_a_diverging_step_raises_physics_error(monkeypatch, tmp_path, capfd):
    monkeypatch.chdir(tmp_path)
    env = gymnasium.make("GeoMDP/PointMass3D-v0").unwrapped
    env.reset(seed=0)
    state = env.get_state()
    state.qvel[:] = 9e9  # a valid state, but damping makes the acceleration 3e10
    env.set_state(state)
    handler = mujoco.get_mju_user_warning()
    with pytest.raises(PhysicsError, match="PointMass3D: the simulation diverged at t=0.0200 s "
                                           "\\(.*QACC.*\\); call reset\\(\\)") as err:
        env.step(np.zeros(3))
    _one_line(err)
    assert isinstance(err.value, RuntimeError)
    assert mujoco.get_mju_user_warning() is handler  # MuJoCo's handler is put back
    # Not silently moved to the origin: stepping on keeps failing until reset.
    assert not np.all(env.data.qvel == 0)
    with pytest.raises(PhysicsError, match="diverged at t=0.0400 s"):
        env.simulate(np.zeros(3))
    assert pickle.loads(pickle.dumps(err.value)).details == err.value.details  # AsyncVectorEnv
    obs, _ = env.reset(seed=0)
    obs, reward, *_ = env.step(np.zeros(3))
    assert np.all(np.isfinite(obs)) and np.any(obs != 0)
    assert not list(tmp_path.iterdir())  # no MUJOCO_LOG.TXT
    out, errors = capfd.readouterr()
    assert "WARNING" not in out + errors


# --- 5. width and height ------------------------------------------------------
@pytest.mark.parametrize("kwargs, message", [
    ({"width": "abc"}, "PointMass2D: width must be an integer >= 1, got 'abc'"),
    ({"width": 0}, "width must be an integer >= 1, got 0"),
    ({"height": -5}, "height must be an integer >= 1, got -5"),
    ({"height": 24.0}, "height must be an integer >= 1, got 24.0"),
    ({"width": None}, "width must be an integer >= 1, got None"),
])
def test_width_and_height_are_validated_at_construction(kwargs, message):
    with pytest.raises(ValueError, match=message) as err:
        gymnasium.make("GeoMDP/PointMass2D-v0", render_mode="rgb_array", **kwargs)
    _one_line(err)


def test_numpy_and_large_image_sizes_render():
    env = gymnasium.make("GeoMDP/Reacher-v0", render_mode="rgb_array",
                         width=np.int64(700), height=np.int32(8))  # wider than MuJoCo's 640
    env.reset(seed=0)
    assert env.render().shape == (8, 700, 3)
    env.close()


# --- 6. Reacher's task state --------------------------------------------------
@pytest.mark.parametrize("task, message", [
    ({}, "Reacher: set_state: state.task is missing 'target'; expected keys: 'target'"),
    ({"target": np.zeros(2), "goal": np.zeros(2)}, "state.task has unknown 'goal'; expected keys"),
    ({"target": np.zeros(3)}, "state.task\\['target'\\] has shape \\(3,\\), expected \\(2,\\)"),
    ({"target": [np.nan, 0.0]}, "state.task\\['target'\\] has NaN"),
])
def test_reacher_set_state_names_a_missing_or_bad_target(task, message):
    env, reference = _twins("GeoMDP/Reacher-v0")
    target = env.model.geom("target").pos.copy()
    with pytest.raises(ValueError, match=message) as err:
        env.set_state(SimState(np.zeros(2), np.zeros(2), task))
    _one_line(err)
    np.testing.assert_array_equal(env.model.geom("target").pos, target)
    _assert_same_next_step(env, reference)


@pytest.mark.parametrize("state, message", [
    (SimState(np.zeros(3), np.zeros(2)), "state.qpos has shape \\(3,\\), expected \\(2,\\)"),
    (SimState(["a", "b"], np.zeros(2)), "state.qpos must be an array of numbers"),
    ((np.zeros(2), np.zeros(2)), "state must be a SimState \\(qpos, qvel, task\\) as get_state"),
])
def test_set_state_names_malformed_fields(state, message):
    env, reference = _twins("GeoMDP/PointMass2D-v0")
    with pytest.raises(ValueError, match=message) as err:
        env.set_state(state)
    _one_line(err)
    _assert_same_next_step(env, reference)


# --- 7. too many balls --------------------------------------------------------
@pytest.mark.parametrize("n_balls", [MAX_BALLS + 1, 10_000])
def test_too_many_balls_fail_fast(n_balls):
    assert MAX_BALLS == 1000
    start = time.perf_counter()
    with pytest.raises(ValueError, match=f"PointMass3D: n_balls={n_balls} is above "
                                         "MAX_BALLS = 1000") as err:
        gymnasium.make("GeoMDP/PointMass3D-v0", n_balls=n_balls)
    assert time.perf_counter() - start < 1.0
    _one_line(err)
