"""scripts/before_reward.py: an untrained equivariant policy pushes along the line to the
target; the first solved episode and the reward earned before it, from train.csv."""

from __future__ import annotations

import csv
import re
from pathlib import Path

import gymnasium
import numpy as np
import pytest
import torch
from conftest import TINY_AGENT, load_script, run_main
from omegaconf import OmegaConf

from agents import TDMPCAgent, agent_config
from agents.cli.train import run
from agents.run import checkpoint
from agents.run.presets import compose_config
from geomdp_envs import symmetry_of

before_reward = load_script("scripts/before_reward.py")


def test_alignment_is_the_cosine_with_each_balls_way_to_the_target():
    positions = np.array([[0.1, 0.0, 0.0, 0.0, 0.2, 0.0]])  # two balls, at rest
    observations = np.concatenate([positions, np.zeros_like(positions)], axis=1)
    actions = np.array([[-1.0, 0.0, 0.0, 1.0, 0.0, 0.0]])  # ball 1 inward, ball 2 sideways
    np.testing.assert_allclose(before_reward.alignment(observations, actions, 3), [[1.0, 0.0]])


def axis_of_rotation(group, angle: float) -> np.ndarray:
    """The axis of one of the group's rotations by ``angle``."""
    for element in group.elements():
        matrix = group.element_matrix(element)
        if np.isclose(np.linalg.det(matrix), 1) and np.isclose(np.trace(matrix), 1 + 2 * np.cos(angle)):
            values, vectors = np.linalg.eig(matrix)
            return np.real(vectors[:, np.argmin(np.abs(values - 1))])
    raise AssertionError(f"no rotation by {angle} in {group}")


@pytest.mark.parametrize("group, angle", [("icosahedral", 2 * np.pi / 5), ("octahedral", np.pi / 2)])
def test_an_untrained_equivariant_policy_at_rest_on_a_symmetry_axis_pushes_along_it(group, angle):
    """On an axis whose rotations fix nothing else, equivariance alone puts the action at
    rest on the line to the target (the origin), whatever the weights; a plain network's
    action there points elsewhere."""
    env = gymnasium.make("GeoMDP/PointMass3D-v0")
    torch.manual_seed(0)
    agent = TDMPCAgent(agent_config("tdmpc", f"group={group}", "width_strategy=linear"),
                       symmetry_of(env), 6, 3)
    axis = axis_of_rotation(agent.networks.group, angle)
    starts = np.array([[*(r * axis), 0, 0, 0] for r in (0.05, 0.15, -0.25)], dtype=np.float32)
    cos = before_reward.alignment(starts, agent.policy_action(torch.as_tensor(starts)).numpy(), 3)
    np.testing.assert_allclose(np.abs(cos), 1, atol=1e-5)
    torch.manual_seed(0)
    plain = TDMPCAgent(agent_config("tdmpc", "group=none"), symmetry_of(env), 6, 3)
    cos = before_reward.alignment(starts, plain.policy_action(torch.as_tensor(starts)).numpy(), 3)
    assert np.all(np.abs(cos) < 0.99), cos


def write_run(path: Path, group: str, returns: list[float], *overrides: str) -> Path:
    path.mkdir(parents=True)
    resolved = OmegaConf.to_container(compose_config(["env=pointmass3d", f"agent.group={group}",
                                                      "train.seed_steps=2000", *overrides]),
                                      resolve=True)
    OmegaConf.save(OmegaConf.create(resolved), path / "config.yaml")
    with open(path / "train.csv", "w", newline="") as f:
        writer = csv.writer(f)
        writer.writerow(["env_step", "episode", "episode_reward"])
        writer.writerows([1000 * (e + 1), e + 1, r] for e, r in enumerate(returns))
    return path


def test_the_first_solved_episode_and_the_reward_before_it(tmp_path, monkeypatch, capsys):
    early = write_run(tmp_path / "icosahedral", "icosahedral", [0.25, 0.0, 0.5, 850.0, 900.0])
    late = write_run(tmp_path / "plain", "none", [0.0, 0.0, 40.0, 99.0, 300.0])
    never = write_run(tmp_path / "never", "none", [0.0, 3.0, 0.0], "agent.augment=auto")
    blind = write_run(tmp_path / "blind", "octahedral", [0.0, 0.0, 0.0, 700.0])
    assert before_reward.first_solved(early, 2000, 100.0) == (3, 0.25, 0.5, 5)
    out, error = run_main(before_reward, monkeypatch, capsys, "runs", early, late, never, blind)
    assert error is None
    assert f"{early}: first solved episode 4 of 5; earned before it 0.25 in the warm-up, 0.5 after" in out
    assert f"{late}: first solved episode 5 of 5; earned before it 0 in the warm-up, 139 after" in out
    assert f"{never}: never solved in 3 episodes; earned 3 in the warm-up, 0 after" in out
    assert "icosahedral: 1 runs, 1 solved an episode, 1 of them before earning 1 in all (0 having " \
        "earned exactly 0)" in out
    assert "plain: 1 runs, 1 solved an episode, 0 of them before earning 1 in all" in out
    assert "plain, auto augmentation: 1 runs, 0 solved an episode, 0 of them before" in out
    assert "octahedral: 1 runs, 1 solved an episode, 1 of them before earning 1 in all (1 having " \
        "earned exactly 0)" in out
    assert "equivariant networks 2 of 2 runs, plain networks 0 of 2; Fisher's exact test p = 0.33" in out


def test_a_run_on_another_task_is_one_line(tmp_path, monkeypatch, capsys):
    run = write_run(tmp_path / "run", "none", [0.0])
    config = (run / "config.yaml").read_text().replace("name: pointmass3d", "name: reacher", 1)
    (run / "config.yaml").write_text(config)
    _, error = run_main(before_reward, monkeypatch, capsys, "runs", run)
    assert error == f"{run}: a run on 'reacher'; this reads PointMass runs only"


@pytest.mark.parametrize("missing", ["config.yaml", "train.csv"])
def test_a_run_directory_missing_a_file_is_one_line(tmp_path, monkeypatch, capsys, missing):
    run = write_run(tmp_path / "run", "none", [0.0])
    (run / missing).unlink()
    _, error = run_main(before_reward, monkeypatch, capsys, "runs", run)
    assert error.startswith(f"{run / missing}: no such file (a run directory holds ") and "\n" not in error


def test_restored_agents_are_measured_as_their_checkpoints_left_them(tmp_path, monkeypatch, capsys):
    """``restored``: a D4 run stopped after its burst of updates; the policy's alignment it
    prints is the restored agent's, and a run without a checkpoint is one line."""
    path = tmp_path / "D4"
    assert run(compose_config(["env.action_repeat=8", "train.steps=2000", "train.seed_steps=1000",
                               "train.eval_every=2000", "agent.group=D4", *TINY_AGENT]), path) == 0
    out, error = run_main(before_reward, monkeypatch, capsys, "restored", path, "--starts", 6,
                          "--episodes", 1)
    assert error is None
    restored = checkpoint.restore_run(path)
    starts = before_reward.start_states(restored.env, 6)
    cos = before_reward.alignment(starts, restored.agent.policy_action(torch.as_tensor(starts)).numpy(), 2)
    line = f"{path} (env step 2000): at rest, the policy {before_reward.cos_cell(cos)}, the planner's"
    assert line + " first action |cos| " in out
    assert re.search(r"^D4: 1 runs; mean \|cos\| at rest, policy (\S+)-\1, planner's first action "
                     r"\S+; solved by the policy [01]/1, by the planner [01]/1$", out, re.MULTILINE), out
    alignment_only, error = run_main(before_reward, monkeypatch, capsys, "restored", path, "--starts", 6,
                                     "--episodes", 0)
    assert error is None
    assert line in alignment_only and "returns" not in alignment_only and "solved" not in alignment_only
    (path / "checkpoint").rename(tmp_path / "elsewhere")
    _, error = run_main(before_reward, monkeypatch, capsys, "restored", path)
    assert error.startswith(f"no checkpoint in {path} ") and "\n" not in error
