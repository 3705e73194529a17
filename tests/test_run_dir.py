"""The run directory: one process at a time, and records that show only options the
run really used."""

import os
import subprocess
import sys
from pathlib import Path

import pytest
from test_train import TINY, TRAIN, config

from agents.cli.train import run
from agents.run.checkpoint_state import WRITE_PROBE, checkpoint_paths
from agents.run.run_dir import RunDirError, RunDirLock, check_writable

REPO = Path(__file__).resolve().parent.parent

pytestmark = pytest.mark.slow  # every test trains an agent or starts geomdp-train


def test_a_second_process_on_a_run_directory_is_refused_in_one_line(tmp_path, capsys):
    """While one geomdp-train holds the directory, another is refused before it writes
    a row (two processes used to run to the end, interleaving eval.csv)."""
    with RunDirLock(tmp_path):  # flock: a second open file conflicts, even in this process
        assert run(config(), tmp_path) == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "is in use by another geomdp-train (pid " in err[0], err
    assert not (tmp_path / "eval.csv").exists() and not (tmp_path / "config.yaml").exists()
    assert run(config("train.steps=1000"), tmp_path) == 0  # released: the next one runs


def test_a_refused_resume_leaves_the_runs_records_untouched(tmp_path):
    args = [*TINY, "train.steps=1000", f"hydra.run.dir={tmp_path}"]
    first = subprocess.run([*TRAIN, *args], capture_output=True, text=True, timeout=300)
    assert first.returncode == 0, first.stderr[-2000:]
    records = {p: p.read_bytes() for p in [tmp_path / "config.yaml",
                                           *(tmp_path / ".hydra").glob("*.yaml")]}
    assert {p.name for p in records} == {"config.yaml", "hydra.yaml", "overrides.yaml"}
    assert "train.steps=1000" in (tmp_path / ".hydra" / "overrides.yaml").read_text()
    refused = subprocess.run([*TRAIN, *args, "agent.group=D4"], capture_output=True, text=True,
                             timeout=300)
    assert refused.returncode == 2 and "agent.group: 'none' -> 'D4'" in refused.stderr
    assert {p: p.read_bytes() for p in records} == records


def test_a_run_made_before_its_options_existed_resumes(tmp_path, finished_run):
    """A run directory and checkpoint from before ``agent.augment`` and TD-MPC's own choices
    (``agent.networks.layer_norm``, ...) existed resume (each option's no-op default is
    filled in: ``agents.run.nested.ADDED_LATER``)."""
    import json

    import yaml

    from agents.run.nested import ADDED_LATER

    finished_run(config("train.steps=1000"), copy_to=tmp_path)
    saved = yaml.safe_load((tmp_path / "config.yaml").read_text())
    manifest = json.loads((tmp_path / "checkpoint/manifest.json").read_text())
    removed = [k for k in ADDED_LATER if k in manifest["options"]]
    assert "agent.networks.layer_norm" in removed and "agent.augment" in removed
    for dotted in removed:
        *path, last = dotted.split(".")
        section = saved
        for part in path:
            section = section[part]
        del section[last]
        del manifest["options"][dotted]
    (tmp_path / "config.yaml").write_text(yaml.safe_dump(saved))
    (tmp_path / "checkpoint/manifest.json").write_text(json.dumps(manifest))
    assert run(config("train.steps=2000"), tmp_path) == 0


def test_every_option_newer_than_the_step_4_comparators_is_filled_in(finished_run):
    """Issue 37's step 4 pairs new runs with rung 1's (commit daa8c48): every option a run
    records today that rung 1's config.yaml lacks has its no-op default in ADDED_LATER, so
    that geomdp-plot groups them by the options they were made with."""
    import yaml

    from agents.run.nested import ADDED_LATER, flatten

    run_dir = finished_run(config("train.steps=1000"))
    today = flatten(yaml.safe_load((run_dir / "config.yaml").read_text()))
    rung1 = flatten(yaml.safe_load((REPO / "results/fidelity/rung1_schedule/plain/seed1/config.yaml")
                                   .read_text()))
    newer = {k for k in today if k not in rung1 and not k.startswith("env.")}
    assert newer and newer <= set(ADDED_LATER), sorted(newer - set(ADDED_LATER))
    assert all(today[k] == ADDED_LATER[k] for k in newer)


def test_the_cli_writes_records_only_for_an_accepted_run(tmp_path):
    out = subprocess.run([sys.executable, "-c", "from agents.cli.train import main; main()",
                          "train.steps=abc", f"hydra.run.dir={tmp_path / 'run'}"],
                         capture_output=True, text=True, timeout=120)
    assert out.returncode == 2 and not (tmp_path / "run").exists()


def test_constructing_a_trainer_writes_nothing(tmp_path):
    """The trainer receives its parts; only ``restore()`` touches the run directory."""
    from omegaconf import OmegaConf

    from agents.run.config import RunOptions, check_task
    from agents.run.run_log import RunLog
    from agents.run.trainer import Trainer, build_parts

    options = RunOptions.from_config(OmegaConf.to_container(config(), resolve=True))
    (tmp_path / "logs").mkdir()
    run_dir = tmp_path / "run"
    run_dir.mkdir()
    trainer = Trainer(options, run_dir, build_parts(options, check_task(options)),
                      RunLog(tmp_path / "logs"))
    assert list(run_dir.iterdir()) == []
    assert trainer.restore() == 0  # no checkpoint: a new run, its session recorded
    assert (tmp_path / "logs" / "sessions.csv").read_text().count("\n") == 2
    assert list(run_dir.iterdir()) == []


def test_a_run_directory_that_cannot_be_written_is_refused_in_one_line(tmp_path):
    """The write probe fails (here: a directory stands at its name, which fails even for
    root, who may write anywhere): refused before the run starts, naming the directory."""
    (tmp_path / WRITE_PROBE).mkdir()
    with pytest.raises(RunDirError, match=r"^cannot write in the run directory .*hydra\.run\.dir"):
        check_writable(tmp_path)


@pytest.mark.parametrize("which", range(3))
def test_an_unwritable_checkpoint_or_swap_partner_is_refused(tmp_path, monkeypatch, which):
    """Every directory a save replaces (the checkpoint, the one being written, the one being
    replaced) is checked, nested ones included; os.access stands in for permissions, which
    root (this suite's CI user) bypasses."""
    locked = checkpoint_paths(tmp_path)[which] / "agent"
    for path in checkpoint_paths(tmp_path):
        (path / "agent").mkdir(parents=True)
    real_access = os.access
    monkeypatch.setattr(os, "access", lambda p, mode: Path(p) != locked and real_access(p, mode))
    with pytest.raises(RunDirError, match=rf"^{locked} is not writable: "):
        check_writable(tmp_path)
    monkeypatch.setattr(os, "access", real_access)
    check_writable(tmp_path)  # writable again: accepted
