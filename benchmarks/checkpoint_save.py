"""Cost of an agent's checkpoint state (``TDMPCAgent.state_dict``), and of its basis
fingerprints computed two ways, side by side in one process: by the layers' forward
(what the agent does) and by expanding every layer's dense weight (what it did before,
the reference). Paper preset (``agent=tdmpc_paper``) unless overridden.

    .venv/bin/python benchmarks/checkpoint_save.py [--group D8] [--env pointmass2d] [--seconds 3]
"""

from __future__ import annotations

import argparse

import torch
from hydra import compose, initialize_config_dir
from omegaconf import OmegaConf
from timing import best_time

from agents.cli.train import CONFIG_DIR
from agents.nn.spectral import GridActivation
from agents.run.config import RunOptions, check_task
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


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--group", default="D8")
    parser.add_argument("--env", default="pointmass2d")
    parser.add_argument("--preset", default="tdmpc_paper")
    parser.add_argument("--seconds", type=float, default=3.0, help="timing budget per measurement")
    args = parser.parse_args()
    torch.set_num_threads(1)
    with initialize_config_dir(config_dir=str(CONFIG_DIR), version_base="1.3"):
        cfg = compose("train", overrides=[f"env={args.env}", f"agent={args.preset}",
                                          f"agent.group={args.group}"])
    options = RunOptions.from_config(OmegaConf.to_container(cfg, resolve=True))
    task = check_task(options)
    print(f"building the {args.preset} {args.group} agent on {args.env} ...", flush=True)
    agent = TDMPCAgent(options.agent, task.symmetry, task.observation_size, task.action_size)
    forward = agent.basis_fingerprints()
    reference = expanded_fingerprints(agent)
    worst = max(float((forward[k] - reference[k]).abs().max() / reference[k].abs().max().clamp(min=1e-12))
                for k in reference)
    t_forward = best_time(agent.basis_fingerprints, args.seconds, 3)
    t_expand = best_time(lambda: expanded_fingerprints(agent), args.seconds, 3)
    t_state = best_time(agent.state_dict, args.seconds, 3)
    print(f"{len(forward)} fingerprints; largest relative difference forward vs expanded: {worst:.1e}")
    print(f"fingerprints by forward:   {t_forward * 1e3:8.1f} ms")
    print(f"fingerprints by expansion: {t_expand * 1e3:8.1f} ms   ({t_expand / t_forward:.1f}x)")
    print(f"state_dict (all of it):    {t_state * 1e3:8.1f} ms")


if __name__ == "__main__":
    main()
