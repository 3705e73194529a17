"""Statistics of runs' evaluation returns, as ``geomdp-plot`` reports them: means with
95% bootstrap confidence intervals (per evaluation step: ``curve``), steps to reach a
return, per-seed differences between groups paired by seed, paired and Welch t-tests, and the
spread of an agent's returns across the values of one option (``spread_over``).

Torch-free, as ``run_tables``.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from scipy import stats

from agents.run.results import Run, seed_order


def bootstrap_ci(samples: tuple[np.ndarray, ...],
                 statistic: Callable[..., np.ndarray]) -> tuple[float, float]:
    """95% percentile bootstrap CI of ``statistic`` (each sample resampled on its own;
    fixed seed, so that tables are reproducible)."""
    ci = stats.bootstrap(samples, statistic, confidence_level=0.95, n_resamples=2000,
                         method="percentile", random_state=0).confidence_interval
    return float(ci.low), float(ci.high)


def mean_ci(values: np.ndarray) -> tuple[float, float, float]:
    """Mean and 95% bootstrap confidence interval (the mean itself when n < 2)."""
    mean = float(np.mean(values))
    if len(values) < 2 or np.all(values == values[0]):
        return mean, mean, mean
    return mean, *bootstrap_ci((values,), np.mean)


def curve(runs: list[Run]) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """(steps, mean, ci low, ci high, seeds) over the union of evaluation steps."""
    steps = np.unique(np.concatenate([r.steps for r in runs]))
    out = []
    for s in steps:
        values = np.array([r.returns[r.steps == s][0] for r in runs if s in r.steps])
        out.append((*mean_ci(values), len(values)))
    mean, low, high, n = (np.array(c) for c in zip(*out))
    return steps, mean, low, high, n


def steps_to_threshold(run: Run, threshold: float) -> int | None:
    reached = run.steps[run.returns >= threshold]
    return int(reached[0]) if len(reached) else None


def seed_pairs(runs: list[Run], baseline: list[Run]) -> list[tuple[object, Run, Run]]:
    """(seed, run, baseline run) for every seed both have, by seed."""
    base = {r.options.get("seed"): r for r in baseline}
    return sorted(((r.options.get("seed"), r, base[r.options.get("seed")]) for r in runs
                   if r.options.get("seed") in base), key=lambda t: seed_order(t[0]))


def differences(pairs: list[tuple[object, Run, Run]]) -> tuple[np.ndarray, np.ndarray]:
    """Per seed: the differences of the mean return over all evaluations, and of the final return."""
    return (np.array([a.returns.mean() - b.returns.mean() for _, a, b in pairs]),
            np.array([a.returns[-1] - b.returns[-1] for _, a, b in pairs]))


def p_value(p: float) -> str:
    return f"{p:.3f}" if p >= 0.001 else f"{p:.1e}"  # never a bare 0.000


def paired_p(d: np.ndarray) -> str:
    """Paired t-test of per-seed differences against 0 (– where it is undefined)."""
    if len(d) < 2 or np.all(d == d[0]):
        return "–"
    return p_value(stats.ttest_1samp(d, 0.0).pvalue)


def mean_ci_of_difference(a: np.ndarray, b: np.ndarray) -> tuple[float, float, float]:
    """mean(a) − mean(b) and its 95% bootstrap CI, a and b resampled independently."""
    mean = float(np.mean(a) - np.mean(b))
    if np.all(a == a[0]) and np.all(b == b[0]):
        return mean, mean, mean
    return mean, *bootstrap_ci((a, b), lambda x, y, axis: np.mean(x, axis) - np.mean(y, axis))


def welch_p(a: np.ndarray, b: np.ndarray) -> str:
    if np.var(a) == 0 and np.var(b) == 0:
        return "–"
    return p_value(stats.ttest_ind(a, b, equal_var=False).pvalue)


def level_order(level: object) -> tuple[int, float, str]:
    """Sort key for an option's values: numbers in numeric order (2000 before 20000),
    then anything else as text."""
    try:
        return 0, float(str(level)), ""
    except ValueError:
        return 1, 0.0, str(level)


@dataclass
class Spread:
    """How much one agent's returns move across the values (levels) of one option, seed by
    seed: e.g. the warm-up length ``train.seed_steps``. ``area`` and ``final`` are (seeds ×
    levels): the mean return over evaluations and the final return of each run. Only seeds
    with a run at every level count, so that every range spans the same levels."""

    levels: list[str]
    seeds: list[object]
    area: np.ndarray
    final: np.ndarray
    runs_per_level: dict[str, int]  # every run's, whether its seed has all levels or not

    def ranges(self) -> tuple[np.ndarray, np.ndarray]:
        """Per seed: max − min across levels of the mean return over evaluations, and of
        the final return."""
        return np.ptp(self.area, axis=1), np.ptp(self.final, axis=1)


def spread_over(runs: list[Run], option: str, levels: list[str] | None = None) -> Spread:
    """``runs`` (one agent, several seeds and values of ``option``) as a ``Spread`` over
    ``levels`` (default: the values these runs have; pass every agent's, so that all ranges
    span the same values)."""
    by_seed: dict[object, dict[str, Run]] = {}
    for run in runs:
        by_seed.setdefault(run.options.get("seed"), {})[str(run.options.get(option))] = run
    if levels is None:
        levels = sorted({level for runs_of_seed in by_seed.values() for level in runs_of_seed},
                        key=level_order)
    seeds = sorted((s for s, runs_of_seed in by_seed.items() if set(levels) <= set(runs_of_seed)),
                   key=seed_order)
    area = np.array([[by_seed[s][level].returns.mean() for level in levels] for s in seeds])
    final = np.array([[by_seed[s][level].returns[-1] for level in levels] for s in seeds])
    runs_per_level = {level: sum(level in runs_of_seed for runs_of_seed in by_seed.values())
                      for level in levels}
    return Spread(levels, seeds, area.reshape(len(seeds), len(levels)),
                  final.reshape(len(seeds), len(levels)), runs_per_level)
