"""Running an agent on a task: a run's options and their checks (``config``), its envs
(``envs``), its directory (``run_dir``), the training loop and the factory of its parts
(``trainer``), checkpoints, run logs, videos, and fault injection for the reliability
tests."""
