from pathlib import Path

import gymnasium
import numpy as np
import pytest
from conftest import TASK_CONFIGS

from geomdp_envs import check_symmetry, declare, groups, load_declaration
from geomdp_envs.check import declaration_table

SWIMMER = Path(__file__).resolve().parents[1] / "examples" / "swimmer_v5.yaml"


def reacher_v5(kind, name, **change):
    """Gymnasium's Reacher-v5 under the shipped declaration with one field changed: ``kind``
    is observation, action, state.qpos or state.qvel."""
    data = load_declaration("reacher_v5").to_dict()
    fields = data["state"][kind[len("state."):]] if kind.startswith("state.") else data[kind]
    (entry,) = [f for f in fields if f["name"] == name]
    entry.update(change)
    return declare(gymnasium.make("Reacher-v5"), data)


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
    # the rerun with zero actions (fixed by every g) still disagrees: not the action declaration
    assert "even with zero actions (which every g fixes): not the action declaration" in str(report)
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


def test_the_report_shows_the_env_indices_of_swapped_components():
    # (sin q1, cos q1) instead of (cos q1, sin q1): the declared slice [0:2] looks the same
    env = reacher_v5("observation", "upper_arm_direction", index=[2, 0])
    report = check_symmetry(env, n_trials=8)
    assert report.failing_fields == ["upper_arm_direction"]
    assert "fields over tolerance: upper_arm_direction obs[2,0] " in str(report)
    assert "the likely cause is the observation declaration" in str(report)
    table = declaration_table(env)
    assert "| observation | [0:2] | upper_arm_direction | vector | obs[2,0] |" in table
    assert "| action | [1:2] | elbow_torque | sign | act[1] |" in table
    # a built-in task's fields are where its declaration says
    assert "velocity obs[2,3]" not in str(check_symmetry(gymnasium.make("GeoMDP/PointMass2D-v0"),
                                                          n_trials=4))
    assert "| observation | [2:4] | velocity | vector | obs[2,3] |" in declaration_table(
        gymnasium.make("GeoMDP/PointMass2D-v0"))


def test_a_wrong_action_field_is_named_by_the_hint():
    report = check_symmetry(reacher_v5("action", "shoulder_torque", rep="trivial"),
                            n_trials=8)
    assert report.max_observation_error < 1e-12 < 1e-2 < report.max_next_observation_error
    assert ("with zero actions (which every g fixes) they do: the likely cause is the action "
            "declaration, fields shoulder_torque act[0] trivial, elbow_torque act[1] sign"
            ) in str(report)
    assert "state declaration" not in str(report)


def test_a_wrong_state_field_points_to_the_state_declaration():
    # the observation declaration is right; qvel's shoulder velocity is declared invariant
    report = check_symmetry(reacher_v5("state.qvel", "shoulder_velocity", rep="trivial"),
                            n_trials=8)
    assert not report.passed and report.failing_fields[0] == "shoulder_velocity"
    assert "shoulder_velocity obs[6] " in str(report)
    assert ("g.s does not step and is not rewarded like g applied to the run from s (zero actions, "
            "compared without rho_S): the likely cause is the state declaration") in str(report)
    # an orientation declared a sign only shows in the reward: the arm and the target move apart
    report = check_symmetry(reacher_v5("state.qpos", "shoulder", rep="sign"),
                            group="SO(2)", n_trials=8)
    assert "g.s steps but is not rewarded like g applied" in str(report)
    assert "either the state declaration" in str(report)


def test_the_swimmer_example_is_exact_under_d1_only():
    """examples/swimmer_v5.yaml: raw angles are sign fields under D1's reflection y -> -y."""
    declaration = load_declaration(str(SWIMMER))
    assert (declaration.dim, declaration.exact_group) == (2, "D1")
    assert {f.name: f.rep for f in declaration.observation}["torso_angle"] == "sign"
    env = declare(gymnasium.make("Swimmer-v5"), declaration)
    report = check_symmetry(env, n_trials=8)
    assert report.group == "D1" and report.passed and report.max_error < 1e-12, str(report)
    # rotations add to the raw torso angle, and the reward (x velocity) is not invariant
    report = check_symmetry(env, group="O(2)", n_trials=8)
    assert report.failing_fields == ["torso_angle"] and report.max_reward_error > 1e-2
    assert "or g is no symmetry of the reward" in str(report)
    # the raw angle declared invariant ("an angle is a scalar") is caught and named
    data = declaration.to_dict()
    data["observation"][0]["rep"] = "trivial"
    report = check_symmetry(declare(gymnasium.make("Swimmer-v5"), data), n_trials=8)
    assert report.failing_fields == ["torso_angle"] and "torso_angle obs[0] " in str(report)
    assert "the likely cause is the observation declaration" in str(report)
