"""An install without the source tree: the wheel holds every package and the configs,
and its commands work from a copy installed outside the checkout."""

import os
import shutil
import subprocess
import sys
import zipfile
from pathlib import Path

import pytest

pytestmark = pytest.mark.slow  # builds and installs the wheel

ROOT = Path(__file__).resolve().parent.parent


@pytest.fixture(scope="module")
def wheel(tmp_path_factory) -> Path:
    """Built from a copy of the sources (a build in the checkout would reuse ``build/``,
    where a module deleted since an earlier build would still ship)."""
    source, out = tmp_path_factory.mktemp("source"), tmp_path_factory.mktemp("wheel")
    for name in ("pyproject.toml", "README.md"):
        shutil.copy(ROOT / name, source / name)
    for name in ("agents", "geomdp_envs", "configs"):
        shutil.copytree(ROOT / name, source / name, ignore=shutil.ignore_patterns("__pycache__"))
    subprocess.run([sys.executable, "-m", "pip", "wheel", str(source), "--no-deps",
                    "--no-build-isolation", "-q", "-w", str(out)], check=True, capture_output=True,
                   timeout=300)
    (path,) = out.glob("geomdp-*.whl")
    return path


def test_wheel_holds_every_package_and_config(wheel):
    names = set(zipfile.ZipFile(wheel).namelist())
    sources = {str(p.relative_to(ROOT)) for package in ("agents", "geomdp_envs")
               for p in (ROOT / package).rglob("*.py")}
    assert {n for n in names if n.endswith(".py")} == sources  # every module, and no other
    configs = sorted((ROOT / "configs").rglob("*.yaml"))
    assert configs
    for config in configs:
        assert f"agents/configs/{config.relative_to(ROOT / 'configs')}" in names, config
    declarations = sorted((ROOT / "geomdp_envs" / "declarations").glob("*.yaml"))
    assert declarations
    for declaration in declarations:
        assert str(declaration.relative_to(ROOT)) in names, declaration


def test_installed_commands_work_outside_the_checkout(wheel, tmp_path):
    target = tmp_path / "site"
    subprocess.run([sys.executable, "-m", "pip", "install", "-q", "--no-deps", "--target",
                    str(target), str(wheel)], check=True, capture_output=True, timeout=300)
    env = {**os.environ, "PYTHONPATH": str(target)}
    # one process: where the code comes from, and every command's entry point imports
    where = subprocess.run([sys.executable, "-c", "import agents.cli.train as t; print(t.__file__); "
                            "print(t.CONFIG_DIR); from agents.cli.plot import main; "
                            "from agents.cli.theory import main; from geomdp_envs.demo import main; "
                            "from geomdp_envs import load_declaration; load_declaration('reacher_v5'); "
                            "from geomdp_envs.check_cli import main"],
                           cwd=tmp_path, env=env, capture_output=True, text=True, check=True)
    module, config_dir = where.stdout.split()
    assert module.startswith(str(target)) and config_dir == str(target / "agents" / "configs")
    for command in ("geomdp-train", "geomdp-plot", "geomdp-theory", "geomdp-demo", "geomdp-check"):
        assert (target / "bin" / command).exists(), command
    job = subprocess.run([str(target / "bin" / "geomdp-train"), "env=reacher", "agent.group=D8",
                          "--cfg", "job"], cwd=tmp_path, env=env, capture_output=True, text=True,
                         timeout=300)
    assert job.returncode == 0, job.stderr
    assert "id: GeoMDP/Reacher-v0" in job.stdout and "group: D8" in job.stdout
