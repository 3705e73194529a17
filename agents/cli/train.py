"""``geomdp-train``: train TD-MPC (plain or equivariant) on a task, as a Hydra app.

    geomdp-train env=pointmass3d env.n_balls=3 agent.group=icosahedral seed=1 \\
        train.steps=100000 hydra.run.dir=runs/x

Everything a run writes goes to its run directory: ``config.yaml`` (resolved),
``eval.csv``, ``train.csv``, ``sessions.csv`` (the code commit and library versions
of each start and resume), TorchRL logger output and ``checkpoint/``.
Starting the same command again continues from the last checkpoint (replay
buffer included). The loop follows TD-MPC: collect a whole episode with the
planner (random actions for the first ``train.seed_steps``), then make one
update per agent step collected, then evaluate when due and checkpoint.
"""

from __future__ import annotations

import hashlib
import importlib.util
import os
import shutil
import signal
import sys
import time
import warnings
from pathlib import Path
from typing import Any

import gymnasium
import hydra
import numpy as np
import torch
from hydra.core.hydra_config import HydraConfig
from omegaconf import DictConfig, OmegaConf
from tensordict import TensorDictBase
from tensordict.nn import TensorDictModule
from torchrl.envs import GymWrapper, TransformedEnv
from torchrl.envs.transforms import FrameSkipTransform
from tqdm import tqdm

import geomdp_envs  # noqa: F401  (registers the tasks)
from agents.run import checkpoint, faults
from agents.run.nested import differences, flatten
from agents.run.run_log import RunLog, RunLogError
from agents.run.video import frames_per_second, write_video
from agents.tdmpc.agent import TDMPCAgent, TDMPCConfig
from agents.tdmpc.replay import make_replay_buffer, sample_slices, update_priorities
from geomdp_envs.mujoco_env import load_triton_before_mesa
from geomdp_envs.symmetry import Symmetry

TASK_ENVS = ("pointmass2d", "pointmass3d", "reacher")
ENV_META_KEYS = ("name", "id", "action_repeat")
# Options that may change when a run is continued (budgets and display), and the rest must not.
RESUMABLE_KEYS = ("train.steps", "train.eval_every", "train.eval_episodes",
                  "train.eval_noisy_episodes", "train.progress", "train.checkpoint_every",
                  "train.video", "train.threads", "device", "logger.tensorboard")
REPLAY_KEYS = ("observation", "action", "episode", ("next", "observation"),
               ("next", "reward"), ("next", "terminated"))


class ConfigError(ValueError):
    """A bad option, reported in one line before any work starts."""


# --- configuration -----------------------------------------------------------
def env_kwargs(env_cfg: DictConfig) -> dict[str, Any]:
    return {k: v for k, v in OmegaConf.to_container(env_cfg).items() if k not in ENV_META_KEYS}


def make_gym_env(env_cfg: DictConfig, render_mode: str | None = None) -> gymnasium.Env:
    """The Gymnasium env of a config; its errors (bad kwargs) become ConfigErrors."""
    if env_cfg.id not in gymnasium.registry:
        raise ConfigError(f"unknown environment {env_cfg.id!r}: use env=<one of "
                          f"{', '.join(TASK_ENVS)}> or env=<a registered Gymnasium id>")
    kwargs = env_kwargs(env_cfg) | ({"render_mode": render_mode} if render_mode else {})
    try:
        env = gymnasium.make(env_cfg.id, **kwargs)
    except (ValueError, TypeError) as err:
        raise ConfigError(str(err)) from None
    if not isinstance(env.action_space, gymnasium.spaces.Box):
        raise ConfigError(f"{env_cfg.id} has a {type(env.action_space).__name__} action space; "
                          "TD-MPC needs a Box")
    if not (np.all(env.action_space.low == -1) and np.all(env.action_space.high == 1)):
        env = gymnasium.wrappers.RescaleAction(env, -1.0, 1.0)
    return env


def make_env(env_cfg: DictConfig, render_mode: str | None = None
             ) -> tuple[TransformedEnv, Symmetry | None]:
    """The TorchRL env (with TD-MPC's action repeat) and the task's declaration, if any."""
    gym_env = make_gym_env(env_cfg, render_mode)
    symmetry = getattr(gym_env.unwrapped, "symmetry", None)
    env = TransformedEnv(GymWrapper(gym_env), FrameSkipTransform(int(env_cfg.action_repeat)))
    return env, symmetry


def agent_config(cfg: DictConfig) -> TDMPCConfig:
    data = OmegaConf.to_container(cfg.agent, resolve=True)
    group = data.pop("group")
    networks = dict(data.pop("networks"), group=None if group in (None, "none") else str(group),
                    width_strategy=data.pop("width_strategy"),
                    equivariant=data.pop("equivariant"),
                    allow_approximate=data.pop("allow_approximate", False))
    try:
        return TDMPCConfig.from_dict({"networks": networks, **data})
    except (TypeError, ValueError) as err:
        raise ConfigError(str(err)) from None


# Every option outside agent.* and env.*: its type and smallest value (None: a choice).
OPTIONS: dict[str, tuple[type, Any]] = {
    "seed": (int, 0), "device": (str, None),
    "train.steps": (int, 1), "train.seed_steps": (int, 0), "train.updates_per_step": (int, 1),
    "train.eval_every": (int, 1), "train.eval_episodes": (int, 1),
    "train.eval_noisy_episodes": (int, 0), "train.threads": (int, 1), "train.progress": (bool, None),
    "train.checkpoint_every": (int, 1), "train.video": (bool, None), "train.video_every": (int, 1),
    "logger.tensorboard": (object, None), "env.action_repeat": (int, 1),
}


def check_options(cfg: DictConfig) -> None:
    """Types, ranges and unknown keys of the loop's own options, in one line each."""
    plain = OmegaConf.to_container(cfg, resolve=True)
    known_sections = {k.split(".")[0] for k in OPTIONS} | {"agent", "env"}
    for key in plain:
        if key not in known_sections:
            raise ConfigError(f"unknown option {key!r}; valid: {', '.join(sorted(known_sections))}")
    for section in ("train", "logger"):
        valid = sorted(k.split(".", 1)[1] for k in OPTIONS if k.startswith(section + "."))
        for key in plain.get(section) or {}:
            if key not in valid:
                raise ConfigError(f"unknown option {section}.{key}; valid: {', '.join(valid)}")
    for key, (kind, least) in OPTIONS.items():
        value = OmegaConf.select(cfg, key)
        if kind is int and (isinstance(value, bool) or not isinstance(value, int)):
            raise ConfigError(f"{key} must be an integer, got {value!r}")
        if kind is bool and not isinstance(value, bool):
            raise ConfigError(f"{key} must be true or false, got {value!r}")
        if kind is str and not isinstance(value, str):
            raise ConfigError(f"{key} must be a string, got {value!r}")
        if least is not None and value < least:
            raise ConfigError(f"{key} must be >= {least}, got {value}")
    if cfg.logger.tensorboard not in (True, False, "auto"):
        raise ConfigError(f"logger.tensorboard={cfg.logger.tensorboard!r}; valid: true, false, auto")
    if cfg.logger.tensorboard is True and importlib.util.find_spec("tensorboard") is None:
        raise ConfigError("logger.tensorboard=true but the tensorboard package is not installed "
                          "(pip install tensorboard); use logger.tensorboard=auto or false")


def validate(cfg: DictConfig) -> tuple[TDMPCConfig, Symmetry | None, int, int]:
    """Check every option before any work; returns the agent config, declaration and sizes."""
    check_options(cfg)
    if cfg.device not in ("cpu", "cuda") and not str(cfg.device).startswith("cuda:"):
        raise ConfigError(f"device={cfg.device!r}; valid: cpu, cuda, cuda:<n>")
    if str(cfg.device).startswith("cuda") and not torch.cuda.is_available():
        raise ConfigError(f"device={cfg.device} but no CUDA device is available; use device=cpu")
    agent_cfg = agent_config(cfg)
    env = make_gym_env(cfg.env)
    symmetry = getattr(env.unwrapped, "symmetry", None)
    obs_size, action_size = env.observation_space.shape[0], env.action_space.shape[0]
    env.close()
    if agent_cfg.networks.group is not None:
        if symmetry is None:
            raise ConfigError(f"agent.group={agent_cfg.networks.group} needs a task that declares "
                              f"its symmetry ({', '.join(TASK_ENVS)}); {cfg.env.id} does not: "
                              "use agent.group=none")
        from agents.nn.escnn_groups import group_for_task

        nets = agent_cfg.networks
        try:
            _, exact = group_for_task(nets.group, symmetry, nets.max_frequency,
                                      nets.grid_frequency, nets.allow_approximate, cfg.env.id)
        except ValueError as err:
            raise ConfigError(str(err)) from None
        if not exact:
            warnings.warn(f"{agent_cfg.networks.group} is only an approximate symmetry of "
                          f"{cfg.env.id} (exact group: {symmetry.exact_group}); training anyway",
                          stacklevel=1)
    return agent_cfg, symmetry, obs_size, action_size


def check_resumable(run_dir: Path, cfg: DictConfig) -> None:
    """Refuse to continue a run directory that was made with different options."""
    saved_path = run_dir / "config.yaml"
    current = OmegaConf.to_container(cfg, resolve=True)
    if saved_path.exists():
        saved = OmegaConf.to_container(OmegaConf.load(saved_path), resolve=True)
        diffs = [f"{k}: {a!r} -> {b!r}" for k, a, b in differences(saved, current)
                 if not k.startswith(RESUMABLE_KEYS)]
        if diffs:
            raise ConfigError(f"{run_dir} holds a run with other options ({'; '.join(diffs)}); "
                              "use another hydra.run.dir, or the run's own options")
    OmegaConf.save(OmegaConf.create(current), saved_path)


# --- the loop ------------------------------------------------------------------
class Trainer:
    """TD-MPC's training loop with evaluation, logging and checkpoints."""

    def __init__(self, cfg: DictConfig, run_dir: Path,
                 validated: tuple[TDMPCConfig, Symmetry | None, int, int] | None = None) -> None:
        agent_cfg, self.symmetry, obs_size, action_size = validated or validate(cfg)
        check_writable(run_dir)
        check_resumable(run_dir, cfg)
        torch.set_num_threads(cfg.train.threads)
        torch.manual_seed(cfg.seed)
        np.random.seed(cfg.seed)
        self.cfg, self.run_dir = cfg, run_dir
        self.action_repeat = int(cfg.env.action_repeat)
        self.env, _ = make_env(cfg.env)
        if cfg.train.video:
            load_triton_before_mesa()
        self.eval_env, _ = make_env(cfg.env, render_mode="rgb_array" if cfg.train.video else None)
        self.agent = TDMPCAgent(agent_cfg, self.symmetry, obs_size, action_size,
                                device=cfg.device, seed=cfg.seed)
        self.buffer = make_replay_buffer(agent_cfg.replay, agent_cfg.horizon, agent_cfg.batch_size)
        self.log = RunLog(run_dir, cfg.logger.tensorboard)
        self.state = {"env_step": 0, "agent_step": 0, "episode": 0, "pending_updates": 0,
                      "wall_time": 0.0, "last_eval_step": None, "last_eval_reward": None,
                      "last_checkpoint_step": 0}
        self.options = checkpoint_options(cfg)
        restored = checkpoint.load(run_dir, self.agent, self.buffer, self.options)
        if restored is not None:
            self.state.update({k: restored[k] for k in self.state})
            dropped = self.log.truncate_after(self.state["env_step"])
            print(f"resuming {run_dir} at env step {self.state['env_step']} "
                  f"(dropped {dropped} log rows written after the checkpoint)")
        else:
            # No checkpoint: the run starts over, and so do its logs (killed before the
            # first checkpoint, or the checkpoint deleted): never two runs in one table.
            dropped = self.log.truncate_after(-1)
            if dropped:
                print(f"starting {run_dir} over (no checkpoint; dropped {dropped} log rows)")
        check_disk_space(run_dir, self.agent, agent_cfg.replay.capacity, obs_size, action_size)
        self.log.record_session(self.state["env_step"])

    # acting
    def random_action(self) -> torch.Tensor:
        """A uniform action in the agent's action domain (unit ball per vector field)."""
        out = []
        for f in self.agent.action_fields:
            if f.size == 1:
                out.append(torch.rand(1, generator=self.agent.generator) * 2 - 1)
            else:
                v = torch.randn(f.size, generator=self.agent.generator)
                radius = torch.rand(1, generator=self.agent.generator) ** (1 / f.size)
                out.append(v / v.norm() * radius)
        return torch.cat(out)

    def policy(self, explore: bool, random: bool, frames: list[np.ndarray] | None = None,
               phase: str = "acting") -> TensorDictModule:
        """The acting policy for one episode: random warm-up actions, or the planner;
        with ``frames``, the eval env is rendered before every action."""
        step = [self.state["agent_step"]]
        phase = "seeding" if random else phase

        def act(observation: torch.Tensor) -> torch.Tensor:
            stop_if_requested()
            faults.point(phase)
            if frames is not None:
                frames.append(self._eval_gym_env().render())
            if random:
                action = self.random_action()
            else:
                action = self.agent.act(observation, step[0], explore=explore)
            step[0] += 1
            return action.to(torch.float32).cpu()

        return TensorDictModule(act, in_keys=["observation"], out_keys=["action"])

    def episode(self, env: TransformedEnv, seed: int, explore: bool, random: bool,
                frames: list[np.ndarray] | None = None, phase: str = "acting") -> TensorDictBase:
        self.agent.planner.reset()
        env.set_seed(seed)
        td = env.rollout(max_steps=10**9, policy=self.policy(explore, random, frames, phase),
                         break_when_any_done=True, auto_reset=True)
        if frames is not None:
            frames.append(self._eval_gym_env().render())  # the final state
        return td

    def _eval_gym_env(self) -> gymnasium.Env:
        return self.eval_env.base_env._env

    def record_video(self) -> bool:
        """Whether this evaluation writes a video (every ``video_every``-th, the first included)."""
        return bool(self.cfg.train.video) and len(self.log.eval.rows()) % self.cfg.train.video_every == 0

    def evaluate(self) -> None:
        """TD-MPC's evaluation (planner without exploration noise), and the same start
        states with the training noise: a policy that only works with noise shows here."""
        frames: list[np.ndarray] | None = [] if self.record_video() else None

        def returns(n: int, explore: bool) -> list[float]:
            return [float(self.episode(self.eval_env, 10**6 + 1000 * self.cfg.seed + i,
                                       explore=explore, random=False,
                                       frames=frames if i == 0 and not explore else None,
                                       phase="evaluation")["next", "reward"].sum())
                    for i in range(n)]

        plain = returns(self.cfg.train.eval_episodes, explore=False)
        if frames:
            write_video(self.run_dir / "videos" / f"eval_{self.state['env_step']:08d}.mp4", frames,
                        frames_per_second(self._eval_gym_env(), self.action_repeat))
        noisy = returns(self.cfg.train.eval_noisy_episodes, explore=True)
        self.state["last_eval_step"] = self.state["env_step"]
        self.state["last_eval_reward"] = float(np.mean(plain))
        self.log.log("eval", {
            **self._counters(), "episode_reward": np.mean(plain),
            "episode_reward_std": np.std(plain), "eval_episodes": len(plain),
            "noisy_episode_reward": np.mean(noisy) if noisy else float("nan"),
            "noisy_episode_reward_std": np.std(noisy) if noisy else float("nan"),
            "noisy_eval_episodes": len(noisy)})

    def _counters(self) -> dict[str, float]:
        return {k: self.state[k] for k in ("env_step", "agent_step", "episode", "wall_time")}

    def update(self, n: int) -> dict[str, float]:
        horizon = self.agent.config.horizon
        totals: dict[str, float] = {}
        for _ in range(n):
            stop_if_requested()
            faults.point("update")
            batch = sample_slices(self.buffer, horizon)
            metrics = self.agent.update(batch.select(*REPLAY_KEYS, "index", "priority_weight",
                                                     strict=False))
            update_priorities(self.buffer, batch, self.agent.last_priority)
            for k, v in metrics.items():
                totals[k] = totals.get(k, 0.0) + v / n
        return totals

    def train(self) -> None:
        cfg, state = self.cfg.train, self.state
        bar = tqdm(total=cfg.steps, initial=state["env_step"], unit="step", disable=not cfg.progress,
                   dynamic_ncols=True, desc="env steps")
        if state["last_eval_step"] is None:
            self.evaluate()
        while state["env_step"] < cfg.steps:
            start = time.perf_counter()
            random = state["env_step"] < cfg.seed_steps
            td = self.episode(self.env, 1000 * self.cfg.seed + state["episode"], explore=True,
                              random=random)
            length = td.shape[0]
            td.set("episode", torch.full((length,), state["episode"], dtype=torch.int64))
            self.buffer.extend(td.select(*REPLAY_KEYS))
            state["episode"] += 1
            state["agent_step"] += length
            state["env_step"] += length * self.action_repeat
            state["pending_updates"] += length * cfg.updates_per_step
            metrics = {}
            if state["env_step"] >= cfg.seed_steps:
                metrics = self.update(state["pending_updates"])
                metrics["updates"] = state["pending_updates"]
                metrics["target_lag"] = self.agent.target_lag()
                state["pending_updates"] = 0
            elapsed = time.perf_counter() - start
            state["wall_time"] += elapsed
            self.log.log("train", {**self._counters(), **metrics,
                                   "episode_reward": float(td["next", "reward"].sum()),
                                   "steps_per_second": length * self.action_repeat / elapsed})
            if (state["env_step"] - state["last_eval_step"] >= cfg.eval_every
                    or state["env_step"] >= cfg.steps):
                eval_start = time.perf_counter()
                self.evaluate()
                state["wall_time"] += time.perf_counter() - eval_start
            if (state["env_step"] - state["last_checkpoint_step"] >= cfg.checkpoint_every
                    or state["env_step"] >= cfg.steps):
                state["last_checkpoint_step"] = state["env_step"]
                checkpoint.save(self.run_dir, self.agent, self.buffer, state, self.options)
            bar.update(length * self.action_repeat)
            bar.set_postfix(eval_return=f"{state['last_eval_reward']:.1f}")
        bar.close()


def run(cfg: DictConfig, run_dir: Path) -> int:
    """Train; returns the exit status (2: bad input, 1: cannot write, 130: interrupted)."""
    try:
        validated = validate(cfg)
    except ConfigError as err:
        _remove_if_only_hydra_files(run_dir)
        print(f"geomdp-train: error: {err}", file=sys.stderr)
        return 2
    _STOP.clear()
    previous = {s: signal.signal(s, _request_stop) for s in (signal.SIGTERM, signal.SIGINT)}
    try:
        try:
            run_dir.mkdir(parents=True, exist_ok=True)
        except OSError as err:
            raise RunDirError(f"cannot create the run directory {run_dir} ({err.strerror}); "
                              "choose another hydra.run.dir") from None
        trainer = Trainer(cfg, run_dir, validated)
        trainer.train()
    except (ConfigError, checkpoint.CheckpointError, RunLogError) as err:
        print(f"geomdp-train: error: {err}", file=sys.stderr)
        return 1 if isinstance(err, (RunDirError, checkpoint.CheckpointWriteError)) else 2
    except KeyboardInterrupt:
        print(f"\ninterrupted; the last checkpoint is at env step {_saved_step(run_dir)}: run the "
              "same command to continue", file=sys.stderr)
        return 130
    finally:
        for s, handler in previous.items():
            signal.signal(s, handler)
    print(f"done: {run_dir} (last eval return {trainer.state['last_eval_reward']:.1f})")
    return 0


def _saved_step(run_dir: Path) -> int:
    """The env step of the checkpoint a rerun will resume from (a save interrupted
    mid-swap leaves it under checkpoint.old)."""
    import json

    for name in ("checkpoint", "checkpoint.old"):
        path = run_dir / name / "state.json"
        if path.exists():
            return json.loads(path.read_text())["env_step"]
    return 0


# --- interruption, and the run directory ------------------------------------------
_STOP: dict[str, int] = {}


def _request_stop(signum: int, frame: object) -> None:
    """SIGTERM/SIGINT ask the loop to stop at its next safe point (between env steps or
    updates), so no library is interrupted half-way; a second signal stops at once."""
    if _STOP:
        raise KeyboardInterrupt
    _STOP["signal"] = signum


def stop_if_requested() -> None:
    if _STOP:
        raise KeyboardInterrupt


class RunDirError(ConfigError):
    """The run directory cannot hold the run (not writable, disk too full)."""


def check_writable(run_dir: Path) -> None:
    """Refuse, in one line, a run directory (or left-over checkpoint) that cannot be written."""
    probe = run_dir / ".geomdp-write-test"
    try:
        probe.write_text("ok")
        probe.unlink()
    except OSError as err:
        raise RunDirError(f"cannot write in the run directory {run_dir} ({err.strerror}); "
                          "choose another hydra.run.dir or fix its permissions") from None
    for name in ("checkpoint", "checkpoint.old", "checkpoint.tmp"):
        for path in [run_dir / name, *(run_dir / name).rglob("*")]:
            if path.is_dir() and not os.access(path, os.W_OK | os.X_OK):
                raise RunDirError(f"{path} is not writable: the run could not replace its "
                                  "checkpoint; fix its permissions")


def check_disk_space(run_dir: Path, agent: TDMPCAgent, capacity: int, obs_size: int,
                     action_size: int) -> None:
    """Refuse to start when the disk cannot hold two checkpoints (the new one is written
    beside the old); estimated from the agent's state and the replay's full capacity."""
    state_bytes = 4 * sum(p.numel() * p.element_size() for p in agent.model.parameters())
    replay_bytes = capacity * (4 * (2 * obs_size + action_size + 2) + 8 * 2 + 16)
    need = 2 * (state_bytes + replay_bytes) + (16 << 20)
    free = shutil.disk_usage(run_dir).free
    if free < need:
        raise RunDirError(f"not enough disk space in {run_dir}: {free >> 20} MB free, a run of "
                          f"this size needs about {need >> 20} MB for its checkpoints")


def _remove_if_only_hydra_files(run_dir: Path) -> None:
    """A run refused before any work leaves no directory behind (Hydra makes it first)."""
    if not run_dir.is_dir():
        return
    entries = {p.name for p in run_dir.iterdir()}
    log = run_dir / "train.log"
    if entries <= {".hydra", "train.log"} and (not log.exists() or log.stat().st_size == 0):
        shutil.rmtree(run_dir, ignore_errors=True)


def checkpoint_options(cfg: DictConfig) -> dict[str, Any]:
    """The options a checkpoint belongs to: all but those a continued run may change."""
    flat = flatten(OmegaConf.to_container(cfg, resolve=True))
    return {k: v for k, v in flat.items() if not k.startswith(RESUMABLE_KEYS)}


CONFIG_DIR = Path(__file__).resolve().parents[2] / "configs"
MAX_DIRNAME = 120


def sweep_dirname(overrides: str) -> str:
    """A multirun job's directory name: its overrides, or, when they would make a name
    too long for the filesystem, their first characters and a hash of them all."""
    name = overrides.replace("/", "-") or "default"
    if len(name) <= MAX_DIRNAME:
        return name
    digest = hashlib.sha1(name.encode()).hexdigest()[:10]
    return f"{name[:MAX_DIRNAME - 12]}..{digest}"


def usable_cores() -> int:
    return len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count() or 1


OmegaConf.register_new_resolver("geomdp_dirname", sweep_dirname, replace=True)
OmegaConf.register_new_resolver("geomdp_cores", usable_cores, replace=True)


@hydra.main(version_base="1.3", config_path=str(CONFIG_DIR), config_name="train")
def hydra_main(cfg: DictConfig) -> None:
    status = run(cfg, Path(HydraConfig.get().runtime.output_dir))
    if status:
        sys.exit(status)


def rewrite_env_shorthand(argv: list[str]) -> list[str]:
    """``env=Pendulum-v1`` (a Gymnasium id, not a config) means ``env=gym env.id=Pendulum-v1``."""
    out = []
    for arg in argv:
        if arg.startswith("env=") and not (CONFIG_DIR / "env" / f"{arg[4:]}.yaml").exists():
            out += ["env=gym", f"env.id={arg[4:]}"]
        else:
            out.append(arg)
    return out


def main() -> None:
    sys.argv = [sys.argv[0], *rewrite_env_shorthand(sys.argv[1:])]
    hydra_main()


if __name__ == "__main__":
    main()
