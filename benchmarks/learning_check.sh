#!/usr/bin/env bash
# Learning check (BENCHMARKS.md): PointMass2D, CPU preset, plain vs D8, seeds 1-3,
# two runs at a time (one torch thread each). Interrupted runs resume when re-run.
#   bash benchmarks/learning_check.sh [steps]
set -euo pipefail
cd "$(dirname "$0")/.."
STEPS=${1:-30000}
OUT=results/learning_check/pointmass2d
for seed in 1 2 3; do for group in none D8; do
  echo "agent.group=$group seed=$seed train.steps=$STEPS train.progress=false hydra.run.dir=$OUT/$group/seed$seed"
done; done | xargs -P 2 -L 1 sh -c '.venv/bin/geomdp-train "$@" > /dev/null 2>&1; echo "done: $*"' _
