#!/usr/bin/env bash
# The matrix of docs/THERMAL.md "Through the whole pipeline" (issue 36's acceptance): turncal
# montecarlo --pipeline --chamber for accel13 and mag13 x industrial and consumer x a ramp and
# soaks, then gyro12 (rate segments and static poses) x the same, the orders chosen from the data,
# each parameter scored at the held-out temperatures. One JSON line per row on standard output
# (tests/bench/thermal_table.py makes the table), a progress line per row on standard error.
#   tests/bench/thermal_matrix.sh BUILD_DIR [RUNS=200] [JOBS=2] [SEED=1]
# About 75 minutes at 200 runs with 2 jobs on a 2-core host, alone (an accel13 or mag13 row 4-7
# minutes, a gyro12 row 6-10).
set -euo pipefail
BUILD=${1:?usage: thermal_matrix.sh BUILD_DIR [RUNS] [JOBS] [SEED]}
RUNS=${2:-200}
JOBS=${3:-2}
SEED=${4:-1}
TURNCAL=$BUILD/tools/turncal
RAMP="0; ramp 40 4 300"
SOAKS="0; soak 0 300; ramp 20 4 300; ramp 40 4 300"
row() {
  local t0=$SECONDS
  "$TURNCAL" montecarlo --pipeline --runs "$RUNS" --jobs "$JOBS" --seed "$SEED" --json \
    --device-rate 100 --dwell 4 --thermal-orders chosen "$@" 2> /dev/null || true
  echo "thermal_matrix: $* ($((SECONDS - t0)) s)" >&2
}
for model in accel13 mag13 gyro12; do
  for class in industrial consumer; do
    row --model "$model" --class "$class" --chamber "$RAMP"
    row --model "$model" --class "$class" --chamber "$SOAKS"
  done
done
