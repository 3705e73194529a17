"""TD-MPC's training loop, given its parts.

The loop follows TD-MPC: collect a whole episode with the planner (random actions for
the first ``train.seed_steps``), then make one update per agent step collected, then
evaluate when due and checkpoint. ``build_parts`` makes the parts from a run's options
(seeding torch and numpy first, so a run is a function of its seed); a ``Trainer``
receives them and writes nothing until ``restore()`` (continue from the run
directory's checkpoint, or start its logs over) and ``train()``.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass
from pathlib import Path

import gymnasium
import numpy as np
import torch
from tensordict import TensorDictBase
from tensordict.nn import TensorDictModule
from torchrl.data import TensorDictReplayBuffer
from torchrl.envs import TransformedEnv

from agents.run import checkpoint, faults
from agents.run.checkpoint_state import describe
from agents.run.config import RunOptions, Task
from agents.run.envs import make_gym_env, torchrl_env
from agents.run.progress import Progress
from agents.run.run_dir import check_disk_space
from agents.run.run_log import RunLog
from agents.run.td_invariants import bootstrapped_returns, value_at_start
from agents.run.video import frames_per_second, write_video
from agents.tdmpc.agent import TDMPCAgent
from agents.tdmpc.planner import NoiseSource
from agents.tdmpc.replay import make_replay_buffer, sample_slices, update_priorities
from geomdp_envs.mujoco_env import load_triton_before_mesa

REPLAY_KEYS = ("observation", "action", "episode", ("next", "observation"),
               ("next", "reward"), ("next", "terminated"))
EVALUATION_NOISE_KEY = 2_000_003  # keeps evaluation's generators apart from any other seed's


def training_episode_seed(seed: int, episode: int) -> int:
    """The environment seed of a run's training episode ``episode`` (from 0): its start
    state and, on Reacher, its target, whatever the agent did before."""
    return 1000 * seed + episode


def evaluation_episode_seed(seed: int, i: int) -> int:
    """The environment seed of every evaluation's episode ``i``: each evaluation of a run
    starts from the same states."""
    return 10**6 + 1000 * seed + i


def evaluation_noise(seed: int, env_step: int) -> NoiseSource:
    """The planner noise of the evaluation at ``env_step`` under ``train.eval_noise=separate``:
    a generator of its own, a function of (seed, env step) only, so that evaluating draws
    nothing from the agent's generator and a resumed run evaluates as an uninterrupted one."""
    entropy = np.random.SeedSequence([EVALUATION_NOISE_KEY, seed, env_step])
    return NoiseSource(torch.Generator().manual_seed(int(entropy.generate_state(1, np.uint64)[0])))


class StopRequest:
    """Set by the command line's signal handlers; the loop stops at its next safe point
    (between env steps or updates), so no library is interrupted half-way."""

    def __init__(self) -> None:
        self.signal: int | None = None

    def check(self) -> None:
        if self.signal is not None:
            raise KeyboardInterrupt


@dataclass
class Parts:
    """What a trainer trains: the training and evaluation envs (the latter also as the
    Gymnasium env it wraps, to render videos), the agent and its replay buffer."""

    env: TransformedEnv
    eval_env: TransformedEnv
    eval_gym_env: gymnasium.Env
    agent: TDMPCAgent
    buffer: TensorDictReplayBuffer


def build_parts(options: RunOptions, task: Task) -> Parts:
    """Seed torch and numpy, then make the envs, the agent and the replay (in this order:
    the agent's initial weights come from the seeded global generator).

    The training env is the one ``check_task`` made and checked. Evaluation has an env of
    its own (as TorchRL's examples do; TD-MPC evaluates on its training env): evaluating
    never moves the training env's generator, so the training episodes' start states do
    not depend on the evaluation settings, and only the evaluation env renders videos."""
    torch.set_num_threads(options.train.threads)
    torch.manual_seed(options.seed)
    np.random.seed(options.seed)
    env_opts = options.env
    env = torchrl_env(task.env, env_opts.action_repeat)  # made and checked by check_task
    if options.train.video:
        load_triton_before_mesa()
    eval_gym_env = make_gym_env(env_opts,
                                render_mode="rgb_array" if options.train.video else None)
    eval_env = torchrl_env(eval_gym_env, env_opts.action_repeat)
    agent = TDMPCAgent(options.agent, task.symmetry, task.observation_size, task.action_size,
                       device=options.device, seed=options.seed)
    buffer = make_replay_buffer(options.agent.replay, options.agent.horizon,
                                options.agent.batch_size)
    return Parts(env, eval_env, eval_gym_env, agent, buffer)


class Trainer:
    """TD-MPC's training loop with evaluation, logging and checkpoints."""

    def __init__(self, options: RunOptions, run_dir: Path, parts: Parts, log: RunLog,
                 stop: StopRequest | None = None,
                 session_notes: dict[str, str] | None = None) -> None:
        self.options, self.run_dir, self.log = options, run_dir, log
        self.session_notes = session_notes or {}  # symmetry_check, changed_options
        self.env, self.eval_env, self.eval_gym_env = parts.env, parts.eval_env, parts.eval_gym_env
        self.agent, self.buffer = parts.agent, parts.buffer
        self.stop = stop or StopRequest()
        self.action_repeat = options.env.action_repeat
        self.checkpoint_options = options.checkpoint_options()
        self.state = {"env_step": 0, "agent_step": 0, "episode": 0, "pending_updates": 0,
                      "wall_time": 0.0, "last_eval_step": None, "last_eval_reward": None,
                      "last_checkpoint_step": 0, "unfinished_episode": None}
        self.progress: Progress | None = None  # while train() runs

    def restore(self) -> int:
        """Continue from the run directory's checkpoint (its logs cut back to it), or
        start its logs over; record this session. Returns the env step it starts from."""
        restored = checkpoint.load(self.run_dir, self.agent, self.buffer, self.checkpoint_options)
        if restored is not None:
            # (checkpoints from before unfinished_episode existed lack it: never inside updates)
            self.state.update({k: restored.get(k, self.state[k]) for k in self.state})
            # Inside an episode's updates, no row of its env step is written yet.
            inside = self.state["unfinished_episode"] is not None
            dropped = self.log.truncate_after(self.state["env_step"] - inside)
            print(f"resuming {self.run_dir} at {describe(self.state)} "
                  f"(dropped {dropped} log rows written after the checkpoint)")
        else:
            # No checkpoint: the run starts over, and so do its logs (killed before the
            # first checkpoint, or the checkpoint deleted): never two runs in one table.
            dropped = self.log.truncate_after(-1)
            if dropped:
                print(f"starting {self.run_dir} over (no checkpoint; dropped {dropped} log rows)")
        check_disk_space(self.run_dir, self.agent.checkpoint_bytes(), self.options.agent.replay.capacity,
                         self.agent.observation_size, self.agent.action_size)
        self.log.record_session(self.state["env_step"], **self.session_notes)
        return self.state["env_step"]

    # acting
    def policy(self, explore: bool, random: bool, frames: list[np.ndarray] | None = None,
               phase: str = "acting", noise: NoiseSource | None = None) -> TensorDictModule:
        """The acting policy for one episode: random warm-up actions, or the planner (its
        noise from ``noise``, default the agent's generator); with ``frames``, the eval env
        is rendered before every action."""
        step = [self.state["agent_step"]]
        phase = "seeding" if random else phase

        def act(observation: torch.Tensor) -> torch.Tensor:
            self.stop.check()
            faults.point(phase)
            if frames is not None:
                frames.append(self.eval_gym_env.render())
            if random:
                action = self.agent.random_action()
            else:
                action = self.agent.act(observation, step[0], explore=explore, noise=noise)
            step[0] += 1
            if self.progress is not None and phase != "evaluation":
                self.progress.advance(self.action_repeat)
            return action.to(torch.float32).cpu()

        return TensorDictModule(act, in_keys=["observation"], out_keys=["action"])

    def episode(self, env: TransformedEnv, seed: int, explore: bool, random: bool,
                frames: list[np.ndarray] | None = None, phase: str = "acting",
                noise: NoiseSource | None = None) -> TensorDictBase:
        self.agent.start_episode()
        env.set_seed(seed)
        td = env.rollout(max_steps=10**9, policy=self.policy(explore, random, frames, phase, noise),
                         break_when_any_done=True, auto_reset=True)
        if frames is not None:
            frames.append(self.eval_gym_env.render())  # the final state
        return td

    def record_video(self) -> bool:
        """Whether this evaluation writes a video (every ``video_every``-th, the first included)."""
        train = self.options.train
        return train.video and len(self.log.eval.rows()) % train.video_every == 0

    def evaluate(self) -> None:
        """TD-MPC's evaluation (planner without exploration noise), and the same start
        states with the training noise: a policy that only works with noise shows here."""
        frames: list[np.ndarray] | None = [] if self.record_video() else None

        train = self.options.train
        episodes = train.eval_episodes + train.eval_noisy_episodes
        noise = (evaluation_noise(self.options.seed, self.state["env_step"])
                 if train.eval_noise == "separate" else None)

        def rollouts(n: int, explore: bool) -> list[TensorDictBase]:
            out = []
            for i in range(n):
                if self.progress is not None:
                    self.progress.evaluating(i + (train.eval_episodes if explore else 0), episodes)
                out.append(self.episode(self.eval_env, evaluation_episode_seed(self.options.seed, i),
                                        explore=explore, random=False,
                                        frames=frames if i == 0 and not explore else None,
                                        phase="evaluation", noise=noise))
            return out

        played = rollouts(train.eval_episodes, explore=False)
        plain = [float(td["next", "reward"].sum()) for td in played]
        if frames:
            write_video(self.run_dir / "videos" / f"eval_{self.state['env_step']:08d}.mp4", frames,
                        frames_per_second(self.eval_gym_env, self.action_repeat))
        noisy = [float(td["next", "reward"].sum())
                 for td in rollouts(train.eval_noisy_episodes, explore=True)]
        self.state["last_eval_step"] = self.state["env_step"]
        self.state["last_eval_reward"] = float(np.mean(plain))
        self.log.log("eval", {
            **self._counters(), "episode_reward": np.mean(plain),
            "episode_reward_std": np.std(plain), "eval_episodes": len(plain),
            "noisy_episode_reward": np.mean(noisy) if noisy else float("nan"),
            "noisy_episode_reward_std": np.std(noisy) if noisy else float("nan"),
            "noisy_eval_episodes": len(noisy), **self.value_check(played)})
        if self.progress is not None:
            self.progress.evaluated(self.state["env_step"], self.state["last_eval_reward"])

    def value_check(self, played: list[TensorDictBase]) -> dict[str, float]:
        """Q(s₀, π(s₀)) against the discounted return each evaluation episode earned from
        s₀, past a time limit valued at the agent's own Q as its TD targets do
        (``td_invariants.value_at_start``). Computed after the episodes, from their
        logs: it draws no random number and leaves the agent as it was."""
        discount = self.agent.config.loss.discount
        values, returns = [], []
        for td in played:
            first_last = torch.stack([td["observation"][0], td["next", "observation"][-1]])
            q_start, q_last = self.agent.value(first_last).tolist()
            terminated = bool(td["next", "terminated"][-1])
            rewards = td["next", "reward"].reshape(-1).tolist()
            values.append(q_start)
            returns.append(bootstrapped_returns(rewards, discount, 0.0 if terminated else q_last)[0])
        return value_at_start(values, returns)

    def _counters(self) -> dict[str, float]:
        return {k: self.state[k] for k in ("env_step", "agent_step", "episode", "wall_time")}

    def update(self, n: int, of: int, totals: dict[str, float]) -> None:
        """``n`` gradient updates on replayed slices, their metrics added to ``totals`` as a
        share of ``of`` (the episode's updates: its average, built up across checkpoints)."""
        horizon = self.agent.config.horizon
        for _ in range(n):
            self.stop.check()
            faults.point("update")
            batch = sample_slices(self.buffer, horizon)
            metrics, priority = self.agent.update(batch.select(*REPLAY_KEYS, "index",
                                                               "priority_weight", strict=False))
            update_priorities(self.buffer, batch, priority)
            for k, v in metrics.items():
                totals[k] = totals.get(k, 0.0) + v / of

    def train(self) -> None:
        cfg, state = self.options.train, self.state
        self.progress = Progress(cfg, state["env_step"], state["last_eval_step"])
        try:
            self._train()
        finally:
            self.progress.close()
            self.progress = None

    def _train(self) -> None:
        cfg, state = self.options.train, self.state
        if state["last_eval_step"] is None:
            self.evaluate()
        # ``unfinished_episode`` is set from the moment an episode is collected until its
        # train row is logged: a checkpoint taken in between (inside a long block of
        # updates) resumes the block where it stopped.
        while state["env_step"] < cfg.steps or state["unfinished_episode"] is not None:
            resumed = state["unfinished_episode"] is not None
            if not resumed:
                self.collect_episode()
            metrics = self.episode_updates()
            if resumed:  # the ETA's rate leaves out the rest of a block resumed half-way
                self.progress.episode_started()
            self.end_episode(metrics)

    def collect_episode(self) -> None:
        """One training episode into the replay buffer; its updates fall due."""
        cfg, state = self.options.train, self.state
        start = time.perf_counter()
        self.progress.episode_started()
        random = state["env_step"] < cfg.seed_steps
        td = self.episode(self.env, training_episode_seed(self.options.seed, state["episode"]), explore=True,
                          random=random)
        length = td.shape[0]
        td.set("episode", torch.full((length,), state["episode"], dtype=torch.int64))
        self.buffer.extend(td.select(*REPLAY_KEYS))
        state["episode"] += 1
        state["agent_step"] += length
        state["env_step"] += length * self.action_repeat
        state["pending_updates"] += length * cfg.updates_per_step
        state["unfinished_episode"] = {"length": length,
                                       "reward": float(td["next", "reward"].sum()),
                                       "seconds": time.perf_counter() - start,
                                       "updates_done": 0, "metrics": {}}

    def episode_updates(self) -> dict[str, float]:
        """The updates due after an episode (none during the warm-up; after it, all those
        the warm-up held back, then one per agent step), averaged. A long block (the burst
        after the warm-up: TD-MPC's is 5000 updates) is checkpointed every
        ``checkpoint_every`` env steps' worth of updates, so that a stop inside it keeps
        what is done."""
        cfg, state, episode = self.options.train, self.state, self.state["unfinished_episode"]
        if state["env_step"] < cfg.seed_steps:
            return {}
        due = state["pending_updates"]
        # An episode's own updates are one block, as before; only a longer one is split.
        own = episode["length"] * cfg.updates_per_step
        chunk = due if due <= own else (
            math.ceil(cfg.checkpoint_every / self.action_repeat) * cfg.updates_per_step)
        self.progress.updating(due - episode["updates_done"])
        while episode["updates_done"] < due:
            start = time.perf_counter()
            n = min(chunk, due - episode["updates_done"])
            metrics = dict(episode["metrics"])  # the saved state changes only with updates_done
            self.update(n, due, metrics)
            episode.update(metrics=metrics, updates_done=episode["updates_done"] + n,
                           seconds=episode["seconds"] + time.perf_counter() - start)
            if episode["updates_done"] < due:
                checkpoint.save(self.run_dir, self.agent, self.buffer, state,
                                self.checkpoint_options)
        state["pending_updates"] = 0
        return {**episode["metrics"], "updates": due, "target_lag": self.agent.target_lag()}

    def end_episode(self, metrics: dict[str, float]) -> None:
        """The episode's train row; then an evaluation and a checkpoint when due."""
        cfg, state, episode = self.options.train, self.state, self.state["unfinished_episode"]
        self.progress.episode_done(episode["length"] * self.action_repeat)
        state["wall_time"] += episode["seconds"]
        state["unfinished_episode"] = None
        self.log.log("train", {**self._counters(), **metrics, "episode_reward": episode["reward"],
                               "steps_per_second": episode["length"] * self.action_repeat
                               / episode["seconds"]})
        if cfg.evaluation_due(state["env_step"], state["last_eval_step"]):
            eval_start = time.perf_counter()
            self.evaluate()
            state["wall_time"] += time.perf_counter() - eval_start
        if (state["env_step"] - state["last_checkpoint_step"] >= cfg.checkpoint_every
                or state["env_step"] >= cfg.steps):
            state["last_checkpoint_step"] = state["env_step"]
            checkpoint.save(self.run_dir, self.agent, self.buffer, state, self.checkpoint_options)
