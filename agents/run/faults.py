"""Fault injection for the kill tests: the process kills itself (SIGKILL, as ``kill -9``)
the n-th time it reaches a named point, when ``GEOMDP_KILL_AT=<point>:<n>`` is set.

Points: ``seeding`` and ``acting`` (each action of a training episode, random or
planned), ``evaluation`` (each action of an evaluation episode), ``update``
(before each gradient update), ``checkpoint_write`` (after the agent file of a
checkpoint is written), ``checkpoint_swap`` (between the two renames of a save),
``checkpoint_cleanup`` (after the swap, before the previous checkpoint is removed).
Unset, as always outside tests, a point costs one environment lookup.
"""

from __future__ import annotations

import os
import signal

_reached: dict[str, int] = {}


def point(name: str) -> None:
    spec = os.environ.get("GEOMDP_KILL_AT")
    if not spec:
        return
    target, _, count = spec.partition(":")
    if target != name:
        return
    _reached[name] = _reached.get(name, 0) + 1
    if _reached[name] == int(count or 1):
        os.kill(os.getpid(), signal.SIGKILL)
