import dataclasses
import re
import runpy
import sys
from pathlib import Path
from types import SimpleNamespace

import gymnasium
import numpy as np
import pytest
from conftest import load_script

import geomdp_envs  # noqa: F401  (registers the tasks)

pytestmark = pytest.mark.slow  # runs the examples (SAC training, the demo)

ROOT = Path(__file__).resolve().parents[1]


@pytest.mark.parametrize("augment", [True, False], ids=["augmented", "plain"])
def test_sb3_sac_example_trains_with_and_without_augmentation(augment, monkeypatch, capsys):
    pytest.importorskip("stable_baselines3")
    flags = [] if augment else ["--no-augment"]
    monkeypatch.setattr(sys, "argv", ["sb3", "--steps", "300", "--eval-episodes", "1", *flags])
    runpy.run_path(str(ROOT / "examples" / "sb3_sac_augmented.py"), run_name="__main__")
    out = capsys.readouterr().out
    assert "after 300 steps" in out, out  # trained, then evaluated
    moved = re.search(r"augmentation moved (\d+) of (\d+) sampled transitions", out)
    if not augment:
        assert moved is None and "(plain SAC)" in out, out
        return
    assert moved, out
    n_moved, n_sampled = map(int, moved.groups())
    # SAC takes a batch of 256 per step from learning_starts (150) on: ~150 batches.
    assert n_sampled >= 100 * 256, out
    # PointMass2D augments with D4: 7 of its 8 elements move a (generic) transition.
    assert 0.8 * n_sampled < n_moved < 0.95 * n_sampled, out


def test_demo_runs_every_task(capsys):
    from geomdp_envs import demo

    demo.main(["--trials", "4"])
    out = capsys.readouterr().out
    assert out.count("random-policy return") == len(demo.DEMO_TASKS)
    assert "exact group   PASS" in out and "exact group   FAIL" not in out


def test_inspect_run_prints_each_balls_distance_to_the_target():
    """examples/inspect_run.py's distances: one number for one body, one per ball for N,
    nothing for a task that does not say them."""
    inspect_run = load_script("examples/inspect_run.py")
    assert inspect_run.distance_change(np.array([0.2]), np.array([0.0041])) == (
        " distance to target 0.200 -> 0.004")
    assert inspect_run.distance_change(np.array([0.2, 0.15]), np.array([0.002, 0.19])) == (
        " distance to target [0.2  0.15] -> [0.002 0.19 ]")
    assert inspect_run.distance_change(None, None) == ""
    env = gymnasium.make("GeoMDP/PointMass3D-v0", n_balls=3)
    env.reset(seed=0)
    assert inspect_run.distances_to_target(env).shape == (3,)
    assert inspect_run.distances_to_target(gymnasium.make("CartPole-v1")) is None


def test_inspect_run_values_the_last_tenth_at_its_mean_reward_forever():
    """examples/inspect_run.py --q-heads: over the last tenth of the agent steps, mean Q
    against r / (1 - discount); a constant reward's settled value is c / (1 - discount)."""
    inspect_run = load_script("examples/inspect_run.py")
    rewards = [0.0] * 45 + [2.0] * 5
    values = list(range(50))
    tail_q, settled = inspect_run.last_tenth([float(v) for v in values], rewards, 0.99)
    assert tail_q == pytest.approx(np.mean(values[-5:]))
    assert settled == pytest.approx(200.0)
    assert inspect_run.last_tenth([3.0], [1.0], 0.9) == pytest.approx((3.0, 10.0))  # one step


def test_inspect_run_moves_start_states_by_the_element_it_names(capsys):
    """examples/inspect_run.py --rotate/--reflect in 3D (the Reacher replays use 2D): the
    element is the rotation about the vertical axis after y -> -y, the moved start is what
    the task's declaration says g does to the observation, and an impossible request fails
    with one line naming the valid choice."""
    inspect_run = load_script("examples/inspect_run.py")
    assert inspect_run.start_transform(None, None, False) is None  # neither flag: no element
    env = gymnasium.make("GeoMDP/PointMass3D-v0", n_balls=2)
    obs, _ = env.reset(seed=3)
    g = inspect_run.start_transform(env, 90.0, True)
    np.testing.assert_allclose(g, [[0, 1, 0], [1, 0, 0], [0, 0, 1]], atol=1e-12)
    assert "rotation 90 deg after reflection y -> -y" in capsys.readouterr().out
    moved = inspect_run.moved_start(env, g)
    assert moved.dtype == obs.dtype and not np.allclose(moved, obs)
    expected = env.unwrapped.symmetry.observation_matrix(g) @ obs.astype(float)
    np.testing.assert_allclose(moved, expected, atol=1e-6)

    # a task symmetric under SO(3) only has no reflection to replay
    rotations_only = SimpleNamespace(transform_state=env.unwrapped.transform_state,
                                     symmetry=dataclasses.replace(env.unwrapped.symmetry,
                                                                  continuous_group="SO(3)",
                                                                  exact_group="SO(3)"))
    rotations_only.unwrapped = rotations_only
    with pytest.raises(SystemExit, match=r"no reflections; valid: --rotate alone"):
        inspect_run.start_transform(rotations_only, None, True)
    with pytest.raises(SystemExit, match=r"cannot move its state by a group element"):
        inspect_run.start_transform(gymnasium.make("CartPole-v1"), 10.0, False)
