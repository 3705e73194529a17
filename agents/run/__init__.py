"""Running an agent on a task: a run's options and their checks (``config``), its envs
(``envs``), its directory (``run_dir``), the training loop and the factory of its parts
(``trainer``), its progress bar (``progress``), checkpoints, run logs, videos, and fault
injection for the reliability tests; for ``geomdp-plot``, runs found and grouped by option
(``results``) and their statistics (``statistics``)."""
