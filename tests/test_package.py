"""The ``agents`` package's surface: its exports resolve, and reading runs stays torch-free."""

import subprocess
import sys
from pathlib import Path

import pytest

import agents

ROOT = Path(__file__).resolve().parents[1]


def test_every_export_resolves_to_its_module():
    assert sorted(agents.__all__) == sorted(agents._EXPORTS)
    for name in agents.__all__:
        value = getattr(agents, name)
        assert value.__module__ == agents._EXPORTS[name], name
    try:
        agents.no_such_name  # noqa: B018
    except AttributeError as err:
        assert "no_such_name" in str(err)
    else:
        raise AssertionError("an unknown name must raise AttributeError")


@pytest.mark.slow
def test_reading_runs_does_not_import_the_networks_libraries():
    """geomdp-plot and the run queue read CSVs: importing them must not load torch or escnn
    (seconds of start-up on every call)."""
    code = ("import sys; sys.path.insert(0, 'scripts'); import agents.cli.plot, run_queue; "
            "print(sorted(m for m in ('torch', 'escnn', 'torchrl') if m in sys.modules))")
    out = subprocess.run([sys.executable, "-c", code], cwd=ROOT, capture_output=True, text=True,
                         check=True)
    assert out.stdout.strip() == "[]", out.stdout + out.stderr
