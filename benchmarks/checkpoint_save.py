"""Cost of writing a run's checkpoint (agents.run.checkpoint.save), and of its parts.

A real save, as the trainer makes one after every episode, to a temporary run directory:
once with an empty replay (the first checkpoint) and once with the replay that a run of
``--env-steps`` environment steps holds at its last checkpoint (real transitions of the
task, random actions). Beside it, in the same process, its parts: the agent's state
(``TDMPCAgent.state_dict``) and its basis fingerprints, computed by the layers' forward
(what the agent does) and by expanding every layer's dense weight (what it did before,
the reference). Paper preset (``agent=tdmpc_paper``) unless overridden.

    .venv/bin/python benchmarks/checkpoint_save.py [--group D8] [--env pointmass2d] \
        [--preset tdmpc_paper] [--env-steps 30000] [--seconds 3]
"""

from __future__ import annotations

import argparse
import tempfile
from pathlib import Path

import torch
from omegaconf import OmegaConf
from timing import best_time

from agents.nn.spectral import GridActivation
from agents.run import checkpoint
from agents.run.checkpoint_state import checkpoint_paths
from agents.run.config import RunOptions, check_task
from agents.run.presets import compose_config
from agents.run.trainer import REPLAY_KEYS, build_parts
from agents.tdmpc.agent import TDMPCAgent, _probe


@torch.no_grad()
def expanded_fingerprints(agent: TDMPCAgent) -> dict[str, torch.Tensor]:
    """The reference: W p + b with W expanded densely, for every equivariant layer."""
    out = {}
    for name, module in agent.model.named_modules():
        if hasattr(module, "expand") and hasattr(module, "in_type"):
            weight, bias = module.expand()
            mapped = weight.double().cpu() @ _probe(weight.shape[1])
            out[name] = mapped + (0 if bias is None else bias.double().cpu())
        elif isinstance(module, GridActivation):
            out[name] = module.to_grid.double().cpu().T @ _probe(module.to_grid.shape[0])
    return out


def fill_replay(parts, env_steps: int, action_repeat: int) -> int:
    """Put ``env_steps`` environment steps into the replay, as the trainer does (one
    episode id per episode); the episodes repeat one random-action rollout of the task.
    Returns the number of transitions stored."""
    episode = parts.env.rollout(10_000, break_when_any_done=True).select(*REPLAY_KEYS, strict=False)
    length, n = episode.shape[0], 0
    while n * action_repeat < env_steps:
        episode.set("episode", torch.full((length,), n // length, dtype=torch.int64))
        parts.buffer.extend(episode.select(*REPLAY_KEYS))
        n += length
    return n


def checkpoint_megabytes(run_dir: Path) -> float:
    return sum(p.stat().st_size for p in checkpoint_paths(run_dir)[0].rglob("*") if p.is_file()) / 1e6


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--group", default="D8")
    parser.add_argument("--env", default="pointmass2d")
    parser.add_argument("--preset", default="tdmpc_paper")
    parser.add_argument("--env-steps", type=int, default=30000,
                        help="environment steps the replay holds for the second save (default: "
                             "train.steps' default, the last checkpoint of a CPU-preset run)")
    parser.add_argument("--seconds", type=float, default=3.0, help="timing budget per measurement")
    args = parser.parse_args()
    torch.set_num_threads(1)
    cfg = compose_config([f"env={args.env}", f"agent={args.preset}", f"agent.group={args.group}"])
    options = RunOptions.from_config(OmegaConf.to_container(cfg, resolve=True))
    task = check_task(options)
    print(f"building the {args.preset} {args.group} agent on {args.env} ...", flush=True)
    parts = build_parts(options, task)
    agent, buffer = parts.agent, parts.buffer
    forward = agent.basis_fingerprints()
    reference = expanded_fingerprints(agent)
    worst = max((float((forward[k] - reference[k]).abs().max() / reference[k].abs().max().clamp(min=1e-12))
                 for k in reference), default=0.0)
    t_forward = best_time(agent.basis_fingerprints, args.seconds, 3)
    t_expand = best_time(lambda: expanded_fingerprints(agent), args.seconds, 3)
    t_state = best_time(agent.state_dict, args.seconds, 3)
    loop_state = {"env_step": 0, "agent_step": 0, "episode": 0, "pending_updates": 0, "wall_time": 0.0,
                  "last_eval_step": None, "last_eval_reward": None, "last_checkpoint_step": 0}
    saves = []
    with tempfile.TemporaryDirectory() as tmp:
        run_dir = Path(tmp)
        for label in ("empty replay", f"replay of {args.env_steps} env steps"):
            if label != "empty replay":
                stored = fill_replay(parts, args.env_steps, options.env.action_repeat)
                label = f"replay of {args.env_steps} env steps ({stored} transitions)"

            def save() -> None:
                checkpoint.save(run_dir, agent, buffer, loop_state, options.checkpoint_options())

            seconds = best_time(save, args.seconds, 3)
            saves.append((label, seconds, checkpoint_megabytes(run_dir)))
    print(f"{len(forward)} fingerprints; largest relative difference forward vs expanded: {worst:.1e}")
    print(f"fingerprints by forward:   {t_forward * 1e3:8.1f} ms")
    if t_forward > 0 and reference:
        print(f"fingerprints by expansion: {t_expand * 1e3:8.1f} ms   ({t_expand / t_forward:.1f}x)")
    print(f"state_dict (all of it):    {t_state * 1e3:8.1f} ms")
    for label, seconds, megabytes in saves:
        print(f"checkpoint.save:           {seconds * 1e3:8.1f} ms   ({megabytes:.1f} MB on disk; {label})")


if __name__ == "__main__":
    main()
