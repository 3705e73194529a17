"""``geomdp-train``: train TD-MPC (plain or equivariant) on a task, as a Hydra app.

    geomdp-train env=pointmass3d env.n_balls=3 agent.group=icosahedral seed=1 \\
        train.steps=100000 hydra.run.dir=runs/x

Everything a run writes goes to its run directory: ``config.yaml`` (resolved),
``.hydra/``, ``eval.csv``, ``train.csv``, ``sessions.csv`` (the code commit and
library versions of each start and resume), TorchRL logger output and
``checkpoint/``. Starting the same command again continues from the last checkpoint
(replay buffer included). This module is the command line only: options are checked
by ``agents.run.config``, the run directory by ``agents.run.run_dir`` and the loop is
``agents.run.trainer``. Exit status: 0 done, 1 the run directory cannot hold the run,
2 bad input, 130 interrupted (SIGTERM/SIGINT: the run stops at a safe point, its last
checkpoint kept; a second signal stops at once).
"""

from __future__ import annotations

import signal
import sys
from collections.abc import Callable
from pathlib import Path

import hydra
from hydra.core.hydra_config import HydraConfig
from hydra.types import RunMode
from omegaconf import DictConfig, OmegaConf

from agents.cli.launch import exit_interrupted
from agents.options import OptionError
from agents.run import checkpoint
from agents.run.checkpoint_state import describe, saved_state
from agents.run.config import RunOptions, check_task, record_declaration
from agents.run.presets import CONFIG_DIR, compose_config
from agents.run.run_dir import (
    RunDirError,
    RunDirLock,
    changed_options,
    check_same_options,
    check_writable,
    make_run_dir,
    remove_if_only_hydra_files,
    write_records,
)
from agents.run.run_log import RunLog
from agents.run.run_tables import RunLogError
from agents.run.trainer import StopRequest, Trainer, build_parts


# --- signals -------------------------------------------------------------------------
def _stop_handler(stop: StopRequest) -> Callable[[int, object], None]:
    def handler(signum: int, frame: object) -> None:
        if stop.signal is not None:  # the second signal: stop at once
            raise KeyboardInterrupt
        stop.signal = signum

    return handler


# --- one run ---------------------------------------------------------------------------
def run(cfg: DictConfig, run_dir: Path, hydra_records: tuple[DictConfig, DictConfig, list[str]]
        | None = None) -> int:
    """Check the options, then train in ``run_dir``; returns the exit status.
    ``hydra_records`` (composed config, Hydra's config, overrides) are written to
    ``.hydra/`` once the run is accepted."""
    try:
        options = RunOptions.from_config(record_declaration(OmegaConf.to_container(cfg,
                                                                                   resolve=True)))
        task = check_task(options)
    except OptionError as err:
        remove_if_only_hydra_files(run_dir)
        print(f"geomdp-train: error: {err}", file=sys.stderr)
        return 2
    stop = StopRequest()
    previous = {s: signal.signal(s, _stop_handler(stop)) for s in (signal.SIGTERM, signal.SIGINT)}
    try:
        make_run_dir(run_dir)
        with RunDirLock(run_dir):  # first: nothing below reads what another process writes
            check_writable(run_dir)
            check_same_options(run_dir, options.resolved)
            changed = changed_options(run_dir, options.resolved)
            write_records(run_dir, options.resolved, *(hydra_records or ()))
            log = RunLog(run_dir, options.logger.tensorboard)
            try:
                trainer = Trainer(options, run_dir, build_parts(options, task), log, stop,
                                  {"symmetry_check": task.symmetry_check,
                                   "changed_options": changed})
                trainer.restore()
                trainer.train()
            finally:
                log.close()
    except (OptionError, checkpoint.CheckpointError, RunLogError) as err:
        print(f"geomdp-train: error: {err}", file=sys.stderr)
        return 1 if isinstance(err, (RunDirError, checkpoint.CheckpointWriteError)) else 2
    except KeyboardInterrupt:
        for s in previous:  # stopping: a further signal must not interrupt the report
            signal.signal(s, signal.SIG_IGN)
        saved = saved_state(run_dir)
        where = (f"the last checkpoint is at {describe(saved)}: run the same command "
                 "to continue" if saved and saved["env_step"] else
                 "no checkpoint yet: the same command starts the run over")
        print(f"\ninterrupted; {where}", file=sys.stderr)
        return 130
    finally:
        for s, handler in previous.items():
            signal.signal(s, handler)
    print(f"done: {run_dir} (last eval return {trainer.state['last_eval_reward']:.1f})")
    return 0


@hydra.main(version_base="1.3", config_path=str(CONFIG_DIR), config_name="train")
def hydra_main(cfg: DictConfig) -> None:
    hydra_cfg = HydraConfig.get()
    status = run(cfg, Path(hydra_cfg.runtime.output_dir),
                 (cfg, hydra_cfg, list(hydra_cfg.overrides.task)))
    if status == 130 and hydra_cfg.mode == RunMode.RUN:  # not a multirun's worker
        # Interrupted, with everything saved and the logs closed: ignore further signals
        # (a supervisor repeating SIGTERM) and exit normally. Python's shutdown keeps an
        # ignored signal ignored (a handler would be reset to the default action, ending
        # the process with 143), and a normal exit releases the semaphores that the
        # libraries made (os._exit left them to multiprocessing's resource tracker, which
        # warned of leaks after the one-line message).
        for s in (signal.SIGTERM, signal.SIGINT):
            signal.signal(s, signal.SIG_IGN)
    if status:
        sys.exit(status)


def rewrite_env_shorthand(argv: list[str]) -> list[str]:
    """``env=Pendulum-v1`` (a Gymnasium id, not a config) means ``env=gym env.id=Pendulum-v1``."""
    out = []
    for arg in argv:
        if arg.startswith("env=") and not (CONFIG_DIR / "env" / f"{arg[4:]}.yaml").exists():
            out += ["env=gym", f"env.id={arg[4:]}"]
        else:
            out.append(arg)
    return out


def command_line_error(overrides: list[str]) -> str | None:
    """What Hydra would refuse in a many-line report (an unknown key, an unknown config
    group option, an unparsable override), said in one line; then the run directory,
    which Hydra creates before ``run`` is reached, is made here so that one that cannot
    be made is one line too. None: Hydra may take over. A multirun, or Hydra's own
    flags, are left to Hydra."""
    if any(arg.startswith("-") for arg in overrides):
        return None
    try:
        make_run_dir(Path(compose_config(overrides, hydra=True).hydra.run.dir))
    except OptionError as err:
        return str(err)
    return None


def main() -> None:
    for s in (signal.SIGTERM, signal.SIGINT):
        signal.signal(s, exit_interrupted)
    sys.argv = [sys.argv[0], *rewrite_env_shorthand(sys.argv[1:])]
    error = command_line_error(sys.argv[1:])
    if error is not None:
        print(f"geomdp-train: error: {error}", file=sys.stderr)
        sys.exit(2)
    hydra_main()


if __name__ == "__main__":
    main()
