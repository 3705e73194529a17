"""The README stays short, its commands are CI's, its links resolve and its example runs."""

import re
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
README = ROOT / "README.md"


def test_readme_is_at_most_250_lines():
    assert len(README.read_text().splitlines()) <= 250, "a newcomer reads the README in five minutes"


def test_readme_test_commands_are_cis_and_the_fast_subset():
    text = README.read_text()
    ci = (ROOT / ".ci/run").read_text().strip().splitlines()[-1]
    assert ci == "bash scripts/bootstrap.sh && .venv/bin/python -m pytest -q -n auto"
    assert ci in text and "bash scripts/bootstrap.sh && .venv/bin/geomdp-train" in text
    assert '.venv/bin/python -m pytest -q -m "not slow"' in text


def test_readme_code_comes_before_the_results():
    headings = re.findall(r"^## (.+)$", README.read_text(), re.M)
    assert headings.index("Python API") < headings.index("What it shows so far")
    results = README.read_text().split("## What it shows so far", 1)[1].split("\n## ", 1)[0]
    assert len([line for line in results.splitlines() if line.strip()]) <= 6 and "(RESULTS.md)" in results


def test_readme_links_resolve():
    for target in re.findall(r"\]\(([^)#\s]+)(?:#[^)]*)?\)", README.read_text()):
        if "://" not in target:
            assert (ROOT / target).exists(), target


@pytest.mark.slow
def test_readme_python_api_example_runs(tmp_path):
    section = README.read_text().split("## Python API", 1)[1].split("\n## ", 1)[0]
    (code,) = re.findall(r"```python\n(.*?)```", section, re.S)
    assert 10 <= len(code.strip().splitlines()) <= 20, "the example stays a short example"
    out = subprocess.run([sys.executable, "-c", code], cwd=tmp_path, capture_output=True,
                         text=True, timeout=600)
    assert out.returncode == 0, out.stderr[-2000:]
    assert out.stdout.startswith("PASS D4: 64 trials") and "'loss_model':" in out.stdout
