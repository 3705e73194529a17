import os
import shutil
import sys
from pathlib import Path
from types import ModuleType

os.environ.setdefault("MUJOCO_GL", "egl")
# One thread per test process: the tensors here are small, and beside training runs
# (the queue keeps both cores busy) two OpenMP threads per op wait on each other, which
# made single planner calls 200x slower (29 s instead of 0.15 s, measured 2026-12-03).
os.environ.setdefault("OMP_NUM_THREADS", "1")

import pytest  # noqa: E402

import geomdp_envs  # noqa: E402,F401  (registers the tasks)
from geomdp_envs.mujoco_env import load_triton_before_mesa  # noqa: E402

# The fidelity tests import dm_control.suite, which loads Mesa: triton first.
load_triton_before_mesa()


def pytest_configure(config: pytest.Config) -> None:
    import torch

    torch.set_num_threads(int(os.environ["OMP_NUM_THREADS"]))


ROOT = Path(__file__).resolve().parents[1]


def load_script(path: str) -> ModuleType:
    """A script of the repository (``scripts/…``, ``examples/…``: not in a package) as a
    module, registered under its file name so that it can be pickled and imported again."""
    import importlib.util

    spec = importlib.util.spec_from_file_location(Path(path).stem, ROOT / path)
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module
    spec.loader.exec_module(module)
    return module


def run_main(module: ModuleType, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture,
             *args: object) -> tuple[str, str | None]:
    """A script's ``main()`` with ``args`` as its command line, in this process (a
    subprocess would spend seconds importing torch and escnn again): what it printed, and
    the message it stopped with (``SystemExit``, as a user sees it), or None."""
    monkeypatch.setattr(sys, "argv", [module.__name__, *map(str, args)])
    try:
        module.main()
    except SystemExit as stop:
        return capsys.readouterr().out, None if stop.code in (None, 0) else str(stop.code)
    return capsys.readouterr().out, None


@pytest.fixture(scope="session")
def finished_run(tmp_path_factory: pytest.TempPathFactory):
    """``finished_run(cfg)``: the directory of a finished ``geomdp-train`` run of the composed
    config ``cfg``, trained once per test session and shared by every test and pytest-xdist
    worker that asks for the same config (the key is the whole config, so two requests share
    a run only when the runs would be the same). Read it only; ``finished_run(cfg, copy_to=d)``
    copies it into ``d`` for a test that changes it."""
    import fcntl
    import hashlib

    from omegaconf import DictConfig, OmegaConf

    from agents.cli.train import run

    root = tmp_path_factory.getbasetemp()  # pytest-xdist: one per worker, in one session folder
    cache = (root.parent if "PYTEST_XDIST_WORKER" in os.environ else root) / "finished-runs"
    cache.mkdir(exist_ok=True)

    def get(cfg: DictConfig, copy_to: Path | None = None) -> Path:
        key = hashlib.sha256(OmegaConf.to_yaml(cfg, resolve=True).encode()).hexdigest()[:16]
        path, done = cache / key, cache / f"{key}.done"
        with open(cache / f"{key}.lock", "w") as lock:
            fcntl.flock(lock, fcntl.LOCK_EX)  # another worker making it: wait, then read
            if not done.exists():
                shutil.rmtree(path, ignore_errors=True)
                assert run(cfg, path) == 0
                done.touch()
        return path if copy_to is None else shutil.copytree(path, copy_to, dirs_exist_ok=True)

    return get


# A tiny agent evaluated once per evaluation, quietly: the Hydra overrides a training
# test adds to its task and budget (a run of a few thousand env steps takes seconds).
TINY_AGENT = ["train.eval_episodes=1", "train.eval_noisy_episodes=0", "train.progress=false",
              "agent.networks.hidden_dim=16", "agent.networks.latent_dim=8",
              "agent.planner.num_samples=16", "agent.planner.num_elites=4",
              "agent.planner.num_pi_trajs=2", "agent.planner.iterations=1", "agent.horizon=3",
              "agent.batch_size=8", "agent.replay.capacity=5000", "logger.tensorboard=false"]

# Every task configuration the suite offers, as gymnasium.make arguments.
TASK_CONFIGS = [
    pytest.param(("GeoMDP/PointMass2D-v0", {}), id="pointmass2d"),
    pytest.param(("GeoMDP/PointMass3D-v0", {}), id="pointmass3d"),
    pytest.param(("GeoMDP/PointMass3D-v0", {"n_balls": 3, "target_size": 0.02}), id="pointmass3d-3balls"),
    pytest.param(("GeoMDP/PointMass3D-v0", {"walls": True}), id="pointmass3d-walls"),
    pytest.param(("GeoMDP/Reacher-v0", {"difficulty": "easy", "frame": "local"}), id="reacher-easy-local"),
    pytest.param(("GeoMDP/Reacher-v0", {"difficulty": "hard", "frame": "global"}), id="reacher-hard-global"),
]


@pytest.fixture
def randomise_heads():
    """Give the reward and Q heads non-zero output layers (they start at zero, as in
    TD-MPC), so that tests of their equivariance cannot pass on zeros."""
    import torch

    def randomise(networks, seed=0):
        gen = torch.Generator().manual_seed(seed)
        with torch.no_grad():
            for head in (networks.reward, *networks.qs):
                for p in head.net[-1].parameters():
                    p.copy_(0.3 * torch.randn(p.shape, generator=gen, dtype=p.dtype))
        return networks

    return randomise


# The quick subset (pytest -m "not slow") keeps every test, each with the small groups;
# the sweeps over the large or continuous groups (each case seconds to a minute on CPU)
# run in the full suite only, with the tests marked slow in their files (training runs,
# subprocesses, the wheel).
LARGE_GROUPS = ("icosahedral", "octahedral", "C16", "D16", "SO2", "O2", "SO3", "O3")


def pytest_collection_modifyitems(items: list[pytest.Item]) -> None:
    for item in items:
        params = getattr(item, "callspec", None)
        if params is not None and any(isinstance(v, str) and v in LARGE_GROUPS
                                      for v in params.params.values()):
            item.add_marker(pytest.mark.slow)
