#!/usr/bin/env bash
# Fixed-seed sessions as bytes, replayed as `turncald --replay --once` replays them: the RESULT
# JSON of each, for checking that a change which must not alter behaviour (issue 20's move of
# files between layers) leaves every byte of every result as it was:
#   tests/bench/replay_results.sh BUILD_BEFORE /tmp/before
#   tests/bench/replay_results.sh BUILD_AFTER /tmp/after
#   diff -r /tmp/before /tmp/after && echo identical
# Every protocol family, both sensor classes, the default plan and a drifting, warming-up
# consumer sensor; one result and one log (without timestamps) per session.
set -euo pipefail
BUILD=${1:?usage: replay_results.sh BUILD_DIR OUT_DIR}
OUT=${2:?usage: replay_results.sh BUILD_DIR OUT_DIR}
TURNCAL=$BUILD/tools/turncal
TURNCALD=$BUILD/daemon/turncald
mkdir -p "$OUT"
# One fixed folder for the captures: RESULT names its source, which must not differ by run.
work=${TMPDIR:-/tmp}/turncal-replay-results
rm -rf "$work" && mkdir -p "$work"
trap 'rm -rf "$work"' EXIT
run() {
  local name=$1 class=$2
  shift 2
  "$TURNCAL" sim "$@" --class "$class" -o "$work/$name.tcap" --truth-out "$OUT/$name.truth.json" \
    > /dev/null
  printf '[station]\nsensor_class = "%s"\n' "$class" > "$work/$name.toml"
  "$TURNCALD" --config "$work/$name.toml" --replay "$work/$name.tcap" --once \
    --result-out "$OUT/$name.result.json" > /dev/null 2>&1
  echo "replay_results: $name" >&2
}
for protocol in mip gx2 xbus xbus-legacy; do
  for seed in 1 2; do
    run "$protocol-industrial-$seed" industrial --protocol "$protocol" --seed "$seed"
  done
  run "$protocol-consumer-3" consumer --protocol "$protocol" --seed 3
done
run mip-consumer-drift consumer --protocol mip --seed 4 --acc-bias-instability 0.06 \
  --mag-bias-instability 6e-4 --acc-warmup 0.02
