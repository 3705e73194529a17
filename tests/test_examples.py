import re
import runpy
import sys
from pathlib import Path

import pytest

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
