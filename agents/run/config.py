"""A run's options, declared and checked once: ``seed``, ``device``, ``train.*``,
``logger.*``, ``env.*`` and the agent's (``agents.tdmpc.agent.TDMPCConfig``), the
same nesting as ``configs/train.yaml``; and the checks that need the task (its
declaration decides which groups are valid)."""

from __future__ import annotations

import dataclasses
import importlib.util
import typing
import warnings
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import gymnasium
import torch
from omegaconf import OmegaConf

from agents.compat.torchrl import prioritized_replay_refusal
from agents.nn.capacity import encoder_shortfall
from agents.nn.escnn_groups import group_for_task
from agents.options import OptionError, check, from_dict, option
from agents.run.envs import TASK_ENVS, EnvOptions, make_gym_env
from agents.run.nested import flatten
from agents.tdmpc.agent import TDMPCConfig
from agents.tdmpc.augmentation import augmentation_group
from geomdp_envs import symmetry_of
from geomdp_envs.check import check_symmetry
from geomdp_envs.declare import load_declaration, shipped_declarations
from geomdp_envs.symmetry import Symmetry

# Options that may change when a run is continued (budgets and display), and the rest must not.
RESUMABLE_KEYS = ("train.steps", "train.eval_every", "train.eval_episodes",
                  "train.eval_noisy_episodes", "train.progress", "train.checkpoint_every",
                  "train.video", "train.threads", "device", "logger.tensorboard",
                  "env.check_symmetry")


def declaration_contents(source: str) -> dict[str, Any]:
    """A declaration named by its file or shipped name, as the plain data ``config.yaml``
    records; a declaration that cannot be read is an OptionError."""
    try:
        return load_declaration(source).to_dict()
    except (ValueError, TypeError) as err:
        raise OptionError(f"env.symmetry: {err}") from None


def fixed_options(flat: dict[str, Any]) -> dict[str, Any]:
    """The flattened options a continued run must keep (all but ``RESUMABLE_KEYS``): what
    a checkpoint belongs to, and what a resume in the same run directory is checked on.
    A declaration recorded by name (runs made before ``record_declaration``) is compared
    by its contents; one unreadable now is compared by its name, so refused as changed."""
    source = flat.get("env.symmetry")
    if isinstance(source, str):
        try:
            contents = declaration_contents(source)
        except OptionError:
            contents = None
        if contents is not None:
            flat = {**{k: v for k, v in flat.items() if k != "env.symmetry"},
                    **flatten(contents, "env.symmetry.")}
    return {k: v for k, v in flat.items() if not k.startswith(RESUMABLE_KEYS)}


EVAL_NOISES = ("shared", "separate")


@dataclass
class TrainOptions:
    """The training loop's budgets and schedule (``train.*``)."""

    KEY: typing.ClassVar[str] = "train"
    steps: int = option(30000, low=1)            # environment steps (action repeats included)
    seed_steps: int = option(2000, low=0)        # env steps of random actions before updates
    updates_per_step: int = option(1, low=1)     # gradient updates per agent step
    eval_every: int = option(5000, low=1)        # env steps between evaluations (and one at 0)
    eval_episodes: int = option(10, low=1)
    eval_noisy_episodes: int = option(3, low=0)  # the same start states with training noise
    # where evaluation's planner noise comes from: "shared", the agent's generator (as TD-MPC,
    # and every committed run: evaluation settings then change the training trajectory, as
    # another seed would), or "separate", a generator per evaluation seeded by (seed, env
    # step): training then does not depend on when or how much the run is evaluated
    eval_noise: str = option("shared", choices=EVAL_NOISES)
    threads: int = option(1, low=1)              # torch threads
    progress: bool = True
    # env steps between checkpoints (at episode ends; in a block of updates: that many steps' worth)
    checkpoint_every: int = option(1000, low=1)
    video: bool = False
    video_every: int = option(5, low=1)

    def __post_init__(self) -> None:
        check(self)

    def evaluation_due(self, env_step: int, last_eval_step: int) -> bool:
        """The trainer evaluates after the episode that ends ``eval_every`` or more env steps
        after the last evaluation, and after the last episode."""
        return env_step - last_eval_step >= self.eval_every or env_step >= self.steps

    def evaluations_left(self, env_step: int, last_eval_step: int | None,
                         episode_steps: int = 1) -> int:
        """How many evaluations the trainer will still make from ``env_step`` on (one at
        ``env_step`` if it is due there; ``last_eval_step=None``: none made yet), episodes
        of ``episode_steps`` env steps ahead (exact once an episode's length is known)."""
        count = 0
        if last_eval_step is None or (env_step > last_eval_step
                                      and self.evaluation_due(env_step, last_eval_step)):
            count, last_eval_step = 1, env_step
        while env_step < self.steps:
            env_step += episode_steps
            if self.evaluation_due(env_step, last_eval_step):
                count, last_eval_step = count + 1, env_step
        return count


@dataclass
class LoggerOptions:
    KEY: typing.ClassVar[str] = "logger"
    tensorboard: bool | str = option("auto", choices=(True, False, "auto"))

    def __post_init__(self) -> None:
        check(self)


@dataclass
class RunOptions:
    """Every option of a run; ``resolved`` (not an option) is the config as written to
    ``config.yaml``, when the options came from one."""

    KEY: typing.ClassVar[str] = ""
    env: EnvOptions
    seed: int = option(1, low=0)
    device: str = "cpu"
    train: TrainOptions = field(default_factory=TrainOptions)
    logger: LoggerOptions = field(default_factory=LoggerOptions)
    agent: TDMPCConfig = field(default_factory=TDMPCConfig)
    resolved: dict[str, Any] = field(default_factory=dict, init=False, repr=False)

    def __post_init__(self) -> None:
        check(self)
        if self.device not in ("cpu", "cuda") and not self.device.startswith("cuda:"):
            raise OptionError(f"device={self.device!r}; valid: cpu, cuda, cuda:<n>")

    @classmethod
    def from_config(cls, resolved: dict[str, Any]) -> RunOptions:
        """From a resolved Hydra config (plain data), refusing unknown or bad options."""
        data = dict(resolved)
        if isinstance(data.get("env"), dict):
            data["env"] = EnvOptions.from_section(data["env"])
        if isinstance(data.get("agent"), dict):
            data["agent"] = from_dict(TDMPCConfig, data["agent"])
        options = from_dict(cls, data)
        options.resolved = resolved
        return options

    @classmethod
    def from_run_dir(cls, run_dir: Path) -> RunOptions:
        """The options a run was made with, from its directory's ``config.yaml`` (for tools
        that read a finished run: drawing its episodes again, loading its checkpoint)."""
        path = Path(run_dir) / "config.yaml"
        if not path.is_file():
            raise OptionError(f"{path}: no such file (a run directory holds the config.yaml "
                              "its run was made with)")
        return cls.from_config(OmegaConf.to_container(OmegaConf.load(path), resolve=True))

    def checkpoint_options(self) -> dict[str, Any]:
        """The options a checkpoint belongs to: all but those a continued run may change
        (from the resolved config, or from the dataclasses for options built in Python)."""
        plain = self.resolved or dataclasses.asdict(self)
        return fixed_options(flatten(plain))


def record_declaration(resolved: dict[str, Any]) -> dict[str, Any]:
    """The resolved config with ``env.symmetry`` given by its contents, not by a file name
    or shipped name: ``config.yaml`` then records the declaration the run was made with,
    and a resume whose declaration has changed since is refused like any changed option."""
    env = resolved.get("env")
    if not isinstance(env, dict) or not isinstance(env.get("symmetry"), str):
        return resolved
    return {**resolved, "env": {**env, "symmetry": declaration_contents(env["symmetry"])}}


@dataclass(frozen=True)
class Task:
    """The task as checked: its Gymnasium env (made once, by ``check_task``; the run trains
    in it), its declaration and vector sizes, and how the declaration was checked
    (``symmetry_check``: passed under which groups, skipped, or empty when there was
    nothing to check)."""

    env: gymnasium.Env
    symmetry: Symmetry | None
    observation_size: int
    action_size: int
    symmetry_check: str = ""


def check_declaration(options: RunOptions, env: gymnasium.Env, symmetry: Symmetry) -> str:
    """Check a third-party env's declaration (``env.symmetry``) against its simulator under
    the group it claims exact (which holds every group the agent may use exactly), before
    anything is written, when the agent uses the symmetry: a failing declaration is refused
    in one line naming the group and the fields. Returns what ``sessions.csv`` records."""
    agent = options.agent
    if options.env.symmetry is None or (agent.group is None and agent.augment == "none"):
        return ""
    if not options.env.check_symmetry:
        return "skipped (env.check_symmetry=false)"
    group = symmetry.exact_group
    try:
        report = check_symmetry(env, group=group, n_trials=32, seed=options.seed)
    except (ValueError, TypeError) as err:
        raise OptionError(f"env.symmetry cannot be checked under {group} ({err}); fix the "
                          "declaration, or pass env.check_symmetry=false to train "
                          "unchecked") from None
    if not report.passed:  # the report's own line: errors, fields at the env's indices, hint
        raise OptionError(f"env.symmetry fails its check under {group}, its exact group: "
                          f"{report}; see geomdp-check {options.env.id} <declaration> --group "
                          f"{group}, or pass env.check_symmetry=false to train anyway")
    return f"passed under {group} ({report.n_trials} trials)"


def check_task(options: RunOptions) -> Task:
    """The checks that need this machine or the task: the device and logger are here,
    the env is made (its own checks of its kwargs; the run then trains in it), the agent's
    group and augmentation fit the task's declaration; warns once for an approximate group
    and for an equivariant encoder too narrow to carry the observation.
    (Options alone are checked by the dataclasses, so reading a run's config needs
    neither its device nor its task.)"""
    if options.device.startswith("cuda") and not torch.cuda.is_available():
        raise OptionError(f"device={options.device} but no CUDA device is available; use device=cpu")
    if options.agent.replay.prioritized and (refusal := prioritized_replay_refusal()):
        raise OptionError(refusal)
    if options.logger.tensorboard is True and importlib.util.find_spec("tensorboard") is None:
        raise OptionError("logger.tensorboard=true but the tensorboard package is not installed "
                          "(pip install tensorboard); use logger.tensorboard=auto or false")
    env = make_gym_env(options.env)
    try:
        return _checked_task(options, env)
    except BaseException:
        env.close()
        raise


def _checked_task(options: RunOptions, env: gymnasium.Env) -> Task:
    symmetry = symmetry_of(env)
    agent = options.agent
    if agent.augment != "none":
        augmentation_group(agent.augment, symmetry)
    if agent.group is not None and symmetry is None:
        raise OptionError(f"agent.group={agent.group} needs a task that declares its symmetry "
                          f"({', '.join(TASK_ENVS)}, or env.symmetry=<a YAML file or one of "
                          f"{', '.join(shipped_declarations())}>); {options.env.id} does not: "
                          "use agent.group=none")
    checked = check_declaration(options, env, symmetry) if symmetry is not None else ""
    task = Task(env, symmetry, env.observation_space.shape[0], env.action_space.shape[0], checked)
    if agent.group is not None:
        nets = agent.networks
        try:
            _, exact = group_for_task(agent.group, task.symmetry, nets.max_frequency,
                                      nets.grid_frequency, agent.allow_approximate, options.env.id)
        except ValueError as err:
            raise OptionError(str(err)) from None
        if not exact:
            warnings.warn(f"{agent.group} is only an approximate symmetry of {options.env.id} "
                          f"(exact group: {task.symmetry.exact_group}); training anyway",
                          stacklevel=1)
        if short := encoder_shortfall(agent, task.symmetry):
            warnings.warn(short, stacklevel=1)
    return task
