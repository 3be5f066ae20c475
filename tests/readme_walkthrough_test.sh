#!/usr/bin/env bash
# README.md's "Your first five minutes", followed literally: the shell block between the
# `<!-- walkthrough -->` markers runs as written with bash, from the repository's root (it needs
# the build in build/, which ./scripts/test makes; ./scripts/demo inside it rebuilds nothing then).
# Passes when the block exits 0, the demo printed its report's path, and both reports exist with
# their plots. Run by ./scripts/test after ctest (not by ctest: it uses the fixed paths the README
# shows, /tmp/turncal.sock and friends, which parallel tests must not share).
set -euo pipefail
cd "$(dirname "$0")/.."
block=$(awk '/<!-- walkthrough/{on=1; next} /<!-- \/walkthrough -->/{on=0} on' README.md |
  sed -n '/^```sh$/,/^```$/p' | sed '1d;$d')
[[ -n $block ]] || { echo "FAIL: no walkthrough block in README.md"; exit 1; }
# A previous run's daemon state would be resumed (its poses counted twice): start clean, as a
# first-time user does.
rm -rf /tmp/turncal-state /tmp/turncal.sock /tmp/imu1-report.html
log=$(mktemp)
start=$SECONDS
status=0
# In its own session, so that whatever it left running when it failed (turncald, the simulator)
# is stopped with it.
setsid bash -e <<< "$block" > "$log" 2>&1 &
pid=$!
wait "$pid" || status=$?
kill -- -"$pid" 2> /dev/null || true
elapsed=$((SECONDS - start))
fail() {
  echo "--- output of the walkthrough"; cat "$log"
  echo "FAIL: $1"
  exit 1
}
[[ $status == 0 ]] || fail "the block exited $status"
grep -q "The calibration report: .*report.html" "$log" || fail "the demo did not print the report path"
for r in demo-output/report.html /tmp/imu1-report.html; do
  [[ -s $r ]] || fail "$r is missing"
  plots=$(grep -o '<svg class="plot"' "$r" | wc -l)
  ((plots >= 6)) || fail "$r has $plots plots (expected at least 6: residuals, coverage, convergence per model)"
done
grep -q "gate PASS" "$log" || fail "no gate passed"
# The IEEE test report (docs/CHARACTERISE.md): the accelerometer's figures and the rest's.
grep -q "the IEEE test report: .*ieee-report.html" "$log" || fail "the demo did not print the IEEE report"
grep -q "second-order coefficient (K2)" demo-output/ieee-report.html ||
  fail "the IEEE report lists no K2 item"
grep -q "warm-up time" demo-output/ieee-report.html || fail "the IEEE report has no warm-up item"
echo "README walkthrough: followed literally, exit 0 in ${elapsed} s; demo-output/report.html, ieee-report.html and /tmp/imu1-report.html written"
