#!/usr/bin/env bash
# Runs the geomdp-train jobs listed on stdin, two at a time (PARALLEL), one torch
# thread each. One job per line: <run dir> <env steps> <override>...
# A run whose eval.csv has reached <env steps> is skipped; an interrupted one
# resumes from its checkpoint, so running the same list again continues it.
# DRY_RUN=1 prints the jobs that would run, and touches nothing.
#   printf '%s\n' "runs/a 30000 seed=1" "runs/b 30000 seed=2" | bash benchmarks/run_queue.sh
set -euo pipefail
cd "$(dirname "$0")/.."
PYTHON=${PYTHON:-$(pwd)/.venv/bin/python}
while read -r dir steps overrides; do
  if grep -q "^$steps," "$dir/eval.csv" 2>/dev/null; then continue; fi
  echo "$dir $overrides train.steps=$steps"
done | if [ -n "${DRY_RUN:-}" ]; then cat; else xargs -P "${PARALLEL:-2}" -L 1 sh -c 'd=$1; shift; mkdir -p "$d";
  "$0" -m agents.train "$@" train.progress=false hydra.run.dir="$d" > "$d/stdout.log" 2>&1;
  echo "$(date +%H:%M) exit $?: $d"' "$PYTHON"; fi
