"""The ``geomdp-train`` entry point, light on purpose: it handles SIGTERM and SIGINT
before importing torch, escnn and Hydra (seconds of imports), so that a signal at any
moment ends the process with the interrupted status 130, never the default action's 143.
``agents.cli.train`` then takes over the signals for the run's safe stop."""

from __future__ import annotations

import os
import signal
import sys


def exit_interrupted(signum: int, frame: object) -> None:
    """Before the run starts (or after it has stopped): end with the interrupted status."""
    sys.stdout.flush()
    sys.stderr.flush()
    os._exit(130)


def train() -> None:
    for s in (signal.SIGTERM, signal.SIGINT):
        signal.signal(s, exit_interrupted)
    from agents.cli.train import main

    main()


if __name__ == "__main__":
    train()
