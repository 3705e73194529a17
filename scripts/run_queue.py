"""A run queue that loses no compute to interruptions.

Runs a list of ``geomdp-train`` jobs from one pinned commit (a ``git worktree`` of
it), at most ``--parallel`` at a time with one torch thread each, before a deadline:

- a run starts only if its expected wall time fits before the deadline (expected from
  the finished runs of its group -- the folder above its seed folder -- or from
  ``--estimate``), except runs matching ``--carry-over``: longer than any session, they
  start whenever ``--carry-over-minutes`` are left and advance from checkpoint to
  checkpoint, one session after another;
- at the deadline, runs still going get SIGTERM: they stop at a safe point with their
  last checkpoint, and the next call of the same command resumes them on a machine
  that still has the checkpoints (a run that must start over says so in its
  ``stdout.log``). A carried-over run's directory, checkpoint included, is committed
  when it stops, so the next session resumes it even on a fresh machine (whose
  worktree is new); its checkpoint leaves the tree when the run finishes;
- each finished run's logs (never its checkpoints) are copied into the checkout's
  ``results/`` and committed at once, after checking that every session of the run
  used the pinned commit with no local changes (``sessions.csv``);
- trainers run in sessions of their own, so a queue killed outright (SIGKILL, e.g. to
  give it another deadline) leaves them training; the next queue on the same plan
  adopts them: they hold their slots, and are collected or stopped like its own.

A plan has one run per line, ``<results dir> <env steps> <override>...``; ``#`` starts
a comment. The same plan given again skips finished runs and resumes the others::

    python scripts/run_queue.py scripts/plans/headline.txt --commit 9623621 \\
        --deadline 20:45 --estimate 'results/reacher_hard_cpu/*=45'
    python scripts/run_queue.py scripts/plans/baseline_fidelity_paper.txt \\
        --commit 1234abc --deadline 19:00 --parallel 1 --carry-over 'results/fidelity/*'

Several plans make one queue, in the order given (a slot's schedule in one command)::

    python scripts/run_queue.py scripts/plans/warmup.txt scripts/plans/n_balls.txt \\
        --commit a910cab --deadline 19:00 --parallel 1 \\
        --estimate 'results/warmup/*=40' --estimate 'results/n_balls/*=90'

``--dry-run`` prints what would start now, and touches nothing (not even the worktree).
"""
from __future__ import annotations

import argparse
import csv
import datetime as dt
import fnmatch
import os
import re
import shlex
import shutil
import signal
import subprocess
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path

from agents.run.checkpoint_state import LOCK_FILE, WRITE_PROBE, checkpoint_paths, saved_step
from agents.run.machine import cpu_flags, cpu_model
from agents.run.run_tables import wall_minutes

REPO = Path(__file__).resolve().parent.parent
PID_FILE = "run_queue.pid"  # the trainer's process id while a queue runs it
CHECKPOINT, *CHECKPOINT_SWAP = (path.name for path in checkpoint_paths(Path()))
LOG_FILES_SKIPPED = (CHECKPOINT, *CHECKPOINT_SWAP, WRITE_PROBE, PID_FILE, LOCK_FILE)
STARTUP_MINUTES = 1.0  # building the agent and the first evaluation's set-up, per start


class PlanError(ValueError):
    """A plan or command line the queue cannot run."""


def blas_kernels() -> dict[str, str]:
    """OpenBLAS's kernels for the runs: the AVX2 ones (``Haswell``) on every CPU that
    has AVX2, unless OPENBLAS_CORETYPE is set already; nothing elsewhere (forcing
    them on a CPU without AVX2 would stop the run at its first illegal instruction).

    escnn solves for some bases numerically with scipy's SVD (the dihedral groups'
    Clebsch-Gordan coefficients: a system whose solutions are not unique) and caches
    them on disk, and OpenBLAS (numpy's and scipy's) picks its kernels by CPU. On an
    AVX-512 machine it solved for another D8 basis of the same space than the AVX2
    machines every run before 2026-12-07 was made on (Haswell and Zen kernels gave
    those machines' basis), and a carried D8 run could not resume: its checkpoint held
    coefficients only (later commits store the bases too: docs/checkpoints.md). With
    one kernel family everywhere, what the runs put in the cache is what they were
    trained with."""
    if os.environ.get("OPENBLAS_CORETYPE") or "avx2" not in cpu_flags():
        return {}
    return {"OPENBLAS_CORETYPE": "Haswell"}


@dataclass
class Run:
    """One line of a plan: where its logs go, how long it trains, its options."""

    dest: str                      # path relative to the checkout, e.g. results/x/D8/seed1
    steps: int
    overrides: list[str]
    work: Path = field(default=Path())  # where it runs: the same path inside the worktree

    @property
    def group(self) -> str:
        return str(Path(self.dest).parent)

    def argv(self, python: str, module: str) -> list[str]:
        return [python, "-m", module, *self.overrides, f"train.steps={self.steps}",
                "train.progress=false", f"hydra.run.dir={self.work}"]


def read_plan(text: str) -> list[Run]:
    runs, seen = [], set()
    for number, line in enumerate(text.splitlines(), 1):
        words = shlex.split(line, comments=True)
        if not words:
            continue
        if len(words) < 2 or not words[1].isdigit():
            raise PlanError(f"plan line {number}: expected '<results dir> <env steps> "
                            f"<override>...', got {line.strip()!r}")
        dest = os.path.normpath(words[0])
        if dest.startswith("..") or os.path.isabs(dest):
            raise PlanError(f"plan line {number}: {words[0]!r} must be a path inside the checkout")
        if dest in seen:
            raise PlanError(f"plan line {number}: {dest} is listed twice")
        seen.add(dest)
        runs.append(Run(dest, int(words[1]), words[2:]))
    return runs


def read_plans(plans: list[tuple[str, str]]) -> list[Run]:
    """Several plans (name, text) as one queue, in the order given: a slot's whole
    schedule is one command, and a run of a later plan fills time no run of an earlier
    one fits in."""
    runs: list[Run] = []
    source: dict[str, str] = {}
    for name, text in plans:
        try:
            plan_runs = read_plan(text)
        except PlanError as err:
            raise PlanError(f"{name}: {err}") from None
        for run in plan_runs:
            if run.dest in source:
                raise PlanError(f"{name}: {run.dest} is also in {source[run.dest]}")
            source[run.dest] = name
        runs += plan_runs
    return runs


# --- what the file system says about a run ---------------------------------------------
def last_row(path: Path) -> dict[str, str] | None:
    try:
        with path.open() as f:
            rows = list(csv.DictReader(f))
    except OSError:
        return None
    return rows[-1] if rows else None


def logged_step(run_dir: Path) -> int:
    """The last evaluated env step in a run directory (-1: none)."""
    row = last_row(run_dir / "eval.csv")
    return int(row["env_step"]) if row else -1


def running_pid(run_dir: Path) -> int | None:
    """The process a queue started on this run directory, if it is still alive (and, where
    ``/proc`` tells, still trains this directory: a process id can be reused)."""
    try:
        pid = int((run_dir / PID_FILE).read_text())
        os.kill(pid, 0)
    except (OSError, ValueError):
        return None
    cmdline = Path(f"/proc/{pid}/cmdline")
    try:
        if f"hydra.run.dir={run_dir}" not in cmdline.read_bytes().decode(errors="replace").split("\0"):
            return None
    except OSError:
        if cmdline.parent.parent.exists():  # /proc exists but not this pid: it has ended
            return None
    return pid


class AdoptedProcess:
    """A trainer that an earlier queue started and that outlived it (that queue was
    killed, e.g. to change its deadline): watched through its process id, as it is not
    this queue's child. Its exit status is unknown, so it is inferred: finished (0) if
    its logs reach its steps, stopped at its checkpoint (130) after this queue's SIGTERM,
    failed (1) otherwise."""

    def __init__(self, pid: int, run: Run) -> None:
        self.pid, self.run, self.terminated = pid, run, False

    def poll(self) -> int | None:
        if running_pid(self.run.work) == self.pid:
            return None
        if logged_step(self.run.work) >= self.run.steps:
            return 0
        return 130 if self.terminated else 1

    def send_signal(self, sig: int) -> None:
        self.terminated |= sig == signal.SIGTERM
        os.kill(self.pid, sig)

    def kill(self) -> None:
        self.send_signal(signal.SIGKILL)

    def wait(self) -> int:
        while (status := self.poll()) is None:
            time.sleep(0.2)
        return status


def finished(run: Run, root: Path) -> bool:
    return logged_step(root / run.dest) >= run.steps


# --- expected wall time -----------------------------------------------------------------
def parse_estimates(items: list[str]) -> list[tuple[str, float]]:
    out = []
    for item in items:
        pattern, _, minutes = item.rpartition("=")
        try:
            out.append((pattern, float(minutes)))
        except ValueError:
            raise PlanError(f"--estimate {item!r}: expected PATTERN=MINUTES, e.g. "
                            "'results/reacher_hard_cpu/*=45'") from None
    return out


def expected_minutes(run: Run, runs: list[Run], results: Path,
                     estimates: list[tuple[str, float]], default: float) -> float:
    """Minutes a fresh start of ``run`` takes: the mean over its group's finished runs of
    the same length, else the first matching ``--estimate``, else ``default``."""
    measured = [m for other in runs
                if other.group == run.group and other.steps == run.steps and finished(other, results)
                and (m := wall_minutes(results / other.dest)) is not None]
    if measured:
        return sum(measured) / len(measured) + STARTUP_MINUTES
    for pattern, minutes in estimates:
        if fnmatch.fnmatch(run.dest, pattern) or fnmatch.fnmatch(run.group, pattern):
            return minutes
    return default


def remaining_minutes(run: Run, full_minutes: float) -> float:
    done = saved_step(run.work) or 0
    return STARTUP_MINUTES + (full_minutes - STARTUP_MINUTES) * max(0.0, 1 - done / run.steps)


# --- provenance and results ----------------------------------------------------------------
def session_problems(run_dir: Path, commit: str) -> list[str]:
    """Why the run's sessions do not all come from the pinned, clean commit (empty: they do)."""
    try:
        with (run_dir / "sessions.csv").open() as f:
            rows = list(csv.DictReader(f))
    except OSError:
        return ["no sessions.csv"]
    problems = [f"session at env step {r['env_step']} ran commit {r['git_commit'][:10]}"
                for r in rows if not r["git_commit"].startswith(commit)]
    problems += [f"session at env step {r['env_step']} ran with local changes"
                 for r in rows if r["git_dirty"] != "False"]
    return problems or ([] if rows else ["sessions.csv is empty"])


def copy_logs(src: Path, dest: Path, with_checkpoint: bool = False) -> None:
    """The run's logs, without its checkpoints (``with_checkpoint``: with its last complete
    one, for a carried run), replace ``dest``: copied beside it first, so that an
    interrupted copy never leaves a ``dest`` that looks finished."""
    skipped = [n for n in LOG_FILES_SKIPPED if not (with_checkpoint and n == CHECKPOINT)]
    partial = dest.with_name(dest.name + ".copying")
    shutil.rmtree(partial, ignore_errors=True)
    shutil.copytree(src, partial, ignore=shutil.ignore_patterns(*skipped))
    if dest.exists():
        shutil.rmtree(dest)
    partial.rename(dest)


def git(repo: Path, *args: str) -> subprocess.CompletedProcess[str]:
    """git in ``repo``, retried while another git process holds the index lock."""
    for _ in range(30):
        done = subprocess.run(["git", "-C", str(repo), *args], capture_output=True, text=True)
        if done.returncode == 0 or "index.lock" not in done.stderr:
            return done
        time.sleep(2)
    return done


def commit_results(repo: Path, dest: str, message: str, force: bool = False) -> str:
    """Commit exactly ``dest`` (other staged or unstaged work in the checkout stays as it
    is); ``force`` adds ignored files too (a carried run's checkpoint)."""
    add = ("add", "-f", "--", dest) if force else ("add", "--", dest)
    for args in (add, ("commit", "-q", "-m", message, "--only", "--", dest)):
        done = git(repo, *args)
        if done.returncode:
            return f"git {args[0]} failed: {done.stderr.strip() or done.stdout.strip()}"
    return "committed " + git(repo, "rev-parse", "--short", "HEAD").stdout.strip()


def pinned_worktree(repo: Path, commit: str, path: Path | None,
                    create: bool = True) -> tuple[str, Path]:
    """The full commit id and a clean worktree of it (made if missing, unless not
    ``create``: then a missing worktree's path is returned as it is)."""
    done = git(repo, "rev-parse", "--verify", f"{commit}^{{commit}}")
    if done.returncode:
        raise PlanError(f"--commit {commit}: not a commit of {repo}")
    full = done.stdout.strip()
    path = path or repo.parent / f"queue-{full[:7]}"
    if not path.exists() and not create:
        return full, path
    if not path.exists():
        done = git(repo, "worktree", "add", "--detach", str(path), full)
        if done.returncode:
            raise PlanError(f"cannot make a worktree at {path}: {done.stderr.strip()}")
    head = git(path, "rev-parse", "HEAD").stdout.strip()
    if head != full:
        raise PlanError(f"{path} is at {head[:10]}, not the pinned {full[:10]}: give another "
                        "--worktree, or remove it with 'git worktree remove'")
    if git(path, "status", "--porcelain", "--untracked-files=no").stdout.strip():
        raise PlanError(f"{path} has local changes: runs from it would not be from {full[:10]}")
    return full, path


def trainer_module(repo: Path, commit: str) -> str:
    """The module of ``geomdp-train`` in the pinned commit (it moved between commits)."""
    text = git(repo, "show", f"{commit}:pyproject.toml").stdout
    match = re.search(r'^geomdp-train\s*=\s*"([\w.]+):\w+"', text, re.M)
    if match is None:
        raise PlanError(f"pyproject.toml of {commit[:10]} names no geomdp-train entry point")
    return match.group(1)


def parse_deadline(text: str, now: dt.datetime) -> dt.datetime:
    """``HH:MM`` (today, or tomorrow if already past), ``+90m``/``+2h``, or ISO 8601."""
    try:
        if text.startswith("+"):
            value, unit = float(text[1:-1]), text[-1]
            return now + dt.timedelta(minutes=value * {"m": 1, "h": 60}[unit])
        if len(text) <= 5 and ":" in text:
            hour, minute = map(int, text.split(":"))
            at = now.replace(hour=hour, minute=minute, second=0, microsecond=0)
            return at if at > now else at + dt.timedelta(days=1)
        return dt.datetime.fromisoformat(text)
    except (ValueError, KeyError):
        raise PlanError(f"--deadline {text!r}: expected HH:MM, +90m, +2h or an ISO time") from None


def _raise_interrupt(signum: int, frame: object) -> None:
    raise KeyboardInterrupt


# --- the queue ------------------------------------------------------------------------------
def say(text: str) -> None:
    print(f"{dt.datetime.now():%H:%M:%S} {text}", flush=True)


class Queue:
    def __init__(self, runs: list[Run], repo: Path, commit: str, worktree: Path,
                 deadline: dt.datetime, parallel: int = 2, estimates: list[tuple[str, float]] = (),
                 default_minutes: float = 60.0, python: str = sys.executable,
                 module: str | None = None, commit_results: bool = True,
                 poll_seconds: float = 10.0, stop_grace_seconds: float = 120.0,
                 carry_over: list[str] = (), carry_over_minutes: float = 20.0) -> None:
        self.runs, self.repo, self.commit, self.worktree = runs, repo, commit, worktree
        self.deadline, self.parallel = deadline, parallel
        self.estimates, self.default_minutes = list(estimates), default_minutes
        self.module = module or trainer_module(repo, commit)
        self.python, self.commit_results = python, commit_results
        self.poll_seconds, self.stop_grace_seconds = poll_seconds, stop_grace_seconds
        self.carry_over, self.carry_over_minutes = list(carry_over), carry_over_minutes
        for run in runs:
            run.work = worktree / run.dest
        self.running: dict[str, tuple[Run, subprocess.Popen | AdoptedProcess, dt.datetime]] = {}
        self.failed: set[str] = set()

    def minutes_left(self, now: dt.datetime) -> float:
        return (self.deadline - now).total_seconds() / 60

    def remaining(self, run: Run) -> float:
        full = expected_minutes(run, self.runs, self.repo, self.estimates, self.default_minutes)
        return remaining_minutes(run, full)

    def pending(self) -> list[Run]:
        return [r for r in self.runs if r.dest not in self.running and r.dest not in self.failed
                and not finished(r, self.repo)]

    def carried_over(self, run: Run) -> bool:
        """Whether ``run`` may start without fitting before the deadline (``--carry-over``)."""
        return any(fnmatch.fnmatch(run.dest, p) or fnmatch.fnmatch(run.group, p)
                   for p in self.carry_over)

    def fits(self, run: Run, now: dt.datetime) -> bool:
        """Whether starting ``run`` now is worth it: it finishes before the deadline or, carried
        over, has ``carry_over_minutes`` to advance before the deadline's SIGTERM."""
        if self.carried_over(run):
            return self.minutes_left(now) >= self.carry_over_minutes
        return self.remaining(run) <= self.minutes_left(now)

    def next_to_start(self, now: dt.datetime) -> Run | None:
        """The first pending run, in plan order, that fits (``fits``)."""
        for run in self.pending():
            if logged_step(run.work) >= run.steps:
                continue  # finished here, waiting to be collected
            if self.fits(run, now):
                return run
        return None

    def collect_finished_work(self) -> None:
        """What a queue stopped half-way left: runs finished in the worktree whose logs
        are not yet in results/ are collected, and collected logs not yet committed are
        committed."""
        for run in self.runs:
            if not finished(run, self.repo) and logged_step(run.work) >= run.steps:
                self.collect(run)
            elif (self.commit_results and finished(run, self.repo)
                  and git(self.repo, "status", "--porcelain", "--", run.dest).stdout.strip()):
                outcome = commit_results(self.repo, run.dest, f"Run queue: {run.dest} finished "
                                         f"({run.steps} env steps, code {self.commit[:10]})")
                say(f"committed the logs of {run.dest} a stopped queue had left: {outcome}")

    def adopt_running(self) -> None:
        """Runs of the plan that an earlier queue started and that are still training
        count as running here: watched, collected, stopped at the deadline."""
        for run in self.pending():
            if (pid := running_pid(run.work)) is not None:
                self.running[run.dest] = (run, AdoptedProcess(pid, run), dt.datetime.now())
                say(f"adopted {run.dest}: process {pid}, started by an earlier queue, still "
                    "training")

    def start(self, run: Run) -> None:
        run.work.mkdir(parents=True, exist_ok=True)
        if (pid := running_pid(run.work)) is not None:
            self.failed.add(run.dest)
            say(f"NOT STARTED {run.dest}: process {pid} (another queue?) is training it")
            return
        committed = saved_step(self.repo / run.dest)
        if committed and committed > (saved_step(run.work) or 0):
            copy_logs(self.repo / run.dest, run.work, with_checkpoint=True)
            say(f"{run.dest}: took the checkpoint at env step {committed} committed by an "
                "earlier session")
        step, logged = saved_step(run.work), logged_step(run.work)
        if step:
            how = f"resuming from its checkpoint at env step {step}"
        elif logged >= 0 or logged_step(self.repo / run.dest) >= 0:
            seen = max(logged, logged_step(self.repo / run.dest))
            how = (f"STARTING OVER: no checkpoint on this machine (an earlier attempt had "
                   f"evaluated up to env step {seen})")
        else:
            how = "starting"
        kernels = blas_kernels()
        with (run.work / "stdout.log").open("a") as out:
            out.write(f"run_queue {dt.datetime.now():%Y-%m-%d %H:%M:%S}: {how}, "
                      f"commit {self.commit[:10]}, cpu {cpu_model()}"
                      + "".join(f", {k}={v}" for k, v in kernels.items()) + "\n")
            out.flush()
            # A session of its own: Ctrl-C on the queue reaches the trainers only through
            # stop_all's one SIGTERM (a second signal would stop them without their
            # safe point).
            proc = subprocess.Popen(run.argv(self.python, self.module), cwd=self.worktree,
                                    stdout=out, stderr=subprocess.STDOUT, start_new_session=True,
                                    env={**os.environ, "OMP_NUM_THREADS": "1",
                                         "MKL_NUM_THREADS": "1", **kernels})
        (run.work / PID_FILE).write_text(str(proc.pid))
        self.running[run.dest] = (run, proc, dt.datetime.now())
        say(f"{how}: {run.dest} (expected {self.remaining(run):.0f} min, "
            f"{self.minutes_left(dt.datetime.now()):.0f} min to the deadline)")

    def collect(self, run: Run) -> None:
        problems = session_problems(run.work, self.commit)
        if problems:
            self.failed.add(run.dest)
            say(f"NOT COLLECTED {run.dest}: {'; '.join(problems)}")
            return
        copy_logs(run.work, self.repo / run.dest)
        row = last_row(self.repo / run.dest / "eval.csv") or {}
        minutes = wall_minutes(self.repo / run.dest) or 0.0
        message = (f"Run queue: {run.dest} finished ({run.steps} env steps, code "
                   f"{self.commit[:10]}, final eval return "
                   f"{float(row.get('episode_reward', 'nan')):.1f}, {minutes:.0f} min)")
        outcome = commit_results(self.repo, run.dest, message) if self.commit_results else "copied"
        say(f"finished {run.dest}: {outcome}")

    def carry(self, run: Run) -> None:
        """Commit a stopped carried-over run with its checkpoint, so that the next session
        resumes it on any machine (``start`` takes it when the worktree has none as far)."""
        step = saved_step(run.work)
        if step is None or not self.commit_results:
            return
        if problems := session_problems(run.work, self.commit):
            self.failed.add(run.dest)
            say(f"NOT CARRIED {run.dest}: {'; '.join(problems)}")
            return
        copy_logs(run.work, self.repo / run.dest, with_checkpoint=True)
        size = sum(p.stat().st_size for p in (self.repo / run.dest / CHECKPOINT).rglob("*")
                   if p.is_file())
        message = (f"Run queue: {run.dest} carried at env step {step} (code {self.commit[:10]}; "
                   f"checkpoint {size / 2**20:.1f} MiB committed so the next session resumes "
                   "it on any machine)")
        say(f"carried {run.dest}: {commit_results(self.repo, run.dest, message, force=True)}")

    def reap(self) -> None:
        for dest, (run, proc, _) in list(self.running.items()):
            status = proc.poll()
            if status is None:
                continue
            del self.running[dest]
            (run.work / PID_FILE).unlink(missing_ok=True)
            if status == 0 and logged_step(run.work) >= run.steps:
                self.collect(run)
            elif status in (130, -signal.SIGTERM):
                say(f"stopped {dest} at its checkpoint (env step {saved_step(run.work)})")
                if self.carried_over(run):
                    self.carry(run)
            else:
                self.failed.add(dest)
                say(f"FAILED {dest} (exit {status}): see {run.work / 'stdout.log'}")

    def stop_all(self) -> None:
        for run, proc, _ in self.running.values():
            say(f"deadline: SIGTERM to {run.dest}")
            proc.send_signal(signal.SIGTERM)
        end = time.monotonic() + self.stop_grace_seconds
        while self.running and time.monotonic() < end:
            time.sleep(0.2)
            self.reap()
        for run, proc, _ in self.running.values():
            say(f"{run.dest} did not stop in {self.stop_grace_seconds:.0f} s: SIGKILL")
            proc.kill()
            proc.wait()
        self.reap()

    def report(self) -> None:
        parts = []
        for run, _, _ in self.running.values():
            row = last_row(run.work / "train.csv") or {}
            parts.append(f"{run.dest} {int(row.get('env_step', 0)) // 1000}k/{run.steps // 1000}k")
        say(f"running: {', '.join(parts) or 'none'}; pending {len(self.pending())}; "
            f"failed {len(self.failed)}")

    def run(self) -> int:
        """Start, watch and collect runs until none is left that fits, or the deadline.
        SIGTERM/SIGINT to the queue stop its runs at their checkpoints first."""
        previous = signal.signal(signal.SIGTERM, _raise_interrupt)
        try:
            return self._run()
        finally:
            signal.signal(signal.SIGTERM, previous)

    def _run(self) -> int:
        self.collect_finished_work()
        self.adopt_running()
        last_report = time.monotonic()
        try:
            while True:
                self.reap()
                now = dt.datetime.now()
                if now >= self.deadline:
                    self.stop_all()
                    break
                while len(self.running) < self.parallel and (run := self.next_to_start(now)):
                    self.start(run)
                if not self.running:
                    break
                if time.monotonic() - last_report > 600:
                    self.report()
                    last_report = time.monotonic()
                time.sleep(self.poll_seconds)
        except KeyboardInterrupt:
            self.stop_all()
        left = self.pending()
        say(f"queue done: {len(left)} run(s) left" + (f" ({', '.join(r.dest for r in left)})"
                                                      if left else "")
            + (f"; failed: {', '.join(sorted(self.failed))}" if self.failed else ""))
        return 1 if self.failed else 0


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("plans", nargs="+", metavar="plan",
                        help="plan files, run in the order given ('-': stdin)")
    parser.add_argument("--commit", required=True, help="the commit every run is trained with")
    parser.add_argument("--deadline", required=True, help="HH:MM, +90m, +2h or an ISO time")
    parser.add_argument("--worktree", type=Path, help="default: ../queue-<commit> beside the checkout")
    parser.add_argument("--parallel", type=int, default=2)
    parser.add_argument("--estimate", action="append", default=[], metavar="PATTERN=MINUTES",
                        help="minutes for runs whose path or group matches, until one has finished")
    parser.add_argument("--default-minutes", type=float, default=60.0)
    parser.add_argument("--carry-over", action="append", default=[], metavar="PATTERN",
                        help="runs whose path or group matches start even if they cannot finish "
                             "before the deadline (stopped at it, resumed by the next call)")
    parser.add_argument("--carry-over-minutes", type=float, default=20.0,
                        help="a carried-over run starts only with this many minutes left")
    parser.add_argument("--python", default=sys.executable)
    parser.add_argument("--module", help=argparse.SUPPRESS)  # default: the commit's geomdp-train
    parser.add_argument("--no-commit", action="store_true", help="copy finished logs, do not commit")
    parser.add_argument("--poll-seconds", type=float, default=10.0, help=argparse.SUPPRESS)
    parser.add_argument("--dry-run", action="store_true")
    args = parser.parse_args(argv)
    try:
        runs = read_plans([(name, sys.stdin.read() if name == "-" else Path(name).read_text())
                           for name in args.plans])
        commit, worktree = pinned_worktree(REPO, args.commit, args.worktree, create=not args.dry_run)
        queue = Queue(runs, REPO, commit, worktree, parse_deadline(args.deadline, dt.datetime.now()),
                      args.parallel, parse_estimates(args.estimate), args.default_minutes,
                      args.python, args.module, not args.no_commit, args.poll_seconds,
                      carry_over=args.carry_over, carry_over_minutes=args.carry_over_minutes)
    except (OSError, PlanError) as err:
        print(f"run_queue: error: {err}", file=sys.stderr)
        return 2
    # the hours make an HH:MM read as tomorrow (it had passed) plain to see in the log
    say(f"queue: {len(runs)} runs, commit {commit[:10]} in {worktree}, deadline "
        f"{queue.deadline:%Y-%m-%d %H:%M} (in {queue.minutes_left(dt.datetime.now()) / 60:.1f} h), "
        f"{queue.parallel} at a time")
    if args.dry_run:
        for run in queue.pending():
            fits = queue.fits(run, dt.datetime.now())
            word = ("carry" if queue.carried_over(run) else "fits") if fits else "late"
            print(f"{queue.remaining(run):6.0f} min {word}  {run.dest}  "
                  f"{shlex.join(run.argv(args.python, queue.module))}")
        return 0
    return queue.run()


if __name__ == "__main__":
    sys.exit(main())
