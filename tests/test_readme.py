"""The README's Python example runs as written."""

import re
import subprocess
import sys
from pathlib import Path

README = Path(__file__).resolve().parent.parent / "README.md"


def test_readme_python_api_example_runs(tmp_path):
    section = README.read_text().split("## Python API", 1)[1].split("\n## ", 1)[0]
    (code,) = re.findall(r"```python\n(.*?)```", section, re.S)
    assert 10 <= len(code.strip().splitlines()) <= 20, "the example stays a short example"
    out = subprocess.run([sys.executable, "-c", code], cwd=tmp_path, capture_output=True,
                         text=True, timeout=300)
    assert out.returncode == 0, out.stderr[-2000:]
    assert "'loss_model':" in out.stdout


def test_readme_bring_your_own_task_example_runs(tmp_path):
    section = README.read_text().split("## Bring your own task", 1)[1].split("\n## ", 1)[0]
    (code,) = re.findall(r"```python\n(.*?)```", section, re.S)
    out = subprocess.run([sys.executable, "-c", code], cwd=tmp_path, capture_output=True,
                         text=True, timeout=300)
    assert out.returncode == 0, out.stderr[-2000:]
    assert out.stdout.startswith("PASS O(2): 64 trials") and "'loss_model':" in out.stdout
    shipped = (README.parent / "geomdp_envs/declarations/reacher_v5.yaml").read_text()
    for name in ("angle", "[0, 2]", "[8, 9]"):
        assert name in shipped  # the YAML says what the example says
