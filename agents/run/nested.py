"""Nested option dicts (resolved Hydra configs): flattened to ``{"a.b.c": value}``, compared."""

from __future__ import annotations

from typing import Any


def flatten(d: dict[str, Any], prefix: str = "") -> dict[str, Any]:
    """``{"a": {"b": 1}}`` -> ``{"a.b": 1}``: for comparing and grouping runs by option."""
    out: dict[str, Any] = {}
    for k, v in d.items():
        if isinstance(v, dict):
            out.update(flatten(v, f"{prefix}{k}."))
        else:
            out[f"{prefix}{k}"] = v
    return out


# Options added after runs were already made, with the value that reproduces those runs:
# filled into an older run's options before comparing or grouping, so that it resumes
# and plots beside newer runs. Add a key here whenever an option is added.
ADDED_LATER = {"agent.augment": "none", "env.symmetry": None,
               # TD-MPC's own choices (issue 37, step 4), off for every earlier run
               "agent.networks.encoder_layers": None, "agent.networks.encoder_dim": None,
               "agent.networks.layer_norm": "every", "agent.networks.init": "default",
               "agent.loss.straight_through": False,
               "agent.replay.max_priority_within_buffer": False,
               "agent.replay.priority_eps": 1e-8,
               "train.eval_noise": "shared"}


def with_added_later(flat: dict[str, Any]) -> dict[str, Any]:
    """Flattened options with every ``ADDED_LATER`` key an older run lacks filled in
    (none recorded: nothing to fill)."""
    return {**ADDED_LATER, **flat} if flat else flat


def differences(a: Any, b: Any, prefix: str = "") -> list[tuple[str, Any, Any]]:
    """``(dotted key, value in a, value in b)`` wherever two option dicts differ, sorted
    by key (a key missing on one side compares as ``None``)."""
    if isinstance(a, dict) and isinstance(b, dict):
        return [d for k in sorted(set(a) | set(b))
                for d in differences(a.get(k), b.get(k), f"{prefix}{k}.")]
    return [] if a == b else [(prefix.rstrip("."), a, b)]
