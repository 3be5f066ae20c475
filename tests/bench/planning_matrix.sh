#!/usr/bin/env bash
# The planning table of docs/OBSERVABILITY.md "Planning for time": poses and table seconds to a
# passing gate through the whole pipeline (turncal montecarlo --pipeline) on a table that moves
# at 20 deg/s and 20 deg/s^2, for the cube order, the planner before issue 19's item 4 (per pose,
# independent poses) and the planner now (per second, drift model); accel13 and mag13 x
# industrial and consumer, mip. One JSON line per row on standard output, a progress line per row
# on standard error.
#   tests/bench/planning_matrix.sh BUILD_DIR [RUNS=100] [JOBS=2] [RATE_DPS=20]
set -euo pipefail
BUILD=${1:?usage: planning_matrix.sh BUILD_DIR [RUNS] [JOBS] [RATE_DPS]}
RUNS=${2:-100}
JOBS=${3:-2}
RATE=${4:-20}
TURNCAL=$BUILD/tools/turncal
row() {
  local t0=$SECONDS
  "$TURNCAL" montecarlo --pipeline --runs "$RUNS" --jobs "$JOBS" --json --protocol mip \
    --table-rate "$RATE" "$@" 2> /dev/null || true
  echo "planning_matrix: $* ($((SECONDS - t0)) s)" >&2
}
for model in accel13 mag13; do
  for class in industrial consumer; do
    row --model "$model" --class "$class" --plan default
    row --model "$model" --class "$class" --plan planner --planner-objective poses \
      --planner-drift independent
    row --model "$model" --class "$class" --plan planner
  done
done
