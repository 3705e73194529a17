"""Running an agent on a task: the training loop, checkpoints, run logs, videos and
fault injection for the reliability tests."""
