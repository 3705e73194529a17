"""Timing shared by the benchmark scripts (run as ``python benchmarks/<script>.py``)."""

from __future__ import annotations

import time
from collections.abc import Callable


def best_time(fn: Callable[[], object], min_time: float, rounds: int) -> float:
    """Seconds per call: the best of ``rounds`` runs of as many calls as fill
    ``min_time / rounds`` (after one warm-up call)."""
    fn()
    calls, start = 1, time.perf_counter()
    while time.perf_counter() - start < min_time / rounds:
        fn()
        calls += 1
    best = float("inf")
    for _ in range(rounds):
        start = time.perf_counter()
        for _ in range(calls):
            fn()
        best = min(best, (time.perf_counter() - start) / calls)
    return best
