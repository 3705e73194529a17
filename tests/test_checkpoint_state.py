"""Reading how far a run got, without torch (the run queue's view of a checkpoint)."""

import json
import subprocess
import sys
from pathlib import Path

import pytest

from agents.run.checkpoint_state import describe, saved_state, saved_step

ROOT = Path(__file__).resolve().parents[1]


def write_state(directory: Path, text: str) -> None:
    directory.mkdir(parents=True)
    (directory / "state.json").write_text(text)


def test_the_checkpoint_then_the_one_an_interrupted_swap_left(tmp_path):
    assert saved_state(tmp_path) is None and saved_step(tmp_path) is None
    write_state(tmp_path / "checkpoint.old", json.dumps({"env_step": 3000}))
    assert saved_step(tmp_path) == 3000  # a save killed between its two renames
    write_state(tmp_path / "checkpoint", json.dumps({"env_step": 4000, "format": 3}))
    assert saved_step(tmp_path) == 4000 and saved_state(tmp_path)["format"] == 3


@pytest.mark.parametrize("text", ["{\"env_st", "{}", "{\"env_step\": \"many\"}", "[]"])
def test_an_unreadable_state_is_no_checkpoint(tmp_path, text):
    write_state(tmp_path / "checkpoint", text)
    assert saved_state(tmp_path) is None and saved_step(tmp_path) is None


def test_describe_says_where_inside_the_burst():
    assert describe({"env_step": 20000, "unfinished_episode": None}) == "env step 20000"
    inside = {"env_step": 20000, "pending_updates": 5000, "unfinished_episode": {"updates_done": 2750}}
    assert describe(inside) == "env step 20000, 2750 of its 5000 updates done"


def test_the_run_queue_reads_checkpoints_without_torch():
    code = ("import sys; sys.path.insert(0, 'scripts'); import run_queue; "
            "assert 'torch' not in sys.modules, 'torch imported'")
    done = subprocess.run([sys.executable, "-c", code], cwd=ROOT, capture_output=True, text=True)
    assert done.returncode == 0, done.stderr[-2000:]
