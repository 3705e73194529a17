"""The training progress bar: it moves with every agent step, says when the run is
evaluating (episode i of n), and estimates the time left from both parts of a run's
cost, training steps and evaluations, since an evaluation can take minutes during which
no environment step is counted."""

from __future__ import annotations

import math
import time
from typing import TYPE_CHECKING

from tqdm import tqdm

if TYPE_CHECKING:
    from agents.run.config import TrainOptions


class Progress:
    """A ``tqdm`` bar over environment steps with an ETA that counts evaluations."""

    def __init__(self, train: TrainOptions, initial: int, last_eval_step: int | None) -> None:
        self.train, self.steps = train, train.steps
        self.env_step, self.last_eval_step = initial, last_eval_step  # a disabled bar counts nothing
        self.episode_steps = 1  # until the first episode ends
        self.bar = tqdm(total=train.steps, initial=initial, unit="step", disable=not train.progress,
                        dynamic_ncols=True, desc="env steps",
                        bar_format="{desc}: {percentage:3.0f}%|{bar}| {n_fmt}/{total_fmt} "
                                   "[{elapsed}{postfix}]")
        self.train_seconds, self.train_steps = 0.0, 0  # measured this session
        self.eval_seconds: float | None = None         # the last evaluation's duration
        self._clock = time.perf_counter()
        self._eval_start: float | None = None
        self.last_return: float | None = None
        self.rounded_note = False
        self.evaluations_left = train.evaluations_left(initial, last_eval_step)

    # training --------------------------------------------------------------------------
    def episode_started(self) -> None:
        self._clock = time.perf_counter()

    def advance(self, env_steps: int) -> None:
        """One agent step of a training episode (``env_steps`` with the action repeat)."""
        now = time.perf_counter()
        self.train_seconds += now - self._clock
        self.train_steps += env_steps
        self.env_step += env_steps
        self._clock = now
        self.bar.update(env_steps)
        self._show()

    def updating(self, updates: int) -> None:
        """The episode's gradient updates follow (TD-MPC updates after each episode)."""
        self.bar.set_description(f"env steps, {updates} updates")

    def episode_done(self, episode_steps: int) -> None:
        """A training episode and its updates are done. A budget that is not a whole number
        of episodes (they are never cut) is stated once, and the bar's total follows it."""
        self.train_seconds += time.perf_counter() - self._clock  # the updates
        self.episode_steps = episode_steps
        self._count_evaluations()
        if not self.rounded_note and self.steps % episode_steps:
            final = math.ceil(self.steps / episode_steps) * episode_steps
            self.bar.total = max(self.bar.total, final)
            self.bar.write(f"train.steps={self.steps} is not a whole number of episodes "
                           f"({episode_steps} env steps each): the run trains to {final}")
            self.rounded_note = True
        self.bar.set_description("env steps")
        self._show()

    # evaluation ------------------------------------------------------------------------
    def evaluating(self, episode: int, episodes: int) -> None:
        if self._eval_start is None:
            self._eval_start = time.perf_counter()
        self.bar.set_description(f"evaluating (episode {episode + 1}/{episodes})")
        self.bar.refresh()

    def evaluated(self, env_step: int, mean_return: float) -> None:
        if self._eval_start is not None:
            self.eval_seconds = time.perf_counter() - self._eval_start
        self._eval_start, self.last_eval_step, self.last_return = None, env_step, mean_return
        self._count_evaluations()
        self.bar.set_description("env steps")
        self._clock = time.perf_counter()
        self._show()

    # the estimate ----------------------------------------------------------------------
    def _count_evaluations(self) -> None:
        """The trainer's own schedule (``TrainOptions.evaluations_left``), counted again when
        an episode or an evaluation ends: one count per episode, not per step."""
        self.evaluations_left = self.train.evaluations_left(self.env_step, self.last_eval_step,
                                                            self.episode_steps)

    def seconds_left(self, env_step: int) -> float | None:
        if not self.train_steps:
            return None
        remaining = max(0, max(self.bar.total, self.steps) - env_step)
        seconds = remaining * self.train_seconds / self.train_steps
        return seconds + self.evaluations_left * (self.eval_seconds or 0.0)

    def _show(self) -> None:
        parts = []
        if self.last_return is not None:
            parts.append(f"eval return {self.last_return:.1f}")
        left = self.seconds_left(self.env_step)
        if left is not None:
            parts.append(f"ETA {tqdm.format_interval(left)}"
                         + ("" if self.eval_seconds is not None else " + evaluations"))
        self.bar.set_postfix_str(", ".join(parts), refresh=True)

    def close(self) -> None:
        self.bar.close()
