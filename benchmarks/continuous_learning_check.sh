#!/usr/bin/env bash
# Continuous groups learning check (RESULTS.md, issue 12): CPU preset, `linear` width,
# seeds 1-3, interleaved by seed, two runs at a time (benchmarks/run_queue.sh).
# - PointMass2D, 30k steps: plain vs O2 vs D8 (plain and D8 share the runs of
#   learning_check.sh); O(2) is only approximate there (the walls keep D4), so
#   agent.allow_approximate=true.
# - PointMass3D, 1 ball, target 0.02, 50k steps: plain vs SO3 vs icosahedral.
#   bash benchmarks/continuous_learning_check.sh [out_2d] [out_3d]
set -euo pipefail
OUT2=${1:-results/pointmass2d_cpu}
OUT3=${2:-results/pointmass3d_small_target_cpu}
TASK3="env=pointmass3d env.target_size=0.02"
{
  for seed in 1 2 3; do
    echo "$OUT2/O2/seed$seed 30000 agent.group=O2 agent.allow_approximate=true agent.width_strategy=linear seed=$seed"
    echo "$OUT2/plain/seed$seed 30000 agent.group=none agent.width_strategy=linear seed=$seed"
    echo "$OUT2/D8/seed$seed 30000 agent.group=D8 agent.width_strategy=linear seed=$seed"
  done
  for seed in 1 2 3; do
    for group in none SO3 icosahedral; do
      label=$group; [ "$group" = none ] && label=plain
      echo "$OUT3/$label/seed$seed 50000 $TASK3 agent.group=$group agent.width_strategy=linear seed=$seed"
    done
  done
} | bash "$(dirname "$0")/run_queue.sh"
