import gymnasium
import numpy as np
import pytest
from conftest import TASK_CONFIGS

from geomdp_envs import check_symmetry, groups


@pytest.mark.parametrize("config", TASK_CONFIGS)
def test_every_task_is_exactly_symmetric_under_its_exact_group(config):
    env_id, kwargs = config
    env = gymnasium.make(env_id, **kwargs)
    report = check_symmetry(env, n_trials=48)
    assert report.passed, str(report)
    assert report.max_error < 1e-9


@pytest.mark.parametrize("config, subgroup", [
    (("GeoMDP/PointMass2D-v0", {}), "D4"),
    (("GeoMDP/Reacher-v0", {}), "D8"),
    (("GeoMDP/Reacher-v0", {"frame": "global"}), "C16"),
    (("GeoMDP/PointMass3D-v0", {"n_balls": 2}), "icosahedral"),
    (("GeoMDP/PointMass3D-v0", {}), "octahedral"),
    (("GeoMDP/PointMass3D-v0", {"walls": True}), "octahedral"),
])
def test_the_finite_groups_the_agents_use_are_exact_where_declared(config, subgroup):
    env_id, kwargs = config
    report = check_symmetry(gymnasium.make(env_id, **kwargs), group=subgroup, n_trials=32)
    assert report.passed, str(report)


def test_pointmass2d_reports_the_violation_of_a_45_degree_rotation_near_a_wall():
    env = gymnasium.make("GeoMDP/PointMass2D-v0")
    report = check_symmetry(env, elements=[groups.rotation_2d(np.pi / 4)], n_trials=32)
    assert not report.passed
    assert report.max_next_observation_error > 1e-2  # a wall stops one trajectory, not the other
    assert report.max_observation_error < 1e-12  # the declaration itself is right
    # Away from the walls the same rotation is a symmetry: states near the origin
    # with small velocities do not reach a wall in three steps.
    base = env.unwrapped
    base.sample_state = lambda rng: type(base.get_state())(
        rng.uniform(-0.05, 0.05, 2), rng.normal(scale=0.1, size=2))
    assert check_symmetry(env, elements=[groups.rotation_2d(np.pi / 4)], n_trials=32).passed


def test_pointmass3d_with_walls_is_not_icosahedral():
    env = gymnasium.make("GeoMDP/PointMass3D-v0", walls=True)
    assert not check_symmetry(env, group="icosahedral", n_trials=32).passed


def test_wrong_declarations_fail():
    # PointMass2D: velocity declared a pseudovector (wrong for D4's reflections).
    env = gymnasium.make("GeoMDP/PointMass2D-v0")
    wrong = env.unwrapped.symmetry.replace_field("observation", "velocity", "pseudovector")
    report = check_symmetry(env, symmetry=wrong, n_trials=16)
    assert not report.passed and report.max_observation_error > 1e-3
    # PointMass3D: forces declared as pseudovectors (wrong under reflections only).
    env = gymnasium.make("GeoMDP/PointMass3D-v0", n_balls=2)
    wrong = env.unwrapped.symmetry.replace_field("action", "force", "pseudovector")
    assert not check_symmetry(env, symmetry=wrong, group="O(3)", n_trials=16).passed
    assert check_symmetry(env, symmetry=wrong, group="SO(3)", n_trials=16).passed
    # Reacher: the paper's declaration (second link and torques trivial) is exact
    # under rotations only.
    env = gymnasium.make("GeoMDP/Reacher-v0")
    paper = (env.unwrapped.symmetry.replace_field("observation", "wrist_sin", "trivial")
             .replace_field("action", "shoulder_torque", "trivial")
             .replace_field("action", "wrist_torque", "trivial"))
    assert not check_symmetry(env, symmetry=paper, group="O(2)", n_trials=16).passed
    assert check_symmetry(env, symmetry=paper, group="SO(2)", n_trials=16).passed


def test_particle_relabelling_is_checked():
    env = gymnasium.make("GeoMDP/PointMass3D-v0", n_balls=3)
    report = check_symmetry(env, group="O(3)", n_trials=16)
    assert report.passed and report.worst_permutation is not None


def test_check_restores_the_simulator_state_and_rejects_foreign_groups():
    env = gymnasium.make("GeoMDP/Reacher-v0")
    obs, _ = env.reset(seed=5)
    check_symmetry(env, n_trials=4)
    np.testing.assert_array_equal(env.unwrapped.observe().astype(np.float32), obs)
    with pytest.raises(ValueError, match="acts on R\\^3, the task on R\\^2"):
        check_symmetry(env, group="icosahedral")
    with pytest.raises(TypeError, match="declares no symmetry"):
        check_symmetry(gymnasium.make("Pendulum-v1"))
