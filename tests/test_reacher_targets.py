"""scripts/reacher_targets.py: a Reacher run's targets put back in the arena, success by direction."""

from __future__ import annotations

import importlib.util
import re
import subprocess
import sys
from pathlib import Path

import gymnasium
import numpy as np
import pytest
import torch
from tensordict import TensorDict

from agents.tdmpc.replay import ReplayConfig, make_replay_buffer, save_replay

SCRIPT = Path(__file__).resolve().parent.parent / "scripts" / "reacher_targets.py"
SPEC = importlib.util.spec_from_file_location("reacher_targets", SCRIPT)
reacher_targets = importlib.util.module_from_spec(SPEC)
SPEC.loader.exec_module(reacher_targets)


def episodes(frame: str, count: int, steps: int = 3):
    """``count`` short random episodes: their observations, episode ids and true targets."""
    env = gymnasium.make("GeoMDP/Reacher-v0", difficulty="hard", frame=frame)
    env.action_space.seed(0)
    observations, ids, targets = [], [], []
    for e in range(count):
        obs, _ = env.reset(seed=e)
        targets.append(env.unwrapped.model.geom("target").pos[:2].copy())
        for _ in range(steps):
            observations.append(obs)
            ids.append(e)
            obs, *_ = env.step(env.action_space.sample())
    return np.array(observations), np.array(ids), np.array(targets)


@pytest.mark.parametrize("frame", ["local", "global"])
def test_targets_are_put_back_where_the_task_drew_them(frame):
    observation, episode, truth = episodes(frame, count=6)
    found = reacher_targets.episode_targets(observation, episode, frame)
    assert sorted(found) == list(range(6))
    np.testing.assert_allclose(np.array([found[e] for e in range(6)]), truth, atol=1e-5)


def test_success_by_direction_is_tabled_and_tested(tmp_path):
    """Episodes whose target lies in the upper half of the arena are solved, the others
    not: the direction table shows it, and the permutation test rejects independence."""
    observation, episode, truth = episodes("local", count=40)
    upper = truth[:, 1] > 0
    reward = torch.tensor(upper[episode], dtype=torch.float32).unsqueeze(1)
    n = len(episode)
    buffer = make_replay_buffer(ReplayConfig(capacity=n), horizon=2, batch_size=2)
    buffer.extend(TensorDict({"observation": torch.tensor(observation, dtype=torch.float32),
                              "episode": torch.tensor(episode),
                              "action": torch.zeros(n, 2),
                              "next": {"reward": reward}}, [n]))
    (tmp_path / "checkpoint").mkdir()
    save_replay(buffer, tmp_path / "checkpoint" / "replay.pt")
    (tmp_path / "config.yaml").write_text("env:\n  name: reacher\n  frame: local\n")
    out = subprocess.run([sys.executable, str(SCRIPT), str(tmp_path), "--from-episode", "0",
                          "--solved", "2"], capture_output=True, text=True, check=True).stdout
    assert f"episodes 0-39 (40), solved {upper.sum()} (return > 2)" in out
    direction = next(line for line in out.splitlines() if line.startswith("by direction"))
    cells = re.findall(r"(\d+)-\d+° (\d+)/(\d+)", direction)
    assert len(cells) == 8
    for low, solved, total in cells:  # sectors 0-180° all solved, 180-360° none
        assert int(solved) == (int(total) if int(low) < 180 else 0), direction
    assert float(direction.rsplit("p = ", 1)[1]) < 0.01


def test_a_run_on_another_task_is_one_line(tmp_path):
    (tmp_path / "checkpoint").mkdir()
    (tmp_path / "checkpoint" / "replay.pt").write_bytes(b"")
    (tmp_path / "config.yaml").write_text("env:\n  name: pointmass2d\n")
    result = subprocess.run([sys.executable, str(SCRIPT), str(tmp_path)], capture_output=True, text=True)
    assert result.returncode != 0
    assert result.stderr.strip() == f"{tmp_path}: a run on 'pointmass2d'; this reads Reacher runs only"
