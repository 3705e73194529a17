"""Statistics of runs' evaluation returns, as ``geomdp-plot`` reports them: means with
95% bootstrap confidence intervals (per evaluation step: ``curve``), steps to reach a
return, per-seed differences between groups paired by seed, paired and Welch t-tests.

Torch-free, as ``run_tables``.
"""

from __future__ import annotations

from collections.abc import Callable

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
