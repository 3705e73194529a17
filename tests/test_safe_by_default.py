"""Safe by default: a wrong declaration never trains, every bad option is one line (from
Python as from the command line), a run directory records what made the run, signals
are handled from the first moment, and the progress bar says what the run is doing."""

import csv
import re
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest
import yaml
from omegaconf import OmegaConf
from test_train import TINY, config

from agents.cli.train import run
from agents.options import OptionError
from agents.run.run_log import RunLog
from agents.run.run_tables import EVAL_COLUMNS, SESSION_COLUMNS, CsvTable
from agents.tdmpc.agent import TDMPCConfig
from geomdp_envs.declare import load_declaration

LAUNCH = [sys.executable, "-m", "agents.cli.launch"]
REACHER_V5 = ["env=gym", "env.id=Reacher-v5", "env.action_repeat=2", "train.steps=200",
              "train.seed_steps=100", "train.eval_every=200"]


def rows(path: Path) -> list[dict[str, str]]:
    with path.open(newline="") as f:
        return list(csv.DictReader(f))


def wrong_reacher(tmp_path: Path) -> Path:
    """Reacher-v5's shipped declaration with sin q2 declared trivial (it flips sign under
    reflections): trains silently unless checked."""
    data = load_declaration("reacher_v5").to_dict()
    for f in data["observation"]:
        if f["name"] == "sin_elbow":
            f["rep"] = "trivial"
    path = tmp_path / "wrong.yaml"
    path.write_text(yaml.safe_dump(data))
    return path


@pytest.mark.slow
# --- 1. a wrong declaration never trains ----------------------------------------------
def test_a_wrong_declaration_is_refused_before_anything_is_written(tmp_path, capsys):
    wrong = wrong_reacher(tmp_path)
    for agent in (["agent.group=D8"], ["agent.augment=auto"]):
        run_dir = tmp_path / "run"
        assert run(config(*REACHER_V5, f"env.symmetry={wrong}", *agent), run_dir) == 2
        (line,) = capsys.readouterr().err.strip().splitlines()
        assert line.startswith("geomdp-train: error: env.symmetry fails its check under O(2)"), line
        assert "env.check_symmetry=false" in line
        assert re.search(r"sin_elbow obs\[\d+\] \d\.\d\de\+00", line), line  # the env's index
        assert not run_dir.exists()


@pytest.mark.slow
def test_the_check_can_be_skipped_and_the_run_says_so(tmp_path):
    wrong = wrong_reacher(tmp_path)
    assert run(config(*REACHER_V5, f"env.symmetry={wrong}", "agent.group=D8",
                      "env.check_symmetry=false"), tmp_path / "skip") == 0
    (session,) = rows(tmp_path / "skip/sessions.csv")
    assert session["symmetry_check"] == "skipped (env.check_symmetry=false)"
    assert run(config(*REACHER_V5, "env.symmetry=reacher_v5", "agent.group=D8"),
               tmp_path / "ok") == 0
    (session,) = rows(tmp_path / "ok/sessions.csv")
    assert session["symmetry_check"].startswith("passed under O(2)")


# --- 2. one validator, from Python as from the command line -----------------------------
@pytest.mark.parametrize("kwargs, message", [
    ({"group": "Q8"}, "agent.group='Q8'; valid: none, C<N>, D<N>"),
    ({"augment": "bogus"}, "agent.augment='bogus'; valid: none, auto,"),
])
def test_group_and_augment_are_checked_when_the_config_is_built(kwargs, message):
    with pytest.raises(OptionError, match=re.escape(message)):
        TDMPCConfig(**kwargs)


@pytest.mark.slow
@pytest.mark.parametrize("args, message", [
    (["train.stepz=100"], "unknown option train.stepz; valid: checkpoint_every, eval_episodes,"),
    (["env=pointmass3d", "env.n_ballz=3"], "unknown option env.n_ballz; valid: action_repeat, id, "
                                           "n_balls,"),
    (["agent=tdmpc_papr"], "unknown agent=tdmpc_papr; valid: tdmpc, tdmpc_paper"),
    (["hydra.run.dir={tmp}/a_file/run"], "cannot create the run directory"),
])
def test_hydra_errors_are_one_line_with_status_2(tmp_path, args, message):
    (tmp_path / "a_file").write_text("")
    args = [a.format(tmp=tmp_path) for a in args]
    if not any(a.startswith("hydra.run.dir") for a in args):
        args.append(f"hydra.run.dir={tmp_path / 'run'}")
    out = subprocess.run([*LAUNCH, *args], capture_output=True, text=True, timeout=120)
    assert out.returncode == 2, out.stderr
    assert out.stderr.strip().splitlines() == [f"geomdp-train: error: {message}"] or (
        len(out.stderr.strip().splitlines()) == 1 and message in out.stderr), out.stderr
    assert not (tmp_path / "run").exists()


@pytest.mark.slow
# --- 3. a run directory records what made the run ---------------------------------------
def test_a_resume_keeps_the_records_and_logs_what_it_changed(tmp_path):
    assert run(config("train.steps=1000"), tmp_path) == 0
    assert run(config("train.steps=2000"), tmp_path) == 0
    assert OmegaConf.load(tmp_path / "config.yaml").train.steps == 1000  # made with
    first, second = rows(tmp_path / "sessions.csv")
    assert first["changed_options"] == "" and second["changed_options"] == "train.steps: 1000 -> 2000"
    assert list(first) == SESSION_COLUMNS
    for column in ("geomdp", "numpy", "mujoco", "dm_control", "gymnasium", "cpu"):
        assert first[column] not in ("", "absent"), column
    assert first["torch_threads"] == "1"


@pytest.mark.slow
def test_the_declaration_is_recorded_by_its_contents(tmp_path, capsys):
    path = tmp_path / "reacher.yaml"
    path.write_text(yaml.safe_dump(load_declaration("reacher_v5").to_dict()))
    run_dir = tmp_path / "run"
    assert run(config(*REACHER_V5, f"env.symmetry={path}", "agent.group=D8"), run_dir) == 0
    recorded = OmegaConf.to_container(OmegaConf.load(run_dir / "config.yaml"))["env"]["symmetry"]
    assert recorded == load_declaration("reacher_v5").to_dict()
    # the file is edited (a field renamed): the run cannot be continued with it
    path.write_text(path.read_text().replace("fingertip_to_target", "tip_to_target"))
    assert run(config(*REACHER_V5, f"env.symmetry={path}", "agent.group=D8",
                      "train.steps=400"), run_dir) == 2
    (line,) = capsys.readouterr().err.strip().splitlines()
    assert "holds a run with other options" in line and "env.symmetry.observation" in line


def test_a_run_log_is_written_only_when_rows_come(tmp_path):
    log = RunLog(tmp_path, tensorboard=False)
    assert log.eval.rows() == [] and log.truncate_after(-1) == 0  # readable before any row
    assert [p.name for p in tmp_path.iterdir()] == []


def test_sessions_written_by_an_older_version_gain_the_new_columns(tmp_path):
    path = tmp_path / "sessions.csv"
    path.write_text("env_step,started,git_commit,git_dirty,torch,escnn,torchrl,host\n"
                    "0,2026-01-01,abc,False,2.14.1,1.0.11,0.14.1,box\n")
    table = CsvTable(path, SESSION_COLUMNS, grows=True)
    table.append({"env_step": 1000, "cpu": "some cpu"})
    old, new = rows(path)
    assert list(old) == SESSION_COLUMNS and old["git_commit"] == "abc" and old["cpu"] == ""
    assert new["env_step"] == "1000" and new["cpu"] == "some cpu"
    (tmp_path / "other.csv").write_text("a,b\n")
    with pytest.raises(ValueError, match="other columns"):
        CsvTable(tmp_path / "other.csv", SESSION_COLUMNS, grows=True)


def test_an_eval_csv_from_before_the_value_check_is_continued_with_its_columns(tmp_path):
    old_columns = EVAL_COLUMNS[:EVAL_COLUMNS.index("q_start")]
    (tmp_path / "eval.csv").write_text(",".join(old_columns) + "\n0,0,0,0.0,5.0,1.0,10,4.0,1.0,3\n")
    log = RunLog(tmp_path, tensorboard=False)
    log.eval.append({"env_step": 5000, "episode_reward": 7.0, "q_start": 2.5})
    old, new = rows(tmp_path / "eval.csv")
    assert list(old) == EVAL_COLUMNS and old["episode_reward"] == "5.0" and old["q_start"] == ""
    assert new["q_start"] == "2.5"


# --- signals from the first moment, and the messages of an interrupted run ------------------
def handles_sigterm(pid: int) -> bool:
    """Whether the process has installed a SIGTERM handler (its caught-signals mask)."""
    try:
        status = Path(f"/proc/{pid}/status").read_text()
    except OSError:
        return False
    mask = int(re.search(r"^SigCgt:\s*([0-9a-f]+)", status, re.M).group(1), 16)
    return bool(mask >> (signal.SIGTERM - 1) & 1)


@pytest.mark.slow
@pytest.mark.skipif(not Path("/proc/self/status").exists(), reason="needs /proc")
def test_sigterm_while_importing_exits_130_and_writes_nothing(tmp_path):
    run_dir = tmp_path / "run"
    proc = subprocess.Popen([*LAUNCH, *TINY, f"hydra.run.dir={run_dir}"],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    deadline = time.time() + 60
    while not handles_sigterm(proc.pid):
        assert proc.poll() is None and time.time() < deadline, proc.communicate()
        time.sleep(0.001)
    proc.send_signal(signal.SIGTERM)  # torch, escnn and Hydra are still being imported
    _, err = proc.communicate(timeout=60)
    assert proc.returncode == 130, err
    assert "Traceback" not in err and "leaked semaphore" not in err, err


@pytest.mark.slow
def test_interrupted_before_the_first_checkpoint_says_so(tmp_path):
    """SIGTERM during the step-0 evaluation: no checkpoint exists yet, and the message
    does not pretend one does."""
    run_dir = tmp_path / "run"
    proc = subprocess.Popen([*LAUNCH, *TINY, "train.eval_episodes=20", f"hydra.run.dir={run_dir}"],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    deadline = time.time() + 180
    while not (run_dir / "sessions.csv").exists():  # restored: the evaluation has begun
        assert proc.poll() is None and time.time() < deadline, proc.communicate()
        time.sleep(0.05)
    proc.send_signal(signal.SIGTERM)
    _, err = proc.communicate(timeout=60)
    assert proc.returncode == 130, err
    assert "no checkpoint yet" in err and "checkpoint is at env step" not in err, err
    assert "leaked semaphore" not in err, err


@pytest.mark.slow
# --- progress -----------------------------------------------------------------------------
def test_the_bar_moves_within_episodes_and_states_rounding(tmp_path, capsys):
    assert run(config("train.progress=true", "train.steps=1500", "train.eval_episodes=2"),
               tmp_path) == 0
    err = capsys.readouterr()
    text = err.err + err.out
    assert "evaluating (episode 2/2)" in text
    assert "train.steps=1500 is not a whole number of episodes (1000 env steps each): " \
           "the run trains to 2000" in text
    assert "ETA" in text and "eval return" in text
    shown = {int(n) for n in re.findall(r"(\d+)/2000", text)}
    assert shown - {0, 1000, 2000}, "the bar moves within episodes"
