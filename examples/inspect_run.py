"""Replay a trained run's agent from its checkpoint and show where episodes end.

    python examples/inspect_run.py results/pointmass2d_cpu/D8/seed2 [--episodes 4] [--video out.mp4]

Prints, per episode, the first two observation coordinates at the start and
at the end (for PointMass2D: the mass's position) and the return, with the
planner in evaluation mode (no exploration noise). ``--video`` writes the
first episode as an MP4 (rendered headless).
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np
import torch
from omegaconf import OmegaConf

from agents.run import checkpoint
from agents.run.config import RunOptions
from agents.run.envs import make_gym_env
from agents.run.video import frames_per_second, write_video
from agents.tdmpc.agent import TDMPCAgent
from agents.tdmpc.replay import make_replay_buffer
from geomdp_envs import symmetry_of


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("run_dir", type=Path)
    parser.add_argument("--episodes", type=int, default=4)
    parser.add_argument("--seed", type=int, default=500)
    parser.add_argument("--video", type=Path, default=None, help="write the first episode to this MP4")
    args = parser.parse_args()
    torch.set_num_threads(1)
    options = RunOptions.from_config(OmegaConf.to_container(OmegaConf.load(args.run_dir / "config.yaml")))
    agent_cfg = options.agent
    env = make_gym_env(options.env,
                       render_mode="rgb_array" if args.video else None)
    agent = TDMPCAgent(agent_cfg, symmetry_of(env), env.observation_space.shape[0],
                       env.action_space.shape[0])
    state = checkpoint.load(args.run_dir, agent, make_replay_buffer(
        agent_cfg.replay, agent_cfg.horizon, agent_cfg.batch_size))
    if state is None:
        raise SystemExit(f"no checkpoint in {args.run_dir}")
    print(f"{args.run_dir}: agent at env step {state['env_step']}")
    for episode in range(args.episodes):
        obs, _ = env.reset(seed=args.seed + episode)
        start, total, done = obs[:2].copy(), 0.0, False
        frames = [] if args.video and episode == 0 else None
        agent.planner.reset()
        while not done:
            if frames is not None:
                frames.append(env.render())
            action = agent.act(torch.as_tensor(obs), state["agent_step"], explore=False).numpy()
            for _ in range(options.env.action_repeat):
                obs, reward, terminated, truncated, _ = env.step(action)
                total += reward
                done = terminated or truncated
                if done:
                    break
        print(f"episode {episode}: start {np.round(start, 3)} end {np.round(obs[:2], 3)} "
              f"return {total:.1f}")
        if frames is not None:
            frames.append(env.render())
            fps = frames_per_second(env, options.env.action_repeat)
            print(f"video: {write_video(args.video, frames, fps)} ({len(frames)} frames)")


if __name__ == "__main__":
    main()
