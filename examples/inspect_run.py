"""Replay a trained run's agent from its checkpoint: where episodes end, and whether Q is right.

    python examples/inspect_run.py results/pointmass2d_cpu/D8/seed2 [--episodes 4]
        [--evaluation] [--only I ...] [--policy | --explore] [--rotate DEG] [--reflect]
        [--final-observation] [--q-heads] [--policy-after K] [--plan-values] [--video a.mp4]

Prints, per episode, the first two observation coordinates at the start and
at the end (for PointMass2D: the mass's position), how far each rewarded body is
from its target at the start and at the end (the finger on Reacher, every ball on
PointMass3D: which balls an N-ball agent brings in), and the return, with the
planner in evaluation mode (no exploration noise), with the training episodes'
exploration noise (``--explore``: the noise schedule at the checkpoint's step, as
the run's noisy evaluation episodes plan), or with the learned policy alone
(``--policy``). Then the agent's value estimate against what it got:
Q(s, pi(s)) at the first state, and averaged over the episode's states, beside
the discounted return from there (``bootstrapped_returns``: rewards per agent
step, the state after the time limit valued at the agent's own Q, as its TD
targets do). A Q far above the return where the episode earned nothing is
value overestimation, not a model the planner could trust. Then what the
agent's reward model predicts for the episode's states and actions against the
rewards earned: reward the model sees where there is none points at the model,
an optimistic Q with a truthful reward model at the value. ``--final-observation``
prints each episode's last observation whole (where every ball ended: a spot an agent
parks a ball at shows there). ``--q-heads`` prints each Q head at the first state
(the value is their minimum: a low value from one pessimistic head shows there) and,
over the episode's last tenth, Q against ``r / (1 - discount)``, what earning that
tenth's mean reward r forever is worth: where an agent holds its bodies at the target,
a Q below it is what a value still converging to its fixed point shows (a bias can show
the same; the run's Q over time, in ``train.csv``, tells them apart). Where the planner
fails a start, ``--policy-after K`` hands the episode to the policy alone after K agent
steps (does pi finish what the planner would not?), and ``--plan-values`` prints how each
plan valued its best Gaussian sample against the policy's best proposal: a sample valued
above every proposal, in an episode that earns nothing, is the planner trusting its model
or Q where the policy does not go. ``--video`` writes
the first episode as an MP4 (rendered headless). ``--evaluation`` starts episode
i where every evaluation of the run started its episode i (the trainer's seeds,
drawn as the trainer draws them), to look at the episodes its ``eval.csv``
averages; the planner's noise is this replay's own, not the evaluation's.
``--rotate DEG`` and ``--reflect`` move every start state by a group element before
the episode (``transform_state``, as ``check_symmetry`` moves states): a rotation by DEG
about the arena's vertical axis, after a reflection y -> -y. An exactly equivariant
agent acts on the moved start as on the original, up to the planner's sampling noise,
so where an episode fails this separates a start the agent cannot solve in any
orientation from one that an approximately equivariant agent (D8 for O(2)) fails in
some orientations only; an element outside the task's exact group (walls, joint limits)
is said, as such a start may be one the task never draws.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import gymnasium
import numpy as np
import torch

from agents.options import OptionError
from agents.run import checkpoint
from agents.run.envs import torchrl_env
from agents.run.td_invariants import bootstrapped_returns
from agents.run.trainer import evaluation_episode_seed
from agents.run.video import frames_per_second, write_video
from agents.tdmpc.agent import TDMPCAgent
from geomdp_envs import groups


def start_transform(env: gymnasium.Env, degrees: float | None, reflect: bool) -> np.ndarray | None:
    """The orthogonal matrix ``--rotate``/``--reflect`` ask for (None: neither), after
    checking that the task can move its state and that its group holds the element."""
    if degrees is None and not reflect:
        return None
    task = env.unwrapped
    if not hasattr(task, "transform_state"):
        raise SystemExit(f"--rotate/--reflect: {type(task).__name__} cannot move its state by a "
                         "group element (no transform_state); GeoMDP's tasks and declared "
                         "MuJoCo tasks can")
    symmetry = task.symmetry
    angle = np.radians(degrees or 0.0)
    rotation = (groups.rotation_2d(angle) if symmetry.dim == 2
                else groups.rotation_3d(np.array([0.0, 0.0, 1.0]), angle))
    flip = np.eye(symmetry.dim)
    if reflect:
        flip[1, 1] = -1.0
    g = rotation @ flip
    if not groups.contains(symmetry.continuous_group, g):
        raise SystemExit(f"--reflect: the task is symmetric under {symmetry.continuous_group}, "
                         "which has no reflections; valid: --rotate alone")
    exact = ("" if groups.contains(symmetry.exact_group, g)
             else f"; not in the task's exact group {symmetry.exact_group}")
    print(f"start states moved by: rotation {degrees or 0.0:g} deg"
          f"{' after reflection y -> -y' if reflect else ''}{exact}")
    return g


def moved_start(env: gymnasium.Env, g: np.ndarray) -> np.ndarray:
    """Move the env's current (start) state by ``g``; the observation there."""
    task = env.unwrapped
    task.set_state(task.transform_state(task.get_state(), g))
    return task.observe().astype(env.observation_space.dtype)


def distances_to_target(env: gymnasium.Env) -> np.ndarray | None:
    """Each rewarded body's distance to its target, where the task says it (GeoMDP's do)."""
    distances = getattr(env.unwrapped, "distances_to_target", None)
    return None if distances is None else distances()


def distance_change(start: np.ndarray | None, end: np.ndarray | None) -> str:
    """`` distance to target 0.21 -> 0.004`` (one per ball), or nothing for a task without."""
    if start is None or end is None:
        return ""
    return f" distance to target {rounded(start)} -> {rounded(end)}"


def last_tenth(values: list[float], rewards: list[float], discount: float) -> tuple[float, float]:
    """Mean Q over the episode's last tenth of agent steps, and the value of earning that
    tenth's mean reward forever, ``r / (1 - discount)``: equal at the TD fixed point where
    the reward has settled (a body held at its target)."""
    tail = max(1, len(rewards) // 10)
    return float(np.mean(values[-tail:])), float(np.mean(rewards[-tail:])) / (1.0 - discount)


def replay_action(agent: TDMPCAgent, obs: torch.Tensor, t: int, agent_step: int,
                  args: argparse.Namespace, plan_gaps: list[float]) -> np.ndarray:
    """The replay's action at the episode's agent step ``t``: the policy's under
    ``--policy`` or once ``--policy-after`` has passed, else the planner's (recording how far
    its best sample was valued above the policy's best proposal)."""
    if args.policy or (args.policy_after is not None and t >= args.policy_after):
        return agent.policy_action(obs).numpy()
    action, values = agent.act_with_values(obs, agent_step, explore=args.explore)
    if values.best_proposed is not None:
        plan_gaps.append(float(values.best_sampled - values.best_proposed))
    return action.numpy()


def plan_values_line(plan_gaps: list[float], planned: int) -> str:
    if not plan_gaps:
        return "  planner: no policy proposals to compare with (agent.planner.num_pi_trajs = 0)"
    return (f"  planner: best sample valued {np.mean(plan_gaps):+.1f} against the policy's best "
            f"proposal, mean over {planned} plans (min {min(plan_gaps):+.1f}, "
            f"max {max(plan_gaps):+.1f})")


def rounded(distances: np.ndarray) -> str:
    return f"{distances[0]:.3f}" if len(distances) == 1 else str(np.round(distances, 3))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("run_dir", type=Path)
    parser.add_argument("--episodes", type=int, default=4)
    parser.add_argument("--only", type=int, nargs="+", metavar="I", default=None,
                        help="replay only these episodes (numbered as --episodes counts them: "
                             "evaluation episode I, or seed SEED + I); --episodes unused")
    parser.add_argument("--seed", type=int, default=500, help="episode i resets with seed SEED + i")
    parser.add_argument("--evaluation", action="store_true",
                        help="start from the run's evaluation start states instead (--seed unused)")
    acting = parser.add_mutually_exclusive_group()
    acting.add_argument("--policy", action="store_true",
                        help="act with the learned policy's mean action instead of planning")
    acting.add_argument("--explore", action="store_true",
                        help="plan with the training episodes' exploration noise")
    parser.add_argument("--rotate", type=float, default=None, metavar="DEG",
                        help="rotate every start state by DEG degrees (about the vertical axis in 3D)")
    parser.add_argument("--reflect", action="store_true",
                        help="reflect every start state y -> -y (before --rotate)")
    parser.add_argument("--final-observation", action="store_true",
                        help="print each episode's last observation whole (e.g. where every "
                             "ball ended)")
    parser.add_argument("--q-heads", action="store_true",
                        help="print each Q head at the first state, and Q over the episode's "
                             "last tenth against r / (1 - discount) for its mean reward r")
    parser.add_argument("--policy-after", type=int, default=None, metavar="K",
                        help="plan the first K agent steps of each episode, then act with the "
                             "policy alone")
    parser.add_argument("--plan-values", action="store_true",
                        help="print how each plan valued its best sample against the policy's "
                             "best proposal")
    parser.add_argument("--video", type=Path, default=None, help="write the first episode to this MP4")
    args = parser.parse_args()
    if args.policy and (args.policy_after is not None or args.plan_values):
        raise SystemExit("--policy plans nothing: --policy-after K and --plan-values need the "
                         "planner (drop --policy)")
    if args.policy_after is not None and args.policy_after < 0:
        raise SystemExit(f"--policy-after {args.policy_after}: K counts agent steps, 0 or more")
    torch.set_num_threads(1)
    try:
        run = checkpoint.restore_run(args.run_dir, render_mode="rgb_array" if args.video else None)
    except (OptionError, checkpoint.CheckpointError) as err:
        raise SystemExit(str(err)) from None
    options, env, agent, state = run.options, run.env, run.agent, run.state
    agent_cfg = options.agent
    print(f"{args.run_dir}: agent at env step {state['env_step']}")
    transform = start_transform(env, args.rotate, args.reflect)
    discount = agent_cfg.loss.discount
    # resets env as the trainer does (TorchRL's seeding, then a reset)
    trainer_env = torchrl_env(env, options.env.action_repeat) if args.evaluation else None
    episodes = args.only if args.only is not None else list(range(args.episodes))
    if any(episode < 0 for episode in episodes):
        raise SystemExit(f"--only {' '.join(map(str, episodes))}: episode numbers start at 0")
    for episode in episodes:
        if trainer_env is not None:
            trainer_env.set_seed(evaluation_episode_seed(options.seed, episode))
            obs = trainer_env.reset()["observation"].numpy()
        else:
            obs, _ = env.reset(seed=args.seed + episode)
        if transform is not None:
            obs = moved_start(env, transform)
        start, done, terminated = obs[:2].copy(), False, False
        start_distances = distances_to_target(env)
        values, rewards, observations, actions = [], [], [], []  # per agent step
        plan_gaps: list[float] = []
        first_heads = agent.q_heads(torch.as_tensor(obs)) if args.q_heads else None
        frames = [] if args.video and episode == episodes[0] else None
        agent.start_episode()
        while not done:
            if frames is not None:
                frames.append(env.render())
            obs_t = torch.as_tensor(obs)
            values.append(float(agent.value(obs_t)))
            action = replay_action(agent, obs_t, len(rewards), state["agent_step"], args, plan_gaps)
            observations.append(obs_t)
            actions.append(torch.as_tensor(action))
            rewards.append(0.0)
            for _ in range(options.env.action_repeat):
                obs, reward, terminated, truncated, _ = env.step(action)
                rewards[-1] += reward
                done = terminated or truncated
                if done:
                    break
        final_value = 0.0 if terminated else float(agent.value(torch.as_tensor(obs)))
        returns = bootstrapped_returns(rewards, discount, final_value)
        print(f"episode {episode}: start {np.round(start, 3)} end {np.round(obs[:2], 3)}"
              f"{distance_change(start_distances, distances_to_target(env))}; "
              f"return {sum(rewards):.1f}; Q(s_0, pi) {values[0]:.1f} vs discounted return "
              f"{returns[0]:.1f}, mean over the episode {np.mean(values):.1f} vs {np.mean(returns):.1f}")
        if first_heads is not None:
            tail_q, settled = last_tenth(values, rewards, discount)
            print(f"  Q heads at s_0: {np.round(first_heads.cpu().numpy(), 1)}; last tenth of "
                  f"the episode: Q {tail_q:.1f} vs {settled:.1f}, its mean reward forever")
        planned = len(rewards) if args.policy_after is None else min(args.policy_after, len(rewards))
        if args.policy_after is not None:
            print(f"  policy alone from agent step {args.policy_after}: earned "
                  f"{sum(rewards[planned:]):.1f} (the planner before it: {sum(rewards[:planned]):.1f})")
        if args.plan_values and planned:
            print(plan_values_line(plan_gaps, planned))
        if args.final_observation:
            print(f"  final observation: {np.array2string(np.round(obs, 3), max_line_width=10**6)}")
        predicted = agent.predicted_reward(torch.stack(observations), torch.stack(actions)).cpu().numpy()
        print(f"  reward model: {predicted.sum():.1f} predicted over the episode vs "
              f"{sum(rewards):.1f} earned; at the steps that earned nothing "
              f"{predicted[np.array(rewards) == 0].sum():.1f}")
        if frames is not None:
            frames.append(env.render())
            fps = frames_per_second(env, options.env.action_repeat)
            print(f"video: {write_video(args.video, frames, fps)} ({len(frames)} frames)")


if __name__ == "__main__":
    main()
