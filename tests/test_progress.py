"""The progress bar's ETA counts the evaluations the trainer will make, from the trainer's
own schedule (``TrainOptions.evaluation_due``), on budgets that are and are not whole
numbers of episodes, from the start and on resume."""

import pytest

from agents.run.config import TrainOptions
from agents.run.progress import Progress


@pytest.mark.parametrize("steps, every, episode, start", [
    (30000, 5000, 1000, 0), (30000, 5000, 400, 0), (30500, 5000, 1000, 0),
    (2600, 1300, 100, 0), (100000, 10000, 1000, 24000), (7, 3, 2, 0), (5000, 5000, 1000, 5000),
])
def test_evaluations_left_is_what_the_trainer_loop_makes(steps, every, episode, start):
    train = TrainOptions(steps=steps, eval_every=every, progress=False)
    resumed = start > 0
    progress = Progress(train, start, start if resumed else None)
    made, last, step = [], start if resumed else None, start
    expected = []  # (evaluations made so far, the bar's count of those left)
    if last is None:  # the trainer evaluates first when no evaluation was made
        progress.evaluating(0, 1)
        made.append(step)
        last = step
        progress.evaluated(step, 0.0)
    expected.append((len(made), progress.evaluations_left))
    while step < steps:  # Trainer._train: an episode, then an evaluation when due
        progress.episode_started()
        progress.advance(episode)
        step += episode
        progress.episode_done(episode)
        expected.append((len(made), progress.evaluations_left))
        if train.evaluation_due(step, last):
            progress.evaluating(0, 1)
            made.append(step)
            last = step
            progress.evaluated(step, 0.0)
            expected.append((len(made), progress.evaluations_left))
    progress.close()
    total = len(made)
    assert (made[-1] >= steps and (resumed or made[0] == 0)) if made else start >= steps
    # once an episode's length is known, made + left is the run's total at every point
    assert all(done + left == total for done, left in expected[1:]), expected
    assert expected[-1] == (total, 0)
    if not resumed:  # before the first episode: counted with 1-step episodes
        assert train.evaluations_left(0, None, episode) == total
