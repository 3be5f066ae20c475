#!/usr/bin/env bash
# Runs the libFuzzer targets (tests/fuzz; a build configured with -DTURNCAL_FUZZ=ON and clang)
# for SECONDS each, each on a copy of its committed corpus (tests/fuzz/corpus/TARGET) in a
# temporary directory: the repository is not modified. Prints one line per target: executions,
# executions per second, coverage (libFuzzer's cov: edges and ft: features at the end), corpus
# size at the end, and the result. Exits 1 when a target crashed, leaked, timed out or broke an
# invariant; the crashing input's path is printed, and the temporary directory is kept.
#
# Usage: tests/fuzz/run_fuzz.sh BUILD_DIR SECONDS [TARGET...]
#   TARGET: mip gx2 xbus xbus_legacy capture request config (default: all seven)
# Environment:
#   FUZZ_JOBS  targets run side by side (default: 2 when nproc >= 2, else 1)
#   FUZZ_ARGS  more libFuzzer options for every target (e.g. "-max_len=40000")
#   FUZZ_KEEP  1: keep the temporary directory (the grown corpora, the logs) even when all passed
#
# Example: tests/fuzz/run_fuzz.sh build-fuzz 60; FUZZ_JOBS=1 tests/fuzz/run_fuzz.sh build-fuzz 600
set -u

if [ $# -lt 2 ]; then
  echo "usage: $0 BUILD_DIR SECONDS [TARGET...]" >&2
  exit 2
fi
build=$(cd "$1" && pwd) || exit 2
seconds=$2
shift 2
case $seconds in
  '' | *[!0-9]*) echo "$0: SECONDS must be a whole number" >&2; exit 2 ;;
esac
targets=("$@")
[ ${#targets[@]} -gt 0 ] || targets=(mip gx2 xbus xbus_legacy capture request config)
here=$(cd "$(dirname "$0")" && pwd)
if [ -n "${FUZZ_JOBS:-}" ]; then
  jobs=$FUZZ_JOBS
elif [ "$(nproc)" -ge 2 ]; then
  jobs=2
else
  jobs=1
fi

for t in "${targets[@]}"; do
  if [ ! -x "$build/tests/fuzz/${t}_fuzz" ]; then
    echo "$0: no $build/tests/fuzz/${t}_fuzz (cmake -DTURNCAL_FUZZ=ON with clang, then build it)" >&2
    exit 2
  fi
  if [ ! -d "$here/corpus/$t" ]; then
    echo "$0: no corpus $here/corpus/$t" >&2
    exit 2
  fi
done

work=$(mktemp -d "${TMPDIR:-/tmp}/turncal-fuzz.XXXXXX")
echo "run_fuzz: ${#targets[@]} targets x ${seconds} s, $jobs at a time, in $work"

# Undefined behaviour stops the run like a crash (the build recovers from it by default).
export UBSAN_OPTIONS=${UBSAN_OPTIONS:-halt_on_error=1:print_stacktrace=1}

run_one() {
  local t=$1 dir=$work/$1
  mkdir -p "$dir/corpus" "$dir/artifacts"
  cp -R "$here/corpus/$t/." "$dir/corpus/"
  local dict=()
  [ -f "$here/$t.dict" ] && dict=("-dict=$here/$t.dict")
  # shellcheck disable=SC2086
  "$build/tests/fuzz/${t}_fuzz" -max_total_time="$seconds" -print_final_stats=1 \
    -artifact_prefix="$dir/artifacts/" "${dict[@]}" ${FUZZ_ARGS:-} "$dir/corpus" \
    > "$dir/log" 2>&1
  echo $? > "$dir/status"
}

running=0
for t in "${targets[@]}"; do
  if [ "$running" -ge "$jobs" ]; then
    wait -n
    running=$((running - 1))
  fi
  run_one "$t" &
  running=$((running + 1))
done
wait

failed=0
printf '%-12s %12s %8s %6s %7s %7s  %s\n' target runs exec/s cov ft corpus result
for t in "${targets[@]}"; do
  dir=$work/$t
  log=$dir/log
  status=$(cat "$dir/status" 2>/dev/null || echo "?")
  runs=$(sed -n 's/^stat::number_of_executed_units: *//p' "$log" | tail -n 1)
  rate=$(sed -n 's/^stat::average_exec_per_sec: *//p' "$log" | tail -n 1)
  # The last status line ("#N DONE cov: C ft: F corp: ..."; before a crash, the last one printed).
  last=$(grep -E '^#[0-9]+.* cov: ' "$log" | tail -n 1)
  cov=$(sed -n 's/.* cov: \([0-9]*\).*/\1/p' <<< "$last")
  ft=$(sed -n 's/.* ft: \([0-9]*\).*/\1/p' <<< "$last")
  [ -n "$runs" ] || runs=$(sed -n 's/^#\([0-9]*\).*/\1/p' <<< "$last")
  corpus=$(find "$dir/corpus" -type f | wc -l)
  result=ok
  artifacts=$(find "$dir/artifacts" -type f | sort)
  if [ "$status" != 0 ] || [ -n "$artifacts" ]; then
    failed=1
    result="FAILED (exit $status)"
    for a in $artifacts; do result="$result $a"; done
    [ -n "$artifacts" ] || result="$result, log $log"
  fi
  printf '%-12s %12s %8s %6s %7s %7s  %s\n' "$t" "${runs:-?}" "${rate:-?}" "${cov:-?}" \
    "${ft:-?}" "$corpus" "$result"
done

if [ "$failed" != 0 ]; then
  echo "run_fuzz: FAILED; logs, corpora and crashing inputs kept in $work"
  for t in "${targets[@]}"; do
    if [ "$(cat "$work/$t/status" 2>/dev/null)" != 0 ]; then
      echo "--- $t, from $work/$t/log:"
      grep -E 'ERROR|SUMMARY|runtime error|Test unit written|deadly signal' "$work/$t/log" | head -n 8
    fi
  done
  exit 1
fi
if [ "${FUZZ_KEEP:-0}" = 1 ]; then
  echo "run_fuzz: all passed; kept $work"
else
  rm -rf "$work"
  echo "run_fuzz: all passed"
fi
