"""How a run's prioritised replay spreads its sampling: the slots still holding a zero TD error.

    python scripts/replay_priorities.py RUN_DIR/checkpoint/replay.pt --warmup-slots 5000

Reads the replay a checkpoint saved (``agents.tdmpc.replay.save_replay``) and prints,
for the first ``--warmup-slots`` slots (the random warm-up's agent steps) and the rest:
how many slots still hold a priority of TD error 0, which a slot keeps from the update
that wrote it until a later sample covers it (``agent.replay.priority_eps`` sets how
rarely such a slot is drawn), and each part's share of the sampling mass beside its share
of the slots. Priority quantiles follow. The priority exponent and offset are the run's
(``--alpha``, ``--eps``: the defaults are ``agent.replay``'s).
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np
import torch


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("replay", type=Path, help="a checkpoint's replay.pt")
    parser.add_argument("--warmup-slots", type=int, required=True,
                        help="agent steps of random warm-up (train.seed_steps / action repeat)")
    parser.add_argument("--alpha", type=float, default=0.6)
    parser.add_argument("--eps", type=float, default=1e-8)
    parser.add_argument("--zero", type=float, default=1e-6,
                        help="a TD error below this counts as zero")
    args = parser.parse_args()
    if not args.replay.is_file():
        raise SystemExit(f"{args.replay}: no such file (a checkpoint's replay.pt)")
    state = torch.load(args.replay, weights_only=False)
    if "priorities" not in state:
        raise SystemExit(f"{args.replay}: no priorities (uniform replay, or an empty buffer)")
    n = state["len"]
    mass = state["priorities"]["sum"].double().numpy()  # (TD error + eps) ** alpha per slot
    error = np.clip(mass ** (1 / args.alpha) - args.eps, 0, None)
    warmup = np.arange(n) < args.warmup_slots
    print(f"{args.replay}: {n} slots, alpha {args.alpha}, eps {args.eps:g}")
    for name, part in (("warm-up", warmup), ("after", ~warmup)):
        if not part.any():
            continue
        zero = error[part] < args.zero
        print(f"{name:>8}: {part.sum()} slots ({part.mean():.1%}); zero TD error: {zero.sum()} "
              f"({zero.mean():.2%}); share of the sampling mass {mass[part].sum() / mass.sum():.1%}; "
              f"priority^alpha quantiles 1/10/50/90/99%: "
              + " ".join(f"{q:.3g}" for q in np.quantile(mass[part], [.01, .1, .5, .9, .99])))


if __name__ == "__main__":
    main()
