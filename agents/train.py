"""``geomdp-train``: train TD-MPC (plain or equivariant) on a task, as a Hydra app.

    geomdp-train env=pointmass3d env.n_balls=3 agent.group=icosahedral seed=1 \\
        train.steps=100000 hydra.run.dir=runs/x

Everything a run writes goes to its run directory: ``config.yaml`` (resolved),
``eval.csv``, ``train.csv``, TorchRL logger output and ``checkpoint/``.
Starting the same command again continues from the last checkpoint (replay
buffer included). The loop follows TD-MPC: collect a whole episode with the
planner (random actions for the first ``train.seed_steps``), then make one
update per agent step collected, then evaluate when due and checkpoint.
"""

from __future__ import annotations

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
from agents import checkpoint
from agents.replay import make_replay_buffer, sample_slices, update_priorities
from agents.run_log import RunLog
from agents.tdmpc import TDMPCAgent, TDMPCConfig
from geomdp_envs.symmetry import Symmetry

TASK_ENVS = ("pointmass2d", "pointmass3d", "reacher")
ENV_META_KEYS = ("name", "id", "action_repeat")
# Options that may change when a run is continued (budgets and display), and the rest must not.
RESUMABLE_KEYS = ("train.steps", "train.eval_every", "train.eval_episodes",
                  "train.eval_noisy_episodes", "train.progress",
                  "train.threads", "device", "logger.tensorboard")
REPLAY_KEYS = ("observation", "action", "episode", ("next", "observation"),
               ("next", "reward"), ("next", "terminated"))


class ConfigError(ValueError):
    """A bad option, reported in one line before any work starts."""


# --- configuration -----------------------------------------------------------
def env_kwargs(env_cfg: DictConfig) -> dict[str, Any]:
    return {k: v for k, v in OmegaConf.to_container(env_cfg).items() if k not in ENV_META_KEYS}


def make_gym_env(env_cfg: DictConfig) -> gymnasium.Env:
    """The Gymnasium env of a config; its errors (bad kwargs) become ConfigErrors."""
    if env_cfg.id not in gymnasium.registry:
        raise ConfigError(f"unknown environment {env_cfg.id!r}: use env=<one of "
                          f"{', '.join(TASK_ENVS)}> or env=<a registered Gymnasium id>")
    try:
        env = gymnasium.make(env_cfg.id, **env_kwargs(env_cfg))
    except (ValueError, TypeError) as err:
        raise ConfigError(str(err)) from None
    if not isinstance(env.action_space, gymnasium.spaces.Box):
        raise ConfigError(f"{env_cfg.id} has a {type(env.action_space).__name__} action space; "
                          "TD-MPC needs a Box")
    if not (np.all(env.action_space.low == -1) and np.all(env.action_space.high == 1)):
        env = gymnasium.wrappers.RescaleAction(env, -1.0, 1.0)
    return env


def make_env(env_cfg: DictConfig) -> tuple[TransformedEnv, Symmetry | None]:
    """The TorchRL env (with TD-MPC's action repeat) and the task's declaration, if any."""
    gym_env = make_gym_env(env_cfg)
    symmetry = getattr(gym_env.unwrapped, "symmetry", None)
    env = TransformedEnv(GymWrapper(gym_env), FrameSkipTransform(int(env_cfg.action_repeat)))
    return env, symmetry


def agent_config(cfg: DictConfig) -> TDMPCConfig:
    data = OmegaConf.to_container(cfg.agent, resolve=True)
    group = data.pop("group")
    networks = dict(data.pop("networks"), group=None if group in (None, "none") else str(group),
                    width_strategy=data.pop("width_strategy"),
                    equivariant=data.pop("equivariant"))
    try:
        return TDMPCConfig.from_dict({"networks": networks, **data})
    except (TypeError, ValueError) as err:
        raise ConfigError(str(err)) from None


def validate(cfg: DictConfig) -> tuple[TDMPCConfig, Symmetry | None, int, int]:
    """Check every option before any work; returns the agent config, declaration and sizes."""
    for key in ("train.steps", "train.eval_every", "train.eval_episodes", "train.threads",
                "train.updates_per_step", "env.action_repeat"):
        if OmegaConf.select(cfg, key) is None or OmegaConf.select(cfg, key) < 1:
            raise ConfigError(f"{key} must be a positive integer, got {OmegaConf.select(cfg, key)}")
    for key in ("train.seed_steps", "train.eval_noisy_episodes"):
        if OmegaConf.select(cfg, key) is None or OmegaConf.select(cfg, key) < 0:
            raise ConfigError(f"{key} must be >= 0, got {OmegaConf.select(cfg, key)}")
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
        from agents.groups import group_for_task

        try:
            _, exact = group_for_task(agent_cfg.networks.group, symmetry)
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
        diffs = [f"{k}: {a!r} -> {b!r}" for k, a, b in _diff(saved, current)
                 if not k.startswith(RESUMABLE_KEYS)]
        if diffs:
            raise ConfigError(f"{run_dir} holds a run with other options ({'; '.join(diffs)}); "
                              "use another hydra.run.dir, or the run's own options")
    OmegaConf.save(OmegaConf.create(current), saved_path)


def _diff(a: Any, b: Any, prefix: str = "") -> list[tuple[str, Any, Any]]:
    if isinstance(a, dict) and isinstance(b, dict):
        return [d for k in sorted(set(a) | set(b))
                for d in _diff(a.get(k), b.get(k), f"{prefix}{k}.")]
    return [] if a == b else [(prefix.rstrip("."), a, b)]


# --- the loop ------------------------------------------------------------------
class Trainer:
    """TD-MPC's training loop with evaluation, logging and checkpoints."""

    def __init__(self, cfg: DictConfig, run_dir: Path) -> None:
        agent_cfg, self.symmetry, obs_size, action_size = validate(cfg)
        check_resumable(run_dir, cfg)
        torch.set_num_threads(cfg.train.threads)
        torch.manual_seed(cfg.seed)
        np.random.seed(cfg.seed)
        self.cfg, self.run_dir = cfg, run_dir
        self.action_repeat = int(cfg.env.action_repeat)
        self.env, _ = make_env(cfg.env)
        self.eval_env, _ = make_env(cfg.env)
        self.agent = TDMPCAgent(agent_cfg, self.symmetry, obs_size, action_size,
                                device=cfg.device, seed=cfg.seed)
        self.buffer = make_replay_buffer(agent_cfg.replay, agent_cfg.horizon, agent_cfg.batch_size)
        self.log = RunLog(run_dir, cfg.logger.tensorboard)
        self.state = {"env_step": 0, "agent_step": 0, "episode": 0, "pending_updates": 0,
                      "wall_time": 0.0, "last_eval_step": None, "last_eval_reward": None}
        restored = checkpoint.load(run_dir, self.agent, self.buffer)
        if restored is not None:
            self.state.update({k: restored[k] for k in self.state})
            dropped = self.log.truncate_after(self.state["env_step"])
            print(f"resuming {run_dir} at env step {self.state['env_step']} "
                  f"(dropped {dropped} log rows written after the checkpoint)")

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

    def policy(self, explore: bool, random: bool) -> TensorDictModule:
        """The acting policy for one episode: random warm-up actions, or the planner."""
        step = [self.state["agent_step"]]

        def act(observation: torch.Tensor) -> torch.Tensor:
            if random:
                action = self.random_action()
            else:
                action = self.agent.act(observation, step[0], explore=explore)
            step[0] += 1
            return action.to(torch.float32).cpu()

        return TensorDictModule(act, in_keys=["observation"], out_keys=["action"])

    def episode(self, env: TransformedEnv, seed: int, explore: bool, random: bool) -> TensorDictBase:
        self.agent.planner.reset()
        env.set_seed(seed)
        return env.rollout(max_steps=10**9, policy=self.policy(explore, random),
                           break_when_any_done=True, auto_reset=True)

    def evaluate(self) -> None:
        """TD-MPC's evaluation (planner without exploration noise), and the same start
        states with the training noise: a policy that only works with noise shows here."""
        def returns(n: int, explore: bool) -> list[float]:
            return [float(self.episode(self.eval_env, 10**6 + 1000 * self.cfg.seed + i,
                                       explore=explore, random=False)["next", "reward"].sum())
                    for i in range(n)]

        plain = returns(self.cfg.train.eval_episodes, explore=False)
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
            checkpoint.save(self.run_dir, self.agent, self.buffer, state)
            bar.update(length * self.action_repeat)
            bar.set_postfix(eval_return=f"{state['last_eval_reward']:.1f}")
        bar.close()


def run(cfg: DictConfig, run_dir: Path) -> int:
    """Train; returns the exit status (130 when interrupted)."""
    run_dir.mkdir(parents=True, exist_ok=True)
    signal.signal(signal.SIGTERM, _raise_interrupt)
    try:
        trainer = Trainer(cfg, run_dir)
    except (ConfigError, checkpoint.CheckpointError) as err:
        print(f"geomdp-train: error: {err}", file=sys.stderr)
        return 2
    try:
        trainer.train()
    except KeyboardInterrupt:
        print(f"\ninterrupted; the last checkpoint is at env step {_saved_step(run_dir)}: run the "
              "same command to continue", file=sys.stderr)
        return 130
    print(f"done: {run_dir} (last eval return {trainer.state['last_eval_reward']:.1f})")
    return 0


def _saved_step(run_dir: Path) -> int:
    import json

    path = checkpoint.checkpoint_dir(run_dir) / "state.json"
    return json.loads(path.read_text())["env_step"] if path.exists() else 0


def _raise_interrupt(signum: int, frame: object) -> None:
    raise KeyboardInterrupt


CONFIG_DIR = Path(__file__).resolve().parent.parent / "configs"


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
