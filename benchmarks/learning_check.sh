#!/usr/bin/env bash
# PointMass2D learning check (RESULTS.md): CPU preset, 30k environment steps,
# plain, D4 and D8 (`linear` width) with seeds 1-5, then D8 `sqrt` with seeds 1-3.
# Runs are interleaved by seed so that a cut-off leaves balanced groups; two at a
# time, one torch thread each. An interrupted run resumes from its checkpoint
# when this script is run again; finished runs are skipped.
#   bash benchmarks/learning_check.sh [out_dir] [steps]
set -euo pipefail
cd "$(dirname "$0")/.."
OUT=${1:-results/pointmass2d_cpu}
STEPS=${2:-30000}
PYTHON=${PYTHON:-$(pwd)/.venv/bin/python}
jobs() {
  for seed in 1 2 3 4 5; do
    echo "none linear $seed"; echo "D8 linear $seed"; echo "D4 linear $seed"
  done
  for seed in 1 2 3; do echo "D8 sqrt $seed"; done
}
jobs | while read -r group width seed; do
  label=$group; [ "$group" = none ] && label=plain; [ "$width" = sqrt ] && label=${group}_sqrt
  dir=$OUT/$label/seed$seed
  if grep -q "^$STEPS," "$dir/eval.csv" 2>/dev/null; then continue; fi
  echo "$dir agent.group=$group agent.width_strategy=$width seed=$seed train.steps=$STEPS"
done | xargs -P 2 -L 1 sh -c 'd=$1; shift; mkdir -p "$d";
  "$0" -m agents.train "$@" train.progress=false hydra.run.dir="$d" > "$d/stdout.log" 2>&1;
  echo "$(date +%H:%M) exit $?: $d"' "$PYTHON"
