"""Agent steps per second (plan + update), equivariant vs plain, measured side by side.

TD-MPC makes one gradient update per agent step, so an agent step costs one
``plan`` (MPPI over the latent model) and one ``update`` (a batch of
horizon-length slices). For the CPU preset (``configs/agent/tdmpc.yaml``) this
measures both for the plain agent, the plain agent on symmetry-augmented replay
(``agent.augment=auto``: the cheap alternative to equivariant networks), D8 (PointMass2D,
Reacher hard) and icosahedral (PointMass3D) agents with both width strategies, the ``sqrt`` ones with their
hidden layers dense (escnn's expanded matrix: the reference) and in the irrep
basis (``FourierLinear``: the default), the continuous groups' agents (SO2, O2
beside D8; SO3, O3 beside icosahedral; default band limit and grid), plain,
octahedral and icosahedral ``linear`` agents on PointMass3D with 5 balls (the
N-ball experiment's largest task), and prints ratios to the plain agent on the
same task. It also counts the planner's FLOPs (as the dense expanded layers it stands
for) and compares its achieved FLOP rate with that of a plain
matrix product of the planner's batch and width; and it counts the arithmetic an
agent step actually does (matmul-type ops, irrep-basis transforms included, by
torch's FLOP formulas), so that a ratio to plain splits into "more arithmetic"
and "arithmetic done less efficiently".

Every configuration is measured in a fresh process, so none inherits another's
warm-up, allocator or thread state, once per round over ``--rounds`` rounds
(all configurations in turn, so that a change in the machine's load hits all
alike); each row reports medians, and its ratio to the plain agent per round.
``--baseline DIR`` also measures the plain agent of another checkout (e.g.
``git worktree add /tmp/landed <commit>``) in the same run, for "faster than
before" ratios. ``--devices cpu cuda`` measures every configuration on each device in the
same round (a device column; ratios to plain within a device, and each row's ratio to the
same configuration on the first device).

    python benchmarks/agent_speed.py [--threads 1] [--preset tdmpc] [--baseline /tmp/landed]
                                     [--only plain D8] [--tasks "pointmass3d 5 balls"]
                                     [--devices cpu cuda] [--overrides KEY=VALUE ...]
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import subprocess
import sys
from pathlib import Path
from statistics import median

ROOT = Path(__file__).resolve().parent.parent

# (task, label, agent overrides) in the order printed; the first of a task is its plain agent.
CONFIGS = [
    ("pointmass2d", "plain", ["agent.group=none"]),
    ("pointmass2d", "plain augmented", ["agent.group=none", "agent.augment=auto"]),
    ("pointmass2d", "D8 linear", ["agent.group=D8", "agent.width_strategy=linear"]),
    ("pointmass2d", "D8 sqrt (irrep basis)", ["agent.group=D8", "agent.width_strategy=sqrt",
                                              "agent.networks.layers=fourier"]),
    ("pointmass2d", "D8 sqrt (dense, reference)", ["agent.group=D8", "agent.width_strategy=sqrt",
                                                   "agent.networks.layers=dense"]),
    ("pointmass2d", "SO2 linear", ["agent.group=SO2", "agent.width_strategy=linear",
                                   "agent.allow_approximate=true"]),
    ("pointmass2d", "SO2 sqrt", ["agent.group=SO2", "agent.width_strategy=sqrt",
                                 "agent.allow_approximate=true"]),
    ("pointmass2d", "O2 linear", ["agent.group=O2", "agent.width_strategy=linear",
                                  "agent.allow_approximate=true"]),
    ("pointmass2d", "O2 sqrt", ["agent.group=O2", "agent.width_strategy=sqrt",
                                "agent.allow_approximate=true"]),
    # Reacher hard: where augmentation (by all of O(2)) and D8 differ in sample efficiency
    ("reacher", "plain", ["env.difficulty=hard", "agent.group=none"]),
    ("reacher", "plain augmented", ["env.difficulty=hard", "agent.group=none", "agent.augment=auto"]),
    ("reacher", "D8 linear", ["env.difficulty=hard", "agent.group=D8", "agent.width_strategy=linear"]),
    ("pointmass3d", "plain", ["agent.group=none"]),
    ("pointmass3d", "plain augmented", ["agent.group=none", "agent.augment=auto"]),
    ("pointmass3d", "icosahedral linear", ["agent.group=icosahedral", "agent.width_strategy=linear"]),
    ("pointmass3d", "icosahedral sqrt (irrep basis)", ["agent.group=icosahedral",
                                                       "agent.width_strategy=sqrt",
                                                       "agent.networks.layers=fourier"]),
    ("pointmass3d", "icosahedral sqrt (dense, reference)", ["agent.group=icosahedral",
                                                            "agent.width_strategy=sqrt",
                                                            "agent.networks.layers=dense"]),
    ("pointmass3d", "SO3 linear", ["agent.group=SO3", "agent.width_strategy=linear"]),
    ("pointmass3d", "SO3 sqrt", ["agent.group=SO3", "agent.width_strategy=sqrt"]),
    ("pointmass3d", "O3 linear", ["agent.group=O3", "agent.width_strategy=linear"]),
    ("pointmass3d", "O3 sqrt", ["agent.group=O3", "agent.width_strategy=sqrt"]),
    # the N-ball experiment's largest task (the paper's Figure 3), at its linear width
    ("pointmass3d 5 balls", "plain", ["agent.group=none"]),
    ("pointmass3d 5 balls", "octahedral linear", ["agent.group=octahedral",
                                                  "agent.width_strategy=linear"]),
    ("pointmass3d 5 balls", "icosahedral linear", ["agent.group=icosahedral",
                                                   "agent.width_strategy=linear"]),
]
LABELS = {label for _, label, _ in CONFIGS}  # what --only can name whole
TASKS = list(dict.fromkeys(task for task, _, _ in CONFIGS))  # what --tasks can name
# A task that is not an env config's name: the env config and its options.
TASK_ENVS = {"pointmass3d 5 balls": ("pointmass3d", ["env.n_balls=5", "env.target_size=0.03"])}

# Runs inside the measured checkout (its own agents package), with only the APIs
# that every version of it has; prints one JSON line.
MEASURE = r"""
import json, sys, time, gymnasium, torch
torch.set_num_threads(int(sys.argv[1])); torch.manual_seed(0)
gymnasium.logger.min_level = 40
from hydra import compose, initialize_config_dir
from omegaconf import OmegaConf
import geomdp_envs
from agents.cli.train import CONFIG_DIR
from agents.run.config import RunOptions, check_task
from agents.run.envs import make_gym_env, torchrl_env
from agents.run.trainer import REPLAY_KEYS
from agents.tdmpc.replay import make_replay_buffer, sample_slices
from agents.tdmpc.agent import TDMPCAgent
task, repeats, device, overrides = sys.argv[2], int(sys.argv[3]), sys.argv[4], sys.argv[5:]
sync = torch.cuda.synchronize if device.startswith("cuda") else (lambda: None)
with initialize_config_dir(config_dir=str(CONFIG_DIR), version_base="1.3"):
    cfg = compose("train", overrides=[f"env={task}", *overrides])
options = RunOptions.from_config(OmegaConf.to_container(cfg, resolve=True))
info = check_task(options)
agent_cfg = options.agent
env = torchrl_env(make_gym_env(options.env), options.env.action_repeat)
agent = TDMPCAgent(agent_cfg, info.symmetry, info.observation_size, info.action_size, device=device)
buffer = make_replay_buffer(agent_cfg.replay, agent_cfg.horizon, agent_cfg.batch_size)
td = env.rollout(1000, break_when_any_done=True)
td.set("episode", torch.zeros(td.shape[0], dtype=torch.int64))
buffer.extend(td.select(*REPLAY_KEYS))
obs = td["observation"][0]
def timed(fn):
    for _ in range(3):
        fn()
    sync()
    start = time.perf_counter()
    for _ in range(repeats):
        fn()
    sync()  # a GPU's queued kernels are part of the time
    return (time.perf_counter() - start) / repeats
act = lambda: agent.act(obs, step=10**6, explore=True)
learn = lambda: agent.update(sample_slices(buffer, agent_cfg.horizon))
# Warm up as training does, plans and updates alternating, before timing either, so
# that a plan is not timed in a process that has never sampled nor updated.
for _ in range(3):
    act(); learn()
plan = timed(act)
update = timed(learn)
def dense_flops(module):
    total = 0
    for m in module.modules():
        if isinstance(m, torch.nn.Linear):
            total += 2 * m.in_features * m.out_features
        elif hasattr(m, "in_type") and hasattr(m, "out_type"):
            total += 2 * m.in_type.size * m.out_type.size
    return total
p, m, h = agent_cfg.planner, agent.model, agent_cfg.horizon
n = p.num_samples + p.num_pi_trajs
flops = (dense_flops(m.encoder) + p.num_pi_trajs * h * (dense_flops(m.policy) + dense_flops(m.dynamics))
         + p.iterations * n * (h * (dense_flops(m.dynamics) + dense_flops(m.reward_net))
                               + dense_flops(m.policy) + dense_flops(m.qs)))
hidden = next(x for x in agent.networks.dynamics.modules() if hasattr(x, "out_type")
              or isinstance(x, torch.nn.Linear))
width = hidden.out_type.size if hasattr(hidden, "out_type") else hidden.out_features
a, b = torch.randn(n, width, device=device), torch.randn(width, width, device=device)
matmul = timed(lambda: a @ b)
# The arithmetic actually done (matmul-type ops, by torch's own FLOP formulas) in one
# plan and one update, untimed. A dispatch mode of our own: torch's FlopCounterMode
# also tracks modules, and its tracker tests TorchRL's modules for truth, which raises.
try:  # torch's private dispatch-mode base, behind agents.compat (checkouts from before it: direct)
    from agents.compat.torch import TorchDispatchMode
except ImportError:
    from torch.utils._python_dispatch import TorchDispatchMode
from torch.utils.flop_counter import flop_registry
class CountFlops(TorchDispatchMode):
    total = 0
    def __torch_dispatch__(self, func, types, args=(), kwargs=None):
        kwargs = kwargs or {}
        out = func(*args, **kwargs)
        formula = flop_registry.get(func.overloadpacket)
        if formula is not None:
            kwargs = {k: v for k, v in kwargs.items() if k != "out"}
            CountFlops.total += formula(*args, **kwargs, out_val=out)
        return out
with CountFlops():
    act(); learn()
print(json.dumps({"plan": plan, "update": update, "width": width,
                  "step_gflop": CountFlops.total / 1e9,
                  "planner_gflops": flops / plan / 1e9,
                  "matmul_gflops": 2 * n * width * width / matmul / 1e9}))
"""


def measure(tree: Path, task: str, overrides: list[str], threads: int, preset: str,
            repeats: int, device: str = "cpu") -> dict[str, float]:
    env, env_options = TASK_ENVS.get(task, (task, []))
    out = subprocess.run([sys.executable, "-c", MEASURE, str(threads), env, str(repeats), device,
                          f"agent={preset}", *env_options, *overrides],
                         cwd=tree, capture_output=True, text=True,
                         env={**os.environ, "RL_WARNINGS": "False",  # the measured tree first
                              "PYTHONPATH": os.pathsep.join(
                                  filter(None, [str(tree), os.environ.get("PYTHONPATH")]))})
    if out.returncode != 0:
        raise SystemExit(f"measuring {task} {overrides} in {tree} failed:\n{out.stderr[-2000:]}")
    return json.loads(out.stdout.strip().splitlines()[-1])


def picks(word: str, label: str) -> bool:
    """``--only``: a whole label picks itself only (``plain`` is not ``plain augmented``)."""
    return word == label if word in LABELS else word in label


def table(runs: dict[tuple[str, str, str], list[dict[str, float]]], devices: list[str]) -> str:
    """The markdown table: per (task, agent, device) the medians over rounds and the step
    time's ratio to that task's plain agent on the same device, per round in brackets;
    with several devices also the median per-round ratio to the same agent on the first.
    ``runs`` holds each task's plain agent first (the ratios' denominator)."""
    first = devices[0]
    versus = f" | x {first} step" if len(devices) > 1 else ""
    lines = ["| task | agent | device | hidden width | plan (ms) | update (ms) | agent step (ms) "
             f"| x plain step{versus} | GFLOP per step (x plain) | achieved GFLOP/s "
             "| planner GFLOP/s (dense-equivalent) | matmul GFLOP/s, same size |",
             "|---|---|---|---|---|---|---|---|---|---|---|---|" + ("---|" if versus else "")]
    plain: dict[tuple[str, str], tuple[list[float], float]] = {}
    for (task, label, device), rs in runs.items():
        steps = [r["plan"] + r["update"] for r in rs]
        plain.setdefault((task, device), (steps, rs[0]["step_gflop"]))
        ratios = [a / b for a, b in zip(steps, plain[task, device][0])]
        m = {key: median([r[key] for r in rs]) for key in rs[0]}
        spread = f" [{', '.join(f'{x:.2f}' for x in ratios)}]" if len(rs) > 1 else ""
        against = ""
        if versus:  # per round, the same configuration on the first device
            per_round = [a / (b["plan"] + b["update"]) for a, b in zip(steps, runs[task, label, first])]
            against = f" | {median(per_round):.3f}"
        lines.append(
            f"| {task} | {label} | {device} | {rs[0]['width']} | {m['plan'] * 1e3:.1f} "
            f"| {m['update'] * 1e3:.1f} | {median(steps) * 1e3:.1f} | {median(ratios):.2f}{spread}"
            f"{against} | {m['step_gflop']:.2f} ({m['step_gflop'] / plain[task, device][1]:.1f}) "
            f"| {m['step_gflop'] / median(steps):.1f} "
            f"| {m['planner_gflops']:.1f} | {m['matmul_gflops']:.1f} |")
    return "\n".join(lines)


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("--threads", type=int, default=1)
    parser.add_argument("--preset", default="tdmpc", help="agent config: tdmpc (CPU), tdmpc_paper")
    parser.add_argument("--repeats", type=int, default=10)
    parser.add_argument("--baseline", type=Path, default=None,
                        help="another checkout whose plain PointMass2D agent to measure alongside")
    parser.add_argument("--rounds", type=int, default=3,
                        help="each configuration (and the baseline, alternating with this checkout) "
                             "measured this many times; medians reported")
    parser.add_argument("--only", nargs="*", default=None,
                        help="measure only these agents: a word that is a whole label picks that "
                             "label ('plain'), any other picks the labels containing it ('D8')")
    parser.add_argument("--tasks", nargs="*", default=TASKS, choices=TASKS, metavar="TASK",
                        help=f"measure only these tasks (default: all): {', '.join(TASKS)}")
    parser.add_argument("--devices", nargs="+", default=["cpu"], metavar="DEVICE",
                        help="measure each configuration on each of these (cpu, cuda, cuda:<n>) in "
                             "the same round; with more than one, 'x <first> step' is the step "
                             "time's ratio to the same configuration on the first")
    parser.add_argument("--overrides", nargs="*", default=[], metavar="KEY=VALUE",
                        help="Hydra overrides added to every configuration (and the baseline), e.g. "
                             "agent.replay.prioritized=false")
    args = parser.parse_args()
    args.devices = list(dict.fromkeys(args.devices))
    import torch

    gpus = [d for d in args.devices if d.startswith("cuda")]
    if gpus and not torch.cuda.is_available():
        parser.error(f"--devices {' '.join(args.devices)}: no CUDA device here; valid: cpu")
    gpu = "".join(f", {d}: {torch.cuda.get_device_name(torch.device(d))}" for d in gpus)
    print(f"machine: {platform.machine()}, {os.cpu_count()} cores{gpu}, torch {torch.__version__}, "
          f"{args.threads} thread(s); agent preset {args.preset}\n")
    # Every configuration once per round, rounds repeated: a change in the machine's load
    # hits all of them alike, and each row reports its median over the rounds.
    selected = [c for c in CONFIGS if c[0] in args.tasks and (
        c[1] == "plain"  # every ratio's denominator
        or args.only is None or any(picks(word, c[1]) for word in args.only))]
    runs: dict[tuple[str, str, str], list[dict[str, float]]] = {
        (t, lab, d): [] for t, lab, _ in selected for d in args.devices}
    total, done = args.rounds * len(runs), 0
    for _ in range(args.rounds):
        for task, label, overrides in selected:
            for device in args.devices:
                r = measure(ROOT, task, [*overrides, *args.overrides], args.threads, args.preset,
                            args.repeats, device)
                runs[task, label, device].append(r)
                done += 1  # progress, and the numbers so far if the table never comes
                print(f"[{done}/{total}] {task} | {label} | {device}: agent step "
                      f"{(r['plan'] + r['update']) * 1e3:.1f} ms", file=sys.stderr, flush=True)
    print(f"median of {args.rounds} round(s); 'x plain step' per round in brackets\n")
    print(table(runs, args.devices), flush=True)
    if args.baseline:
        # Alternating rounds, so that a change in the machine's load hits both alike;
        # the medians are reported.
        before, after = [], []
        for _ in range(args.rounds):
            for tree, out in ((args.baseline, before), (ROOT, after)):
                r = measure(tree, "pointmass2d", ["agent.group=none", *args.overrides],
                            args.threads, args.preset, args.repeats, args.devices[0])
                out.append((r["plan"] + r["update"], r["plan"], r["update"]))
        (b, bp, bu), (a, ap, au) = sorted(before)[len(before) // 2], sorted(after)[len(after) // 2]
        print(f"\nplain PointMass2D agent step, median of {args.rounds} alternating rounds: "
              f"{args.baseline}: {b * 1e3:.1f} ms (plan {bp * 1e3:.1f}, update {bu * 1e3:.1f}); "
              f"this checkout: {a * 1e3:.1f} ms (plan {ap * 1e3:.1f}, update {au * 1e3:.1f}); "
              f"speed-up {b / a:.2f}x (per round: "
              + ", ".join(f"{x[0] / y[0]:.2f}x" for x, y in zip(before, after)) + ")")

if __name__ == "__main__":
    main()
