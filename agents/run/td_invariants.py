"""The invariants a working TD learner shows, read from a run's ``train.csv``.

A learning curve alone cannot tell "the agent has not found the reward yet" from
"the value learning is broken" (a frozen target network, a sign error, a Q that
drifts without reward). These checks can, and each is cheap enough to run on
every finished run (``geomdp-plot --runs``):

- the target network tracks the online one: ``target_lag`` (|online - target| /
  |online| over all parameters) stays above 0 in the second half of the run (a
  target equal to the online network is no target), and at the end of the run
  (median of the last ``END_EPISODES``) is below ``MAX_TARGET_LAG`` (a frozen or
  lost target drifts away and keeps drifting). Healthy runs spike where the
  online network moves fast (after initialisation, when the reward is first
  found), so the spikes are reported, not judged;
- Q has the sign of the rewards seen late in training (a positive-reward task
  must not learn negative values, nor a cost task positive ones);
- with (almost) no reward in the whole run, Q stays near 0 (the fixed point of
  the TD backup on zero rewards) rather than drifting.

Whether Q is right where the agent actually goes is checked at every evaluation
(``value_at_start``, columns of ``eval.csv``): Q(s₀, π(s₀)) at each noiseless evaluation
episode's first state against the discounted return the episode then earned
(``bootstrapped_returns``), and whether Q tells the episodes it solves from those it
fails. ``examples/inspect_run.py`` prints the same along whole episodes played from a
checkpoint.
"""

from __future__ import annotations

import csv
import math
import statistics
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

# Healthy runs in results/ (53 on 2026-12-02): at most 0.063 at the end (spikes up to 0.23 in
# the second half, when the reward is first found). PointMass2D plain, 10k steps, with the
# target update disabled (SoftUpdate.step a no-op): 0.05-0.07 until the first rewards, then
# 0.27-0.33 from 7k steps on, growing; 0.31 at the end.
MAX_TARGET_LAG = 0.2
END_EPISODES = 10
REWARD_SEEN = 1.0  # |mean episode reward| from which rewards count as seen (per episode)
MAX_Q_WITHOUT_REWARD = 1.0  # |Q| after a run with no reward; healthy runs show ~0.02
LAST_EPISODES = 50  # late training: the last episodes of the second half
MIN_LATE_ROWS = 3  # fewer logged rows in the second half judge no lag (a run too short)


@dataclass(frozen=True)
class TDInvariants:
    """Late-training value statistics of one run, and the checks they fail (none: healthy)."""

    q_half: float  # q_mean at the logged row nearest half of the run's env steps
    q_end: float  # q_mean at the last logged row
    target_lag_low: float  # over late training (the last LAST_EPISODES of the second half)
    target_lag_high: float
    target_lag_end: float  # median of the last END_EPISODES logged rows
    late_reward: float  # mean training episode reward over late training
    run_reward: float  # total |training episode reward| of the run
    failures: tuple[str, ...]
    notes: tuple[str, ...] = ()  # checks left unjudged, and why


def bootstrapped_returns(rewards: Sequence[float], discount: float,
                         final_value: float = 0.0) -> list[float]:
    """G_t = r_t + discount * G_{t+1} with G_T = ``final_value``, for t < T = len(rewards).

    What Q(s_t, pi(s_t)) estimates along a played episode: a learner that bootstraps
    through time limits (TD-MPC) values the state after the last step at its own Q
    (``final_value``), not at 0; pass 0 after a true termination.
    """
    returns, running = [], float(final_value)
    for reward in reversed(rewards):
        running = float(reward) + discount * running
        returns.append(running)
    return returns[::-1]


def value_at_start(values: Sequence[float], returns: Sequence[float]) -> dict[str, float]:
    """An evaluation's check of Q where the agent goes: over its episodes, the mean of
    Q(s₀, π(s₀)) (``q_start``), the mean discounted return earned from s₀
    (``discounted_return``), and their correlation across the episodes
    (``q_return_corr``: does Q tell the episodes the agent solves from those it fails?
    NaN with fewer than two episodes, or when either does not vary)."""
    if len(values) != len(returns) or not values:
        raise ValueError(f"one value per episode: {len(values)} values, {len(returns)} returns")
    try:
        corr = statistics.correlation(values, returns)
    except statistics.StatisticsError:  # fewer than two points, or a constant
        corr = math.nan
    return {"q_start": statistics.fmean(values), "discounted_return": statistics.fmean(returns),
            "q_return_corr": corr}


def _floats(rows: list[dict[str, str]], column: str) -> list[float]:
    return [float(r[column]) for r in rows if r.get(column) not in (None, "")]


def td_invariants(train_csv: Path) -> TDInvariants:
    """The invariants of the run whose training log is ``train_csv``; a ValueError names
    the file when it has no logged update to judge."""
    with Path(train_csv).open(newline="") as f:
        rows = list(csv.DictReader(f))
    updated = [r for r in rows if r.get("q_mean") not in (None, "")]
    if not updated:
        raise ValueError(f"{train_csv}: no row with an update (q_mean), so no TD invariant to check")
    half = float(updated[-1]["env_step"]) / 2
    q_half = float(min(updated, key=lambda r: abs(float(r["env_step"]) - half))["q_mean"])
    q_end = float(updated[-1]["q_mean"])
    late = [r for r in updated if float(r["env_step"]) > half][-LAST_EPISODES:]
    lags = _floats(late, "target_lag")
    lag_low, lag_high, lag_end = ((min(lags), max(lags), statistics.median(lags[-END_EPISODES:]))
                                  if lags else (math.nan,) * 3)
    late_rewards = _floats(late, "episode_reward")
    rewards = _floats(rows, "episode_reward")
    late_reward = sum(late_rewards) / max(len(late_rewards), 1)
    run_reward = sum(abs(r) for r in rewards)
    failures, notes = [], []
    if not (math.isfinite(q_half) and math.isfinite(q_end)):
        failures.append("Q is not finite")
    if not all(math.isfinite(r) for r in rewards):
        failures.append("an episode reward is not finite")
    if len(lags) < MIN_LATE_ROWS:
        notes.append(f"target_lag not judged ({len(lags)} logged in the second half, "
                     f"fewer than {MIN_LATE_ROWS})")
    elif not all(math.isfinite(x) for x in lags):
        failures.append("target_lag is not finite")
    elif lag_low <= 0:
        failures.append("target_lag is 0: the target network is the online network")
    elif lag_end > MAX_TARGET_LAG:
        failures.append(f"target_lag ends at {lag_end:.3f} > {MAX_TARGET_LAG}: "
                        "the target network does not track the online one")
    if abs(late_reward) >= REWARD_SEEN and q_end * late_reward <= 0:
        failures.append(f"Q ends at {q_end:.3g}, not of the sign of the rewards seen "
                        f"({late_reward:.3g} per episode)")
    if run_reward < REWARD_SEEN and abs(q_end) > MAX_Q_WITHOUT_REWARD:
        failures.append(f"Q ends at {q_end:.3g} with no reward seen (the TD fixed point is 0)")
    return TDInvariants(q_half, q_end, lag_low, lag_high, lag_end, late_reward, run_reward,
                        tuple(failures), tuple(notes))
