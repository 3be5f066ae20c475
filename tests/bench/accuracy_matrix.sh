#!/usr/bin/env bash
# The acceptance matrix of docs/ACCURACY.md "Through the pipeline": turncal montecarlo --pipeline
# for accel13 and mag13 x industrial and consumer x mip and xbus x the default plan, the same
# poses shuffled, the planner's sequence; then the warm-up rows. One JSON line per row on
# standard output, a progress line per row on standard error.
#   tests/bench/accuracy_matrix.sh BUILD_DIR [RUNS=200] [JOBS=2]
set -euo pipefail
BUILD=${1:?usage: accuracy_matrix.sh BUILD_DIR [RUNS] [JOBS]}
RUNS=${2:-200}
JOBS=${3:-2}
TURNCAL=$BUILD/tools/turncal
row() {
  local t0=$SECONDS
  "$TURNCAL" montecarlo --pipeline --runs "$RUNS" --jobs "$JOBS" --json "$@" 2> /dev/null || true
  echo "accuracy_matrix: $* ($((SECONDS - t0)) s)" >&2
}
for model in accel13 mag13; do
  for class in industrial consumer; do
    for protocol in mip xbus; do
      for plan in default shuffled planner; do
        row --model "$model" --class "$class" --protocol "$protocol" --plan "$plan"
      done
    done
  done
done
# Warm-up of 3 bias instabilities (tau 60 s) that the station is not told about, then the same
# with the station's warm-up allowance ([station] warmup = 3).
for model in accel13 mag13; do
  for class in industrial consumer; do
    row --model "$model" --class "$class" --protocol mip --plan default --warmup 3
    row --model "$model" --class "$class" --protocol mip --plan default --warmup 3 --station-warmup 3
  done
done
