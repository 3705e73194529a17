"""The run queue's decisions (benchmarks/run_queue.py), with a stand-in trainer that
trains nothing: skip finished runs, resume from checkpoints, start over loudly, start
only what fits before the deadline, stop at the deadline with SIGTERM, copy logs
without checkpoints and commit exactly them."""
from __future__ import annotations

import datetime as dt
import os
import shlex
import signal
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest
from conftest import load_script

from agents.run.checkpoint_state import saved_step

pytestmark = pytest.mark.slow  # runs stand-in trainers as subprocesses

rq = load_script("scripts/run_queue.py")

# A trainer with geomdp-train's contract: resumes from checkpoint/state.json, logs
# eval.csv/train.csv/sessions.csv, checkpoints every step (atomically), and on SIGTERM
# stops at its next safe point with exit status 130.
FAKE_TRAIN = textwrap.dedent('''
    import json, os, signal, subprocess, sys, time
    from pathlib import Path
    opts = dict(a.split("=", 1) for a in sys.argv[1:])
    print("kernels", os.environ.get("OPENBLAS_CORETYPE", "native"), flush=True)
    run_dir, steps = Path(opts["hydra.run.dir"]), int(opts["train.steps"])
    delay = float(opts.get("delay", "0.01"))
    stop = []
    signal.signal(signal.SIGTERM, lambda *_: stop.append(1))  # stop at the next safe point
    commit = subprocess.run(["git", "rev-parse", "HEAD"], capture_output=True, text=True).stdout.strip()
    ckpt = run_dir / "checkpoint" / "state.json"
    step = json.loads(ckpt.read_text())["env_step"] if ckpt.exists() else 0
    if step == 0:
        (run_dir / "eval.csv").write_text("env_step,wall_time,episode_reward\\n")
        (run_dir / "train.csv").write_text("env_step,wall_time\\n")
    with (run_dir / "sessions.csv").open("a") as f:
        if f.tell() == 0:
            f.write("env_step,git_commit,git_dirty\\n")
        f.write(f"{step},{commit},False\\n")
    ckpt.parent.mkdir(exist_ok=True)
    while step < steps:
        if stop:
            sys.exit(130)
        time.sleep(delay)
        step += 1
        for name in ("eval.csv", "train.csv"):
            with (run_dir / name).open("a") as f:
                f.write(f"{step},{60.0 * step}" + (",1.0" if name == "eval.csv" else "") + "\\n")
        tmp = ckpt.with_suffix(".tmp")
        tmp.write_text(json.dumps({"env_step": step}))
        os.replace(tmp, ckpt)
    print("done", run_dir)
''')


def git(repo: Path, *args: str) -> str:
    return subprocess.run(["git", "-C", str(repo), *args], check=True, capture_output=True,
                          text=True).stdout.strip()


@pytest.fixture
def repo(tmp_path: Path) -> Path:
    repo = tmp_path / "checkout"
    repo.mkdir()
    git(repo, "init", "-q")
    git(repo, "config", "user.email", "t@t")
    git(repo, "config", "user.name", "t")
    (repo / "fake_train.py").write_text(FAKE_TRAIN)
    (repo / ".gitignore").write_text("checkpoint/\n")
    git(repo, "add", ".")
    git(repo, "commit", "-q", "-m", "code")
    git(repo, "tag", "code")  # the pinned commit (results commits come after it)
    return repo


def make_queue(repo: Path, plan: str, minutes_left: float, **kw: object) -> rq.Queue:
    commit, worktree = rq.pinned_worktree(repo, "code", repo.parent / "pinned")
    deadline = dt.datetime.now() + dt.timedelta(minutes=minutes_left)
    return rq.Queue(rq.read_plan(plan), repo, commit, worktree, deadline, python=sys.executable,
                    module="fake_train", poll_seconds=0.05, stop_grace_seconds=10, **kw)


def test_plan_lines_are_checked() -> None:
    runs = rq.read_plan("# comment\nresults/a/D8/seed1 100 agent.group=D8 seed=1  # why\n")
    assert [(r.dest, r.steps, r.overrides, r.group) for r in runs] == [
        ("results/a/D8/seed1", 100, ["agent.group=D8", "seed=1"], "results/a/D8")]
    for bad, says in [("results/a many", "<env steps>"), ("../x 10", "inside the checkout"),
                      ("r/a 1\nr/a 2", "listed twice")]:
        with pytest.raises(rq.PlanError, match=says):
            rq.read_plan(bad)
    # several plans: one queue in the order given; a run in two plans, or a bad line, named
    runs = rq.read_plans([("p1", "r/b 1\nr/a 1"), ("p2", "r/c 2")])
    assert [r.dest for r in runs] == ["r/b", "r/a", "r/c"]
    for plans, says in [([("p1", "r/a 1"), ("p2", "r/b 1\nr/a 2")], "p2: r/a is also in p1"),
                        ([("p1", "r/a 1"), ("p2", "r/b x")], "p2: plan line 1")]:
        with pytest.raises(rq.PlanError, match=says):
            rq.read_plans(plans)
    with pytest.raises(rq.PlanError, match="PATTERN=MINUTES"):
        rq.parse_estimates(["results/a=soon"])
    now = dt.datetime(2026, 1, 1, 12, 0)
    assert rq.parse_deadline("13:30", now) == dt.datetime(2026, 1, 1, 13, 30)
    assert rq.parse_deadline("11:00", now) == dt.datetime(2026, 1, 2, 11, 0)
    assert rq.parse_deadline("+2h", now) == dt.datetime(2026, 1, 1, 14, 0)
    with pytest.raises(rq.PlanError, match="HH:MM"):
        rq.parse_deadline("soon", now)


def test_only_runs_that_fit_before_the_deadline_start(repo: Path) -> None:
    plan = "results/x/slow/seed1 4\nresults/x/fast/seed1 4\nresults/x/fast/seed2 4\n"
    queue = make_queue(repo, plan, minutes_left=20,
                       estimates=rq.parse_estimates(["results/x/slow/*=45", "results/x/fast*=10"]))
    now = dt.datetime.now()
    assert queue.next_to_start(now).dest == "results/x/fast/seed1"  # slow (45 min) does not fit
    # a finished run of the group replaces the estimate: 4 steps x 60 s + start-up = 5 min
    done = repo / "results/x/slow/seed9"
    done.mkdir(parents=True)
    (done / "eval.csv").write_text("env_step,wall_time,episode_reward\n4,240.0,1.0\n")
    queue.runs.append(rq.Run("results/x/slow/seed9", 4, [], repo / "unused"))
    assert queue.remaining(queue.runs[0]) == pytest.approx(4 + rq.STARTUP_MINUTES)
    assert queue.next_to_start(now).dest == "results/x/slow/seed1"
    # half-way through its checkpoints, a run needs half the time (plus a start-up)
    ckpt = queue.runs[0].work / "checkpoint"
    ckpt.mkdir(parents=True)
    (ckpt / "state.json").write_text('{"env_step": 2}')
    assert queue.remaining(queue.runs[0]) == pytest.approx(2 + rq.STARTUP_MINUTES)
    assert make_queue(repo, plan, minutes_left=1).next_to_start(now) is None


def test_carried_over_runs_start_without_fitting_and_stop_at_the_deadline(repo: Path) -> None:
    """A run longer than any session (--carry-over) starts when it cannot finish, advances
    to its checkpoint before the deadline's SIGTERM, and the next call resumes it."""
    plan = "results/x/long/seed1 400 delay=0.01\nresults/x/short/seed1 4\n"
    estimates = rq.parse_estimates(["results/x/*=600"])
    now = dt.datetime.now()
    assert make_queue(repo, plan, 30, estimates=estimates).next_to_start(now) is None
    queue = make_queue(repo, plan, 30, estimates=estimates, carry_over=["results/x/long"])
    assert [queue.fits(r, now) for r in queue.runs] == [True, False]
    assert queue.next_to_start(now).dest == "results/x/long/seed1"
    # too close to the deadline for a carried-over run to advance: nothing starts
    late = make_queue(repo, plan, 5, estimates=estimates, carry_over=["results/x/long"])
    assert late.next_to_start(now) is None
    queue.deadline = dt.datetime.now() + dt.timedelta(seconds=1.5)
    queue.carry_over_minutes = 0.0  # the 1.5 s left are enough for this stand-in trainer
    queue.run()
    step = saved_step(queue.runs[0].work)
    assert step is not None and 0 < step < 400
    assert saved_step(repo / "results/x/long/seed1") == step  # carried, not finished
    resumed = make_queue(repo, plan, 30, estimates=estimates, carry_over=["results/x/long"])
    resumed.run()
    assert rq.logged_step(repo / "results/x/long/seed1") == 400
    assert "resuming from its checkpoint" in (queue.runs[0].work / "stdout.log").read_text()


def test_a_carried_run_is_committed_with_its_checkpoint_and_resumes_on_a_fresh_machine(
        repo: Path) -> None:
    """Stopped at the deadline, a carried-over run's directory is committed with its
    checkpoint; a queue whose worktree is new (another machine) resumes from it, and
    when the run finishes its checkpoint leaves the tree."""
    plan = "results/x/long/seed1 300 delay=0.01\n"
    queue = make_queue(repo, plan, 30, carry_over=["results/x/*"], carry_over_minutes=0.0)
    queue.deadline = dt.datetime.now() + dt.timedelta(seconds=1.5)
    queue.run()
    step = saved_step(queue.runs[0].work)
    assert step is not None and 0 < step < 300
    dest = repo / "results/x/long/seed1"
    assert saved_step(dest) == step and rq.logged_step(dest) == step
    message = git(repo, "log", "-1", "--format=%s")
    assert f"results/x/long/seed1 carried at env step {step}" in message
    assert "results/x/long/seed1/checkpoint/state.json" in git(repo, "ls-files", "results")
    assert not git(repo, "status", "--porcelain", "--ignored", "--", "results")
    # a fresh machine: the pinned worktree is gone, the checkout holds what was committed
    git(repo, "worktree", "remove", "--force", str(queue.worktree))
    fresh = make_queue(repo, plan, 30, carry_over=["results/x/*"])
    assert fresh.run() == 0
    log = (fresh.runs[0].work / "stdout.log").read_text()
    assert f"resuming from its checkpoint at env step {step}" in log and "cpu " in log
    kernels = os.environ.get("OPENBLAS_CORETYPE") or rq.blas_kernels().get("OPENBLAS_CORETYPE")
    assert f"kernels {kernels or 'native'}" in log  # what the trainer got
    assert rq.logged_step(dest) == 300
    assert (dest / "eval.csv").read_text().count("\n") == 301  # header + steps 1..300 once
    assert "checkpoint" not in git(repo, "ls-files", "results")
    assert not (dest / "checkpoint").exists()
    assert "results/x/long/seed1 finished" in git(repo, "log", "-1", "--format=%s")


def test_queue_skips_finished_resumes_partial_and_commits_logs_only(repo: Path) -> None:
    plan = ("results/x/a/seed1 3 delay=0.01\n"   # finished earlier: skipped
            "results/x/a/seed2 6 delay=0.01\n"   # checkpoint at 3 on this machine: resumes
            "results/x/a/seed3 3 delay=0.01\n"   # logs committed, no checkpoint here: starts over
            "results/x/a/seed4 3 delay=0.01\n")  # new
    queue = make_queue(repo, plan, minutes_left=60,
                       estimates=rq.parse_estimates(["results/x/*=1"]))
    finished_before = repo / "results/x/a/seed1"
    finished_before.mkdir(parents=True)
    (finished_before / "eval.csv").write_text("env_step,wall_time,episode_reward\n3,1.0,5.0\n")
    partial = queue.runs[1].work
    partial.mkdir(parents=True)
    subprocess.run([sys.executable, "-m", "fake_train", "train.steps=3",
                    f"hydra.run.dir={partial}"], cwd=queue.worktree, check=True, capture_output=True)
    earlier = repo / "results/x/a/seed3"
    earlier.mkdir(parents=True)
    (earlier / "eval.csv").write_text("env_step,wall_time,episode_reward\n0,0.0,0.0\n1,60.0,1.0\n")
    git(repo, "add", "results")  # the earlier runs' logs were committed
    git(repo, "commit", "-q", "-m", "earlier runs")
    head_before = git(repo, "rev-parse", "HEAD")
    (repo / "unrelated.txt").write_text("work in progress")
    git(repo, "add", "unrelated.txt")

    assert queue.run() == 0
    assert not (queue.worktree / "results/x/a/seed1").exists()
    assert "resuming from its checkpoint at env step 3" in (partial / "stdout.log").read_text()
    assert "STARTING OVER" in (queue.runs[2].work / "stdout.log").read_text()
    assert "STARTING OVER" not in (queue.runs[3].work / "stdout.log").read_text()
    for seed, steps in [(2, 6), (3, 3), (4, 3)]:
        dest = repo / f"results/x/a/seed{seed}"
        assert rq.logged_step(dest) == steps and not (dest / "checkpoint").exists()
    # eval.csv of the resumed run holds steps 1..6 once each
    assert (repo / "results/x/a/seed2/eval.csv").read_text().count("\n") == 7
    commits = git(repo, "log", "--format=%s", f"{head_before}..HEAD").splitlines()
    assert len(commits) == 3 and all("finished" in c for c in commits)
    committed = git(repo, "diff", "--name-only", head_before, "HEAD").splitlines()
    assert all(p.startswith("results/x/a/seed") for p in committed)
    assert not any("checkpoint" in p for p in committed)
    assert git(repo, "diff", "--cached", "--name-only") == "unrelated.txt"  # left staged


def test_logs_a_stopped_queue_left_uncommitted_are_committed(repo: Path) -> None:
    plan = "results/x/a/seed1 2 delay=0.01\n"
    queue = make_queue(repo, plan, minutes_left=60, estimates=rq.parse_estimates(["*=0.01"]),
                       commit_results=False)
    assert queue.run() == 0 and rq.logged_step(repo / "results/x/a/seed1") == 2
    assert git(repo, "status", "--porcelain", "--", "results")  # copied, not committed
    queue = make_queue(repo, plan, minutes_left=60, estimates=rq.parse_estimates(["*=0.01"]))
    assert queue.run() == 0
    assert not git(repo, "status", "--porcelain", "--", "results")
    assert "results/x/a/seed1 finished" in git(repo, "log", "-1", "--format=%s")


def test_deadline_stops_runs_with_sigterm_and_they_resume(repo: Path) -> None:
    plan = "results/x/long/seed1 100000 delay=0.01\n"
    queue = make_queue(repo, plan, minutes_left=0.03, estimates=rq.parse_estimates(["*=0.01"]))
    assert queue.run() == 0
    run = queue.runs[0]
    step = saved_step(run.work)
    assert step and 0 < step < 100000 and rq.logged_step(run.work) == step
    assert not (repo / run.dest).exists()  # unfinished: nothing copied, nothing committed
    queue = make_queue(repo, plan.replace("100000", str(step + 2)), minutes_left=60,
                       estimates=rq.parse_estimates(["*=0.01"]))
    assert queue.run() == 0
    assert f"resuming from its checkpoint at env step {step}" in (run.work / "stdout.log").read_text()
    assert rq.logged_step(repo / run.dest) == step + 2


@pytest.fixture
def start_outside_the_queue():
    """Starts a trainer as an earlier, since killed, queue would have: not this process's
    child (the shell that starts it exits), its process id in the run directory. Any
    still alive at the end of the test (it failed) is killed."""
    pids = []

    def start(queue: rq.Queue, run: rq.Run) -> int:
        run.work.mkdir(parents=True, exist_ok=True)
        command = shlex.join(run.argv(sys.executable, "fake_train"))
        pid = int(subprocess.run(["sh", "-c", f"{command} > /dev/null 2>&1 & echo $!"],
                                 cwd=queue.worktree, check=True, capture_output=True,
                                 text=True).stdout)
        (run.work / rq.PID_FILE).write_text(str(pid))
        pids.append(pid)
        return pid

    yield start
    for pid in pids:
        try:
            if b"fake_train" in Path(f"/proc/{pid}/cmdline").read_bytes():
                os.kill(pid, signal.SIGKILL)
        except OSError:
            pass


def test_a_restarted_queue_adopts_runs_still_training(repo: Path, capsys,
                                                      start_outside_the_queue) -> None:
    # an adopted run that the deadline stops is reported stopped, not failed
    plan = "results/x/long/seed1 100000 delay=0.01\n"
    queue = make_queue(repo, plan, minutes_left=0.02, estimates=rq.parse_estimates(["*=0.01"]))
    start_outside_the_queue(queue, queue.runs[0])
    assert queue.run() == 0
    assert "stopped results/x/long/seed1 at its checkpoint" in capsys.readouterr().out
    assert saved_step(queue.runs[0].work) and not (repo / "results/x/long").exists()
    # a process id written there whose process trains something else is not adopted
    (queue.runs[0].work / rq.PID_FILE).write_text(str(os.getpid()))
    assert rq.running_pid(queue.runs[0].work) is None
    # an adopted run holds a slot until it finishes, and is collected
    plan = "results/x/a/seed1 40 delay=0.01\nresults/x/a/seed2 3 delay=0.01\n"
    queue = make_queue(repo, plan, minutes_left=60, estimates=rq.parse_estimates(["*=0.01"]),
                       parallel=1)
    pid = start_outside_the_queue(queue, queue.runs[0])
    assert rq.running_pid(queue.runs[0].work) == pid
    assert queue.run() == 0
    out = capsys.readouterr().out
    assert f"adopted results/x/a/seed1: process {pid}" in out
    assert out.index("finished results/x/a/seed1") < out.index("starting: results/x/a/seed2")
    assert rq.logged_step(repo / "results/x/a/seed1") == 40
    assert "results/x/a/seed2 finished" in git(repo, "log", "-1", "--format=%s")


def test_runs_from_another_commit_are_not_collected(repo: Path) -> None:
    queue = make_queue(repo, "results/x/a/seed1 2\n", minutes_left=60,
                       estimates=rq.parse_estimates(["*=0.01"]))
    work = queue.runs[0].work
    work.mkdir(parents=True)
    (work / "eval.csv").write_text("env_step,wall_time,episode_reward\n2,1.0,1.0\n")
    (work / "sessions.csv").write_text("env_step,git_commit,git_dirty\n0,0123456789abcdef,False\n")
    assert queue.run() == 1
    assert not (repo / "results/x/a/seed1").exists()


def test_worktree_must_be_the_pinned_commit(repo: Path) -> None:
    commit, worktree = rq.pinned_worktree(repo, "code", repo.parent / "pinned")
    (repo / "more.txt").write_text("x")
    git(repo, "add", "more.txt")
    git(repo, "commit", "-q", "-m", "later")
    with pytest.raises(rq.PlanError, match="not the pinned"):
        rq.pinned_worktree(repo, "HEAD", worktree)
    (worktree / "fake_train.py").write_text("# edited\n")
    with pytest.raises(rq.PlanError, match="local changes"):
        rq.pinned_worktree(repo, commit, worktree)
    with pytest.raises(rq.PlanError, match="not a commit"):
        rq.pinned_worktree(repo, "no-such-commit", None)


def test_every_plan_line_is_a_valid_run():
    """The committed plans compose and pass every option check with this code (a typo
    would otherwise surface hours into a queue). This code, not the commit a plan is
    run from: an option a plan needs must exist here too, and a plan whose options
    this code renamed fails here."""
    import warnings

    from omegaconf import OmegaConf

    from agents.run.config import RunOptions, check_task
    from agents.run.presets import compose_config

    plans = sorted((Path(__file__).resolve().parent.parent / "scripts" / "plans").glob("*.txt"))
    assert plans
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # approximate groups warn (D8 on PointMass2D)
        plan_runs = [run for plan in plans for run in rq.read_plan(plan.read_text())]
        for run in plan_runs:  # seeds checked here, then set aside: the same checks
            seeds = [o.split("=", 1)[1] for o in run.overrides if o.startswith("seed=")]
            assert len(seeds) == 1 and seeds[0].isdigit(), (run.dest, run.overrides)
        runs = {(run.steps, *sorted(o for o in run.overrides if not o.startswith("seed=")))
                for run in plan_runs}
        for steps, *overrides in sorted(runs):
            cfg = compose_config([*overrides, f"train.steps={steps}"])
            check_task(RunOptions.from_config(OmegaConf.to_container(cfg, resolve=True)))


def test_dry_run_prints_the_plan_and_makes_no_worktree(repo: Path, monkeypatch, capsys) -> None:
    monkeypatch.setattr(rq, "REPO", repo)
    plan = repo / "plan.txt"
    plan.write_text("results/x/a/seed1 100 seed=1\n")
    worktree = repo.parent / "not-made"
    assert rq.main([str(plan), "--commit", "HEAD", "--deadline", "+1h", "--worktree", str(worktree),
                    "--module", "fake_train", "--estimate", "results/x/*=5", "--dry-run"]) == 0
    out = capsys.readouterr().out
    assert "5 min fits  results/x/a/seed1" in out and "fake_train seed=1 train.steps=100" in out
    assert "(in 1.0 h)" in out  # how far the deadline is: an HH:MM read as tomorrow shows
    assert not worktree.exists() and "not-made" not in git(repo, "worktree", "list")
    second = repo / "plan2.txt"  # a second plan queues after the first
    second.write_text("results/y/a/seed1 100 seed=2\n")
    assert rq.main([str(plan), str(second), "--commit", "HEAD", "--deadline", "+1h",
                    "--worktree", str(worktree), "--module", "fake_train", "--dry-run"]) == 0
    out = capsys.readouterr().out
    assert "queue: 2 runs" in out and out.index("results/x/a/seed1") < out.index("results/y/a/seed1")


def test_an_adopted_carried_run_is_committed_with_its_checkpoint(repo: Path, capsys,
                                                                 start_outside_the_queue) -> None:
    """The carry also covers a trainer an earlier, killed queue started (its exit status is
    inferred): stopped at the deadline, it is committed with its checkpoint."""
    plan = "results/x/long/seed1 100000 delay=0.01\n"
    queue = make_queue(repo, plan, minutes_left=0.03, carry_over=["results/x/*"])
    start_outside_the_queue(queue, queue.runs[0])
    assert queue.run() == 0
    assert "adopted results/x/long/seed1" in capsys.readouterr().out
    step = saved_step(queue.runs[0].work)
    assert step and saved_step(repo / "results/x/long/seed1") == step
    assert f"carried at env step {step}" in git(repo, "log", "-1", "--format=%s")


def test_runs_get_the_avx2_blas_kernels_wherever_the_cpu_has_them(monkeypatch) -> None:
    """escnn's disk cache holds bases solved with OpenBLAS: the queue's runs use one
    kernel family on every CPU with AVX2 (scripts/run_queue.py, ``blas_kernels``), keep
    a choice already made, and leave other CPUs alone. That the runs get them: the
    queue tests' stand-in trainer prints what it got."""
    monkeypatch.delenv("OPENBLAS_CORETYPE", raising=False)
    monkeypatch.setattr(rq, "cpu_flags", lambda: {"sse2", "avx", "avx2", "avx512f"})
    assert rq.blas_kernels() == {"OPENBLAS_CORETYPE": "Haswell"}
    monkeypatch.setattr(rq, "cpu_flags", lambda: {"sse2", "avx"})  # no AVX2: not forced
    assert rq.blas_kernels() == {}
    monkeypatch.setattr(rq, "cpu_flags", set)  # not x86
    assert rq.blas_kernels() == {}
    monkeypatch.setattr(rq, "cpu_flags", lambda: {"avx2"})
    monkeypatch.setenv("OPENBLAS_CORETYPE", "Zen")
    assert rq.blas_kernels() == {}
    assert rq.cpu_model().endswith("OPENBLAS_CORETYPE=Zen)")  # what sessions.csv records
