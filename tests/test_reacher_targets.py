"""scripts/reacher_targets.py: a Reacher run's training targets drawn again from its seed."""

from __future__ import annotations

import csv
import re

import numpy as np
import pytest
import torch
from conftest import TINY_AGENT, load_script, run_main

from agents.cli.train import run
from agents.run.presets import compose_config

reacher_targets = load_script("scripts/reacher_targets.py")

# Three 1000-step Reacher episodes (125 agent steps), the first random, a tiny agent.
TINY_REACHER = ["env=reacher", "env.difficulty=hard", "env.action_repeat=8", "seed=3",
                "train.steps=3000", "train.seed_steps=1000", "train.eval_every=3000", *TINY_AGENT]


@pytest.fixture(scope="module")
def reacher_run(tmp_path_factory):
    path = tmp_path_factory.mktemp("reacher")
    assert run(compose_config(TINY_REACHER), path) == 0
    return path


def test_training_episodes_are_drawn_again_from_the_seed(reacher_run):
    """The start states drawn from the run's seed are the ones its replay holds, exactly,
    and train.csv's returns are its episodes' in order."""
    replay = torch.load(reacher_run / "checkpoint" / "replay.pt", weights_only=False)["data"]
    episode = replay["episode"].numpy()
    first = np.array([replay["observation"][np.flatnonzero(episode == e)[0]].numpy() for e in range(3)])
    observations, targets = reacher_targets.training_starts(reacher_targets.run_options(reacher_run),
                                                            range(3))
    np.testing.assert_array_equal(observations, first)
    assert len({tuple(t) for t in targets}) == 3  # a new target every episode
    returns, starts = reacher_targets.episode_returns(reacher_run)
    earned = [float(replay["next", "reward"][episode == e].sum()) for e in range(3)]
    np.testing.assert_allclose(returns, earned, rtol=1e-5, atol=1e-4)
    assert starts.tolist() == [0, 1000, 2000]


def test_success_by_direction_is_tabled_and_tested(reacher_run, tmp_path, monkeypatch, capsys):
    """A train.csv whose episodes are solved exactly when the target lies in the upper
    half of the arena: the direction table shows it, the permutation test rejects
    independence."""
    options = reacher_targets.run_options(reacher_run)
    _, targets = reacher_targets.training_starts(options, range(40))
    upper = targets[:, 1] > 0
    (tmp_path / "config.yaml").write_text((reacher_run / "config.yaml").read_text())
    with open(tmp_path / "train.csv", "w", newline="") as f:
        writer = csv.writer(f)
        writer.writerow(["env_step", "episode", "episode_reward"])
        writer.writerows([1000 * (e + 1), e + 1, 500.0 if upper[e] else 3.0] for e in range(40))
    out, error = run_main(reacher_targets, monkeypatch, capsys, tmp_path, "--from-step", 0)
    assert error is None
    assert f"episodes 0-39 (40), solved {upper.sum()} (return > 100)" in out
    assert "returns: solved from 500, the others up to 3" in out
    direction = next(line for line in out.splitlines() if "by direction:" in line)
    cells = re.findall(r"(\d+)-\d+° (\d+)/(\d+)", direction)
    assert len(cells) == 8 and sum(int(total) for *_, total in cells) == 40
    for low, solved, total in cells:  # sectors 0-180° all solved, 180-360° none
        assert int(solved) == (int(total) if int(low) < 180 else 0), direction
    assert float(direction.rsplit("p = ", 1)[1]) < 0.01
    relative = next(line for line in out.splitlines() if "relative to the arm's start" in line)
    assert sum(int(total) for total in re.findall(r"\d+°? \d+/(\d+)", relative)) == 40, relative


def test_a_run_on_another_task_is_one_line(reacher_run, tmp_path, monkeypatch, capsys):
    config = (reacher_run / "config.yaml").read_text().replace("name: reacher", "name: pointmass2d", 1)
    (tmp_path / "config.yaml").write_text(config)
    (tmp_path / "train.csv").write_text("env_step,episode,episode_reward\n")
    _, error = run_main(reacher_targets, monkeypatch, capsys, tmp_path)
    assert error == f"{tmp_path}: a run on 'pointmass2d'; this reads Reacher runs only"


@pytest.mark.parametrize("missing", ["config.yaml", "train.csv"])
def test_a_run_directory_missing_a_file_is_one_line(reacher_run, tmp_path, monkeypatch, capsys, missing):
    for name in {"config.yaml", "train.csv"} - {missing}:
        (tmp_path / name).write_text((reacher_run / name).read_text())
    _, error = run_main(reacher_targets, monkeypatch, capsys, tmp_path)
    assert error.startswith(f"{tmp_path / missing}: no such file (a run directory holds ")
    assert "\n" not in error


def test_persistence_counts_the_second_half_in_the_first_halfs_holes():
    sector = np.array([0, 0, 1, 1, 0, 1, 0, 2])
    solved = np.array([False, False, True, False, True, True, False, False])
    # first half: sector 0 never solved (a hole), sector 1 solved once; sector 2 unvisited
    assert reacher_targets.persistence(sector, solved).tolist() == [1, 2, 1, 2]


def test_the_statistic_is_pearsons_chi_square_for_every_shuffle_in_a_batch():
    """The vectorised statistic the permutation test shuffles equals SciPy's chi-square of
    each table (which refuses only all-solved or none-solved runs), batch by batch."""
    from scipy.stats import chi2_contingency

    rng = np.random.default_rng(5)
    groups = rng.integers(0, 8, 80)
    batch = rng.random((6, 80)) < 0.3
    for solved, statistic in zip(batch, reacher_targets.chi_square(groups, batch, axis=-1)):
        table = [[np.sum((groups == g) & solved), np.sum((groups == g) & ~solved)]
                 for g in np.unique(groups)]
        assert statistic == pytest.approx(chi2_contingency(table, correction=False).statistic)
    assert reacher_targets.chi_square(groups, np.ones(80, bool)) == 0
