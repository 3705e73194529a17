"""Does a change alter a single number? Train the same short runs at two commits and compare
their logs.

    .venv/bin/python scripts/same_numbers.py 3ed546e HEAD
    .venv/bin/python scripts/same_numbers.py a910cab HEAD --steps 6000 \\
        --config 'paper_plain=env=reacher env.difficulty=hard agent=tdmpc_paper'

Each commit gets a clean ``git worktree`` (as the run queue's, ``../queue-<commit>``, reused
when it exists), and each config a 4000-step run from it (``train.seed_steps`` is the
config's: the default 2000 gives the burst of updates after the warm-up and ordinary
episodes after it), one at a time, one torch thread. ``eval.csv`` and ``train.csv`` must be
equal in every column but the wall-clock ones (``WALL_CLOCK_COLUMNS``): losses, Q, target
lag and returns, to the last digit. Exit status 0 when every config is, 1 otherwise.
Runs already finished under ``--out`` are reused, so a stopped comparison continues.

Bitwise equality holds on one machine only (RESULTS.md, "What reproduces where"): compare
commits on the machine that will run them.
"""

from __future__ import annotations

import argparse
import shlex
import subprocess
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from run_queue import (  # noqa: E402
    REPO,
    PlanError,
    logged_step,
    pinned_worktree,
    trainer_module,
)

from agents.run.checkpoint_state import saved_step  # noqa: E402
from agents.run.run_tables import added_columns, differing_tables  # noqa: E402

# One of each kind of agent the experiments run: plain and a 2D group on PointMass2D, a
# 3D group on PointMass3D, plain on Reacher hard (action repeat 4, its own schedules).
CONFIGS = {
    "pointmass2d_plain": "env=pointmass2d agent.group=none",
    "pointmass2d_D8": "env=pointmass2d agent.group=D8 agent.width_strategy=linear",
    "pointmass3d_icosahedral": "env=pointmass3d env.target_size=0.02 agent.group=icosahedral "
                               "agent.width_strategy=linear",
    "reacher_hard_plain": "env=reacher env.difficulty=hard agent.group=none",
}
# Small evaluations: the comparison needs every number, not good estimates of the return.
SHORT = ["train.eval_every=2000", "train.eval_episodes=3", "train.eval_noisy_episodes=1",
         "train.progress=false", "logger.tensorboard=false", "train.threads=1"]


def parse_configs(specs: list[str]) -> dict[str, str]:
    """``NAME=OVERRIDES`` (e.g. ``paper_plain=env=reacher agent=tdmpc_paper``) per config."""
    configs = {}
    for spec in specs:
        name, sep, overrides = spec.partition("=")
        words = shlex.split(overrides)
        if (not sep or not name.replace("_", "").isalnum() or not words
                or not all("=" in w or w.startswith("~") for w in words)):
            raise SystemExit(f"same_numbers: error: --config {spec!r} is not NAME=OVERRIDES "
                             "(e.g. 'paper_plain=env=reacher agent=tdmpc_paper')")
        configs[name] = overrides
    return configs


def train(python: str, worktree: Path, module: str, overrides: str, steps: int, run_dir: Path,
          seed: int) -> None:
    """One run of ``overrides`` from ``worktree``'s code (``-m`` from its root imports its
    packages, not the installed ones); reused if already finished."""
    if saved_step(run_dir) == steps == logged_step(run_dir):
        print(f"  {run_dir}: finished before, reused", flush=True)
        return
    argv = [python, "-m", module, *shlex.split(overrides), *SHORT, f"train.steps={steps}",
            f"seed={seed}", f"hydra.run.dir={run_dir}"]
    start = time.perf_counter()
    log = run_dir.parent / f"{run_dir.name}.log"
    run_dir.parent.mkdir(parents=True, exist_ok=True)
    with log.open("w") as out:
        done = subprocess.run(argv, cwd=worktree, stdout=out, stderr=subprocess.STDOUT)
    if done.returncode:
        raise SystemExit(f"same_numbers: error: {run_dir.name} failed at "
                         f"{worktree.name} (exit {done.returncode}); see {log}")
    print(f"  {run_dir}: {time.perf_counter() - start:.0f} s", flush=True)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("base", help="the commit before the change")
    parser.add_argument("head", help="the commit with it")
    parser.add_argument("--config", action="append", default=[], metavar="NAME=OVERRIDES",
                        help="a run to compare (repeatable; default: "
                             f"{', '.join(CONFIGS)})")
    parser.add_argument("--steps", type=int, default=4000, help="env steps per run")
    parser.add_argument("--seed", type=int, default=7)
    parser.add_argument("--out", type=Path, default=REPO.parent / "same-numbers",
                        help="where the runs go (default: ../same-numbers)")
    parser.add_argument("--python", default=sys.executable)
    args = parser.parse_args(argv)
    configs = parse_configs(args.config) if args.config else CONFIGS
    try:
        commits = [pinned_worktree(REPO, rev, None) for rev in (args.base, args.head)]
    except PlanError as err:
        raise SystemExit(f"same_numbers: error: {err}") from None
    runs = {}
    for commit, worktree in commits:
        module = trainer_module(REPO, commit)
        for name, overrides in configs.items():
            print(f"{commit[:10]} {name}", flush=True)
            runs[commit, name] = args.out / commit[:10] / name
            train(args.python, worktree, module, overrides, args.steps, runs[commit, name],
                  args.seed)
    (base, _), (head, _) = commits
    rows = [f"| config | {base[:10]} vs {head[:10]}, {args.steps} env steps, seed {args.seed} |",
            "|---|---|"]
    differing = {name: differing_tables(runs[base, name], runs[head, name]) for name in configs}
    for name, tables in differing.items():
        rows.append(f"| {name} | " + ("DIFFERENT: " + "; ".join(tables) if tables
                                       else "identical (eval.csv, train.csv)") + " |")
    print("\n".join(rows))
    for name in configs:
        for column in added_columns(runs[base, name], runs[head, name], (base[:10], head[:10])):
            print(f"{name}: not compared, {column}")
    return 1 if any(differing.values()) else 0


if __name__ == "__main__":
    sys.exit(main())
