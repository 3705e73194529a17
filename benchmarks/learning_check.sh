#!/usr/bin/env bash
# PointMass2D learning check (RESULTS.md): CPU preset, 30k environment steps,
# plain, D4 and D8 (`linear` width) with seeds 1-5, then D8 `sqrt` with seeds 1-3.
# Runs are interleaved by seed so that a cut-off leaves balanced groups; two at a
# time, one torch thread each (benchmarks/run_queue.sh: finished runs are skipped,
# interrupted ones resume).
#   bash benchmarks/learning_check.sh [out_dir] [steps]
set -euo pipefail
OUT=${1:-results/pointmass2d_cpu}
STEPS=${2:-30000}
{
  for seed in 1 2 3 4 5; do
    echo "$OUT/plain/seed$seed $STEPS agent.group=none agent.width_strategy=linear seed=$seed"
    echo "$OUT/D8/seed$seed $STEPS agent.group=D8 agent.width_strategy=linear seed=$seed"
    echo "$OUT/D4/seed$seed $STEPS agent.group=D4 agent.width_strategy=linear seed=$seed"
  done
  for seed in 1 2 3; do
    echo "$OUT/D8_sqrt/seed$seed $STEPS agent.group=D8 agent.width_strategy=sqrt seed=$seed"
  done
} | bash "$(dirname "$0")/run_queue.sh"
