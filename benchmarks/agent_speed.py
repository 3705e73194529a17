"""Agent steps per second (plan + update), equivariant vs plain, measured side by side.

TD-MPC makes one gradient update per agent step, so an agent step costs one
``plan`` (MPPI over the latent model) and one ``update`` (a batch of
horizon-length slices). For the CPU preset (``configs/agent/tdmpc.yaml``) this
measures both for the plain agent and for D8 (PointMass2D) and icosahedral
(PointMass3D) agents under both width strategies, and prints ratios to the
plain agent on the same task. It also counts the planner's FLOPs (the expanded
linear layers it evaluates) and compares its achieved FLOP rate with that of a
plain matrix product of the planner's batch and width on this machine.

    python benchmarks/agent_speed.py [--threads 1] [--preset tdmpc]
"""

from __future__ import annotations

import argparse
import os
import platform
import time

import gymnasium
import torch
from hydra import compose, initialize_config_dir
from omegaconf import OmegaConf

import geomdp_envs  # noqa: F401
from agents import train
from agents.layers import EquivariantLinear
from agents.replay import make_replay_buffer, sample_slices
from agents.tdmpc import TDMPCAgent, TDMPCConfig
from agents.train import CONFIG_DIR, REPLAY_KEYS, make_env

TASKS = {"PointMass2D": ("pointmass2d", ["none", "D8"]),
         "PointMass3D": ("pointmass3d", ["none", "icosahedral"])}


def agent_config(preset: str, group: str, strategy: str) -> TDMPCConfig:
    """The agent options ``geomdp-train agent=<preset>`` would use."""
    with initialize_config_dir(config_dir=str(CONFIG_DIR), version_base="1.3"):
        cfg = compose("train", overrides=[f"agent={preset}", f"agent.group={group}",
                                          f"agent.width_strategy={strategy}"])
    return train.agent_config(cfg)


def linear_flops(module: torch.nn.Module) -> int:
    """FLOPs of one sample through every linear layer of ``module``."""
    total = 0
    for m in module.modules():
        if isinstance(m, torch.nn.Linear):
            total += 2 * m.in_features * m.out_features
        elif isinstance(m, EquivariantLinear):
            total += 2 * m.in_type.size * m.out_type.size
    return total


def planner_flops(agent: TDMPCAgent) -> float:
    cfg, model, h = agent.config.planner, agent.model, agent.config.horizon
    n = cfg.num_samples + cfg.num_pi_trajs
    step = linear_flops(model.dynamics) + linear_flops(model.reward_net)
    terminal = linear_flops(model.policy) + linear_flops(model.qs)
    pi_rollout = cfg.num_pi_trajs * h * (linear_flops(model.policy) + linear_flops(model.dynamics))
    return linear_flops(model.encoder) + pi_rollout + cfg.iterations * n * (h * step + terminal)


def timed(fn, repeats: int) -> float:  # noqa: ANN001
    fn()
    start = time.perf_counter()
    for _ in range(repeats):
        fn()
    return (time.perf_counter() - start) / repeats


def matmul_rate(rows: int, width: int) -> float:
    """GFLOP/s of a plain [rows, width] @ [width, width] product."""
    a, b = torch.randn(rows, width), torch.randn(width, width)
    seconds = timed(lambda: a @ b, 50)
    return 2 * rows * width * width / seconds / 1e9


def measure(task: str, group: str, strategy: str, preset: str, repeats: int) -> dict[str, float]:
    env_cfg = OmegaConf.load(CONFIG_DIR / "env" / f"{task}.yaml")
    env, symmetry = make_env(env_cfg)
    cfg = agent_config(preset, group, strategy)
    obs_size = env.observation_spec["observation"].shape[-1]
    agent = TDMPCAgent(cfg, symmetry, obs_size, env.action_spec.shape[-1])
    buffer = make_replay_buffer(cfg.replay, cfg.horizon, cfg.batch_size)
    td = env.rollout(1000, break_when_any_done=True)
    td.set("episode", torch.zeros(td.shape[0], dtype=torch.int64))
    buffer.extend(td.select(*REPLAY_KEYS))
    obs = td["observation"][0]
    plan = timed(lambda: agent.act(obs, step=10**6, explore=True), repeats)
    update = timed(lambda: agent.update(sample_slices(buffer, cfg.horizon)), repeats)
    hidden = agent.networks.dynamics.net[0]
    width = hidden.out_type.size if isinstance(hidden, EquivariantLinear) else hidden.out_features
    n = cfg.planner.num_samples + cfg.planner.num_pi_trajs
    return {"plan": plan, "update": update, "steps_per_s": 1 / (plan + update),
            "planner_gflops": planner_flops(agent) / plan / 1e9,
            "matmul_gflops": matmul_rate(n, width), "width": width}


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("--threads", type=int, default=1)
    parser.add_argument("--preset", default="tdmpc", help="agent config: tdmpc (CPU), tdmpc_paper")
    parser.add_argument("--repeats", type=int, default=10)
    args = parser.parse_args()
    torch.set_num_threads(args.threads)
    torch.manual_seed(0)
    gymnasium.logger.min_level = 40
    print(f"machine: {platform.machine()}, {os.cpu_count()} cores, torch {torch.__version__}, "
          f"{args.threads} thread(s); agent preset {args.preset}\n")
    print("| task | agent | hidden width | plan (ms) | update (ms) | agent steps/s (x plain) "
          "| planner GFLOP/s | matmul GFLOP/s, same size |")
    print("|---|---|---|---|---|---|---|---|")
    for name, (task, group_names) in TASKS.items():
        plain = None
        for group in group_names:
            for strategy in (["sqrt"] if group == "none" else ["sqrt", "linear"]):
                r = measure(task, group, strategy, args.preset, args.repeats)
                plain = plain or r
                label = "plain" if group == "none" else f"{group} {strategy}"
                print(f"| {name} | {label} | {r['width']} | {r['plan'] * 1e3:.1f} "
                      f"| {r['update'] * 1e3:.1f} | {r['steps_per_s']:.1f} "
                      f"({r['steps_per_s'] / plain['steps_per_s']:.2f}) "
                      f"| {r['planner_gflops']:.1f} | {r['matmul_gflops']:.1f} |")


if __name__ == "__main__":
    main()
