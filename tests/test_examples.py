import runpy
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]


@pytest.mark.parametrize("flags", [[], ["--no-augment"]])
def test_sb3_sac_example_trains_with_and_without_augmentation(flags, monkeypatch):
    pytest.importorskip("stable_baselines3")
    monkeypatch.setattr(sys, "argv", ["sb3", "--steps", "300", "--eval-episodes", "1", *flags])
    runpy.run_path(str(ROOT / "examples" / "sb3_sac_augmented.py"), run_name="__main__")


def test_demo_runs_every_task(capsys):
    from geomdp_envs import demo

    demo.main(["--trials", "4"])
    out = capsys.readouterr().out
    assert out.count("random-policy return") == len(demo.DEMO_TASKS)
    assert "exact group   PASS" in out and "exact group   FAIL" not in out
