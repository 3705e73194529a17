"""What a PointMass agent does before it has earned any reward.

    python scripts/before_reward.py untrained [--env pointmass3d] [--groups none octahedral icosahedral]
    python scripts/before_reward.py runs RUN_DIR [RUN_DIR ...]
    python scripts/before_reward.py restored RUN_DIR [RUN_DIR ...]

PointMass's target sits at the origin, the point every rotation and reflection fixes, and
the ball starts at rest. With one ball, a G-equivariant policy's action at rest is then an
equivariant function of the ball's position alone, and for the groups used here that pins
it to (nearly) the line through the target: exactly on the line where the position's
stabiliser fixes nothing else (a symmetry axis of a finite group; everywhere for an exactly
SO(3)-equivariant network, which the sampled ones here approximate), and up to terms of
high degree elsewhere (icosahedral: no equivariant map from the vector representation to
itself of degree 2-4 but the radial one; octahedral: degree 3 already has one). So an
untrained equivariant policy pushes the ball straight toward the target or straight away
from it (the sign a function of the distance), while a plain one pushes in a direction
unrelated to the target. Sparse rewards (PointMass3D's small target) make this matter:
before any reward a TD learner's values carry no information, and how it behaves then
decides whether it ever finds the target.

``untrained``: fresh agents (the CPU preset, ``linear`` width, one network per ``--inits``
seed) on the task's start states: how well the policy's action at rest lines up with the
ball's line to the target (mean |cos|; 1: on the line, 0.5: a random direction in 3D,
2/pi in 2D), how many inits' policies head inward or outward, and the return of
``--episodes`` episodes acted by the untrained policy alone (and, with ``--planner``, by
the untrained planner, whose zero-initialised reward and Q heads give every plan the same
value). ``runs``: from committed runs' ``train.csv`` alone, the first training episode a
run solved (return above ``--solved``) and the reward it had earned before it, in the
warm-up and after: did it find the target before it had seen reward? ``restored``: agents
as their runs' checkpoints left them (a run stopped where it matters, e.g. at the end of its
warm-up and its burst of updates: ``train.steps`` = ``train.seed_steps``): the policy's
alignment at rest, the planner's first action's (with training's exploration noise at the
run's agent step) and the returns of each acting alone — does what the trainer acts with
carry the policy's prior?
"""

from __future__ import annotations

import argparse
import math
from collections import defaultdict
from pathlib import Path

import gymnasium
import numpy as np
import torch
from omegaconf import OmegaConf
from scipy.stats import fisher_exact

import geomdp_envs  # noqa: F401  (registers GeoMDP/*)
from agents import TDMPCAgent, agent_config
from agents.options import OptionError
from agents.run import checkpoint
from agents.run.config import RunOptions
from agents.run.envs import make_gym_env
from agents.run.presets import compose_config
from agents.run.run_tables import training_episodes
from geomdp_envs import symmetry_of

TASKS = ("pointmass3d", "pointmass2d")  # configs/env/: the target at the origin, the ball at rest
EARNED = 1.0  # "before it had seen reward": less than this much in all earlier episodes


def alignment(observations: np.ndarray, actions: np.ndarray, dim: int) -> np.ndarray:
    """cos(action on ball i, ball i's direction to the target) per start and ball; the
    observation begins with the balls' positions relative to the target (at the origin)."""
    balls = actions.shape[1] // dim
    to_target = -observations[:, :balls * dim].reshape(len(observations), balls, dim)
    pushed = actions.reshape(len(actions), balls, dim)
    norms = np.linalg.norm(to_target, axis=-1) * np.linalg.norm(pushed, axis=-1)
    return np.sum(to_target * pushed, axis=-1) / np.maximum(norms, 1e-12)


def episode_return(env: gymnasium.Env, action_repeat: int, agent: TDMPCAgent, seed: int,
                   planner: bool, step: int = 0) -> float:
    """One episode acted by the planner as in training (exploration noise of agent step
    ``step``'s schedule) or by the policy's mean action alone."""
    obs, _ = env.reset(seed=seed)
    agent.start_episode()
    total, done = 0.0, False
    while not done:
        o = torch.as_tensor(obs)
        action = (agent.act(o, step, explore=True) if planner else agent.policy_action(o)).numpy()
        for _ in range(action_repeat):
            obs, reward, terminated, truncated, _ = env.step(action)
            total += reward
            done = terminated or truncated
            if done:
                break
    return total


def start_states(env: gymnasium.Env, n: int) -> np.ndarray:
    """The task's first ``n`` start states of a fixed set (seeds 10**6, 10**6 + 1, ...)."""
    return np.array([env.reset(seed=10**6 + i)[0] for i in range(n)])


def first_planned_actions(agent: TDMPCAgent, starts: np.ndarray, step: int) -> np.ndarray:
    """The planner's first action of an episode from each start state, with training's
    exploration noise at agent step ``step``."""
    actions = []
    for start in starts:
        agent.start_episode()
        actions.append(agent.act(torch.as_tensor(start), step, explore=True).numpy())
    return np.array(actions)


def cos_cell(cos: np.ndarray) -> str:
    return f"|cos| {np.abs(cos).mean():.2f} cos {cos.mean():+.2f}"


def untrained(args: argparse.Namespace) -> None:
    task = ([f"env.target_size={args.target_size}", f"env.n_balls={args.n_balls}"]
            if args.env == "pointmass3d" else [])
    options = RunOptions.from_config(OmegaConf.to_container(compose_config([f"env={args.env}", *task]),
                                                            resolve=True)).env
    env = make_gym_env(options)
    symmetry = symmetry_of(env)
    starts = start_states(env, args.starts)
    random_direction = 0.5 if symmetry.dim == 3 else 2 / math.pi
    arguments = f" {options.kwargs}" if options.kwargs else ""
    print(f"{args.env}{arguments}: {args.inits} untrained agents per group, "
          f"the policy at {args.starts} start states (at rest; mean |cos| of a random direction: "
          f"{random_direction:.3f}); returns of {args.episodes} episodes each, solved = "
          f"return > {args.solved:g}", flush=True)
    modes = ("policy", "planner") if args.planner else ("policy",)
    for group in args.groups:
        heading, solved = {"inward": 0, "outward": 0}, dict.fromkeys(modes, 0)
        for init in range(args.inits):
            torch.manual_seed(init)
            try:
                agent = TDMPCAgent(agent_config("tdmpc", f"group={group}", "width_strategy=linear"),
                                   symmetry, env.observation_space.shape[0],
                                   env.action_space.shape[0], seed=init)
            except (OptionError, ValueError) as err:  # a group the task does not allow
                raise SystemExit(str(err)) from None
            cos = alignment(starts, agent.policy_action(torch.as_tensor(starts)).numpy(), symmetry.dim)
            heading["inward"] += cos.mean() > 0.5  # on average within 60 degrees of the way in
            heading["outward"] += cos.mean() < -0.5
            cell = cos_cell(cos)
            for mode in modes:
                returns = [episode_return(env, options.action_repeat, agent, 1000 * init + e,
                                          mode == "planner")
                           for e in range(args.episodes)]
                solved[mode] += sum(r > args.solved for r in returns)
                cell += f", {mode} " + " ".join(f"{r:.0f}" for r in returns)
            print(f"  {group} init {init}: {cell}", flush=True)
        episodes = args.inits * args.episodes
        print(f"{group}: the policy heads inward (mean cos > 0.5) on {heading['inward']} of "
              f"{args.inits} inits, outward (< -0.5) on {heading['outward']}; solved by the "
              "untrained " + ", ".join(f"{mode} {n}/{episodes}" for mode, n in solved.items()),
              flush=True)


def first_solved(run_dir: Path, seed_steps: int, threshold: float) -> tuple[int | None, float, float, int]:
    """(index of the first training episode with a return above ``threshold`` or None, the
    reward earned before it in the warm-up (its first ``seed_steps`` env steps), after the
    warm-up, the number of episodes)."""
    episodes = training_episodes(run_dir)
    first = next((i for i, e in enumerate(episodes) if e.reward > threshold), None)
    before = episodes[:first]
    warm = sum(e.reward for e in before if e.end <= seed_steps)
    return first, warm, sum(e.reward for e in before) - warm, len(episodes)


def agent_label(options: RunOptions) -> str:
    """The agent's group, or ``plain`` (with its replay augmentation, if any)."""
    if options.agent.group:
        return options.agent.group
    return "plain" if options.agent.augment == "none" else f"plain, {options.agent.augment} augmentation"


def runs(args: argparse.Namespace) -> None:
    # agent: runs, solved at all, solved before EARNED, solved having earned exactly nothing
    found = defaultdict(lambda: [0, 0, 0, 0])
    for run_dir in args.run_dirs:
        try:
            options = RunOptions.from_run_dir(run_dir)
            if not options.env.name.startswith("pointmass"):
                raise SystemExit(f"{run_dir}: a run on {options.env.name!r}; this reads PointMass "
                                 "runs only")
            first, warm, after, episodes = first_solved(run_dir, options.train.seed_steps,
                                                        args.solved)
        except (OptionError, FileNotFoundError) as err:  # no config.yaml or train.csv
            raise SystemExit(str(err)) from None
        counts = found[agent_label(options)]
        counts[0] += 1
        if first is None:
            print(f"{run_dir}: never solved in {episodes} episodes; earned {warm:.3g} in the "
                  f"warm-up, {after:.3g} after", flush=True)
            continue
        counts[1] += 1
        counts[2] += warm + after < EARNED
        counts[3] += warm + after == 0
        print(f"{run_dir}: first solved episode {first + 1} of {episodes}; earned before it "
              f"{warm:.3g} in the warm-up, {after:.3g} after", flush=True)
    for agent, (total, solved, early, blind) in found.items():
        print(f"{agent}: {total} runs, {solved} solved an episode, {early} of them before "
              f"earning {EARNED:g} in all ({blind} having earned exactly 0)")
    # the prior is the untrained networks': augmented replay leaves them plain
    plain = [found[a] for a in found if a.startswith("plain")]
    equivariant = [found[a] for a in found if not a.startswith("plain")]
    if plain and equivariant:
        (total, early), (plain_total, plain_early) = (
            [sum(counts[i] for counts in side) for i in (0, 2)] for side in (equivariant, plain))
        p = fisher_exact([[early, total - early], [plain_early, plain_total - plain_early]]).pvalue
        print(f"solved before earning {EARNED:g}: equivariant networks {early} of {total} runs, "
              f"plain networks {plain_early} of {plain_total}; Fisher's exact test p = {p:.2g} "
              "(rough: the equivariant runs of one seed share their warm-up's random actions)")


def restored(args: argparse.Namespace) -> None:
    summary = defaultdict(lambda: {"runs": 0, "policy": [], "planner": [],
                                   "solved": {"policy": 0, "planner": 0}})
    for run_dir in args.run_dirs:
        try:
            run = checkpoint.restore_run(run_dir)
        except (OptionError, checkpoint.CheckpointError) as err:
            raise SystemExit(str(err)) from None
        if run.options.env.name not in TASKS:
            raise SystemExit(f"{run_dir}: a run on {run.options.env.name!r}; this reads "
                             f"{' and '.join(TASKS)} runs only")
        dim, step = symmetry_of(run.env).dim, run.state["agent_step"]
        starts = start_states(run.env, args.starts)
        policy = alignment(starts, run.agent.policy_action(torch.as_tensor(starts)).numpy(), dim)
        planner = alignment(starts, first_planned_actions(run.agent, starts, step), dim)
        # 0.0 exactly: reward and Q heads still at their zero init, so every plan ties
        flat = float(run.agent.value(torch.as_tensor(starts)).abs().max())
        found = summary[agent_label(run.options)]
        found["runs"] += 1
        found["policy"].append(np.abs(policy).mean())
        found["planner"].append(np.abs(planner).mean())
        cells = []
        for mode in ("policy", "planner") if args.episodes else ():
            returns = [episode_return(run.env, run.options.env.action_repeat, run.agent, 10**7 + e,
                                      mode == "planner", step) for e in range(args.episodes)]
            found["solved"][mode] += sum(r > args.solved for r in returns)
            cells.append(f"{mode} " + " ".join(f"{r:.0f}" for r in returns))
        print(f"{run_dir} (env step {run.state['env_step']}): at rest, the policy {cos_cell(policy)}, "
              f"the planner's first action {cos_cell(planner)}; max |V| at them {flat:.2g}"
              + ("; returns " + ", ".join(cells) if cells else ""), flush=True)
    for agent, found in summary.items():
        episodes = found["runs"] * args.episodes
        print(f"{agent}: {found['runs']} runs; mean |cos| at rest, policy "
              f"{min(found['policy']):.2f}-{max(found['policy']):.2f}, planner's first action "
              f"{min(found['planner']):.2f}-{max(found['planner']):.2f}"
              + (f"; solved by the policy {found['solved']['policy']}/{episodes}, by the planner "
                 f"{found['solved']['planner']}/{episodes}" if episodes else ""))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--solved", type=float, default=100.0,
                        help="an episode with a larger return counts as solved (default 100 of 1000)")
    sub = parser.add_subparsers(dest="command", required=True)
    fresh = sub.add_parser("untrained", help="fresh agents on the task's start states")
    fresh.add_argument("--env", choices=TASKS, default="pointmass3d")
    fresh.add_argument("--target-size", type=float, default=0.02,
                       help="PointMass3D's target radius (default 0.02, the paper's small target)")
    fresh.add_argument("--n-balls", type=int, default=1)
    fresh.add_argument("--groups", nargs="+", default=["none", "octahedral", "icosahedral"])
    fresh.add_argument("--inits", type=int, default=10, help="networks per group (seeds 0, 1, ...)")
    fresh.add_argument("--starts", type=int, default=200, help="start states for the alignment")
    fresh.add_argument("--episodes", type=int, default=2, help="episodes per network")
    fresh.add_argument("--planner", action="store_true", help="also act with the untrained planner")
    logged = sub.add_parser("runs", help="committed runs: the first solved episode and the reward before it")
    logged.add_argument("run_dirs", type=Path, nargs="+", metavar="RUN_DIR")
    checkpointed = sub.add_parser("restored", help="agents from their runs' checkpoints (e.g. stopped "
                                  "at the end of the warm-up: train.steps=train.seed_steps)")
    checkpointed.add_argument("run_dirs", type=Path, nargs="+", metavar="RUN_DIR")
    checkpointed.add_argument("--starts", type=int, default=50, help="start states for the alignment")
    checkpointed.add_argument("--episodes", type=int, default=4,
                              help="episodes per run and mode (0: the alignment only)")
    args = parser.parse_args()
    torch.set_num_threads(1)
    {"untrained": untrained, "runs": runs, "restored": restored}[args.command](args)


if __name__ == "__main__":
    main()
