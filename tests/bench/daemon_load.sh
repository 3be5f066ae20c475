#!/usr/bin/env bash
# turncald under load (docs/PERFORMANCE.md, "Daemon under load").
#
# Usage: tests/bench/daemon_load.sh BUILD_DIR [SECONDS]          (SECONDS: default 60)
#
# Needs BUILD_DIR/tools/turncal, BUILD_DIR/daemon/turncald and BUILD_DIR/tests/daemon_load
# (ninja -C BUILD_DIR turncal turncald daemon_load). What it does:
#   1. `turncal sim --controller` creates one pty per simulated MIP device, streams at RATE Hz in
#      real time and plays the turntable controller on turncald's socket (26 cube poses, dwell
#      chosen so the session outlasts the measurement: the sequencer keeps capturing poses and the
#      calibrators keep solving throughout, as in a real session).
#   2. The calibrations of the simulator's truth are written to the state directory
#      (daemon_load seed), so turncald corrects from its first sample instead of after ~13 poses.
#   3. turncald runs on the ptys (configuration dialogue, RATE Hz each; config file in the work
#      directory).
#   4. daemon_load measure connects CLIENTS subscribers ({"cmd":"watch","events":false,
#      "corrected":true}), waits until all of them receive corrected samples of every device, and
#      measures for SECONDS: latency from the daemon's read of the bytes (t_host_ns) to the
#      subscriber's receipt, DROPPED, daemon/simulator/subscriber CPU, daemon RSS every INTERVAL
#      seconds, machine load. Last line of output: {"class":"LOAD_RESULT",...}.
#
# Environment (defaults): DEVICES=8 RATE=1000 CLIENTS=4 PROTOCOL=mip BAUD=921600 INTERVAL=10
#   REGISTRY=CONNINFO adds [registry] (the outbox sends every activated calibration there);
#   SEED=1 SETTLE=5 (seconds between the first corrected sample of every device and the window:
#   the daemon first drains what the ptys buffered while it started); KEEP=1 keeps the work directory (logs, result.json); WORK=DIR uses DIR (created);
#   NICE=N runs simulator, turncald and subscribers under `nice -n N` (e.g. -10 as root: on a
#   shared machine, other people's builds then take the CPU only when these do not need it).
#   FIXTURE=1 makes the devices a batch on a fixture (issue 38): [fixture] with one slot per device,
#   the slots' mounts cycling through the cube fixture's four (+x+y+z -y+x+z +x-y-z +z+x+y, the
#   simulator mounting each unit so), batch "LOAD-FIXTURE"; the batch's state at the end is
#   printed (units passed, waiting, held; seconds to the last gate).
#   CLIENTS=0 measures the daemon without subscribers. PERF=1 records `perf record $PERF_ARGS`
#   (default -g) of the daemon for the first min(SECONDS, 30) s of the window (perf.data in the
#   work directory, which is then kept; PERF_ARGS="--call-graph dwarf" for usable call chains).
# Exit status: daemon_load's (0: measured; targets are reported, not enforced), 1 on set-up failure.
set -euo pipefail

BUILD=${1:?usage: daemon_load.sh BUILD_DIR [SECONDS]}
DURATION=${2:-60}
DEVICES=${DEVICES:-8}
RATE=${RATE:-1000}
CLIENTS=${CLIENTS:-4}
PROTOCOL=${PROTOCOL:-mip}
BAUD=${BAUD:-921600}
INTERVAL=${INTERVAL:-10}
SEED=${SEED:-1}
SETTLE=${SETTLE:-5}
KEEP=${KEEP:-0}
PERF=${PERF:-0}
FIXTURE=${FIXTURE:-0}
MOUNTS=("+x+y+z" "-y+x+z" "+x-y-z" "+z+x+y")
NICE=${NICE:-}
RUN=()
[[ -n $NICE ]] && RUN=(nice -n "$NICE")
PERF_ARGS=${PERF_ARGS:--g}

BUILD=$(cd "$BUILD" && pwd)
TURNCAL=$BUILD/tools/turncal
TURNCALD=$BUILD/daemon/turncald
LOAD=$BUILD/tests/daemon_load
for exe in "$TURNCAL" "$TURNCALD" "$LOAD"; do
  [[ -x $exe ]] || { echo "daemon_load.sh: $exe is missing (ninja -C $BUILD turncal turncald daemon_load)" >&2; exit 1; }
done

if [[ -n ${WORK:-} ]]; then
  mkdir -p "$WORK"
else
  WORK=$(mktemp -d /tmp/daemon_load.XXXXXX)
fi
[[ $PERF == 1 ]] && KEEP=1
SIM_PID=
DAEMON_PID=
PERF_PID=
cleanup() {
  # Only the processes this script started, by their ids.
  [[ -n $PERF_PID ]] && kill -INT "$PERF_PID" 2>/dev/null && wait "$PERF_PID" 2>/dev/null || true
  [[ -n $DAEMON_PID ]] && kill -TERM "$DAEMON_PID" 2>/dev/null && wait "$DAEMON_PID" 2>/dev/null || true
  [[ -n $SIM_PID ]] && kill -TERM "$SIM_PID" 2>/dev/null && wait "$SIM_PID" 2>/dev/null || true
  if [[ $KEEP == 1 ]]; then
    echo "daemon_load.sh: work directory kept: $WORK"
  else
    rm -rf "$WORK"
  fi
}
trap cleanup EXIT

# The session must outlast start-up (capture build, dialogues; ~90 s allowed) and the window:
# 26 cube poses of (3 s move + 1 s settle + DWELL), or fewer poses of the minimum dwell (5 s).
NEED=$((DURATION + 90))
if ((NEED <= 26 * 9)); then
  DWELL=5
  POSES=$(((NEED + 8) / 9))
else
  POSES=26
  DWELL=$(((NEED + 25) / 26 - 4))
fi
"$TURNCAL" poses --design cube | grep -v '^#' | head -n $((POSES + 1)) > "$WORK/poses.csv"

# turncald's configuration: the devices at RATE Hz (the MIP dialogue asks for this rate).
{
  echo "# written by tests/bench/daemon_load.sh"
  if [[ $FIXTURE == 1 ]]; then
    printf '[fixture]\nname = "load%d"\nbatch = "LOAD-FIXTURE"\n\n' "$DEVICES"
    for i in $(seq 1 "$DEVICES"); do
      printf '[[fixture.slot]]\nname = "%d"\nmount = "%s"\n\n' "$i" "${MOUNTS[$(((i - 1) % 4))]}"
    done
  fi
  for i in $(seq 1 "$DEVICES"); do
    printf '[[device]]\nname = "imu%d"\nprotocol = "%s"\nport = "%s/imu%d"\nbaud = %d\nrate_hz = %s\n' \
      "$i" "$PROTOCOL" "$WORK" "$i" "$BAUD" "$RATE"
    [[ $FIXTURE == 1 ]] && printf 'slot = "%d"\n' "$i"
    echo
  done
  # REGISTRY=CONNINFO: the station also sends every activated calibration to that registry
  # (docs/REGISTRY.md), to measure the sample path with and without it.
  if [[ -n ${REGISTRY:-} ]]; then
    printf '[registry]\nconninfo = "%s"\nstation = "daemon-load"\n' "$REGISTRY"
  fi
} > "$WORK/turncald.toml"

LIVES=()
for i in $(seq 1 "$DEVICES"); do
  LIVES+=(--live "$WORK/imu$i")
  [[ $FIXTURE == 1 ]] && LIVES+=("--mount=${MOUNTS[$(((i - 1) % 4))]}")
done

echo "daemon_load.sh: $DEVICES x $PROTOCOL at $RATE Hz ($BAUD baud), $CLIENTS subscribers, ${DURATION} s window;" \
     "session $POSES poses x (4 + $DWELL) s; work $WORK${NICE:+; nice $NICE}"
echo "daemon_load.sh: machine: $(nproc) cores, $(lscpu | sed -n 's/^Model name: *//p'); before: $(uptime)"

"${RUN[@]}" "$TURNCAL" sim --protocol "$PROTOCOL" "${LIVES[@]}" --controller "$WORK/t.sock" --rate "$RATE" \
  --baud "$BAUD" --poses "$WORK/poses.csv" --dwell "$DWELL" --seed "$SEED" \
  --truth-out "$WORK/truth.json" --answer-timeout 60 --live-speed 1 \
  > "$WORK/sim.out" 2> "$WORK/sim.err" &
SIM_PID=$!

# The truth file is written once every device's session is built, just before the ptys stream.
for _ in $(seq 1 3000); do
  [[ -s $WORK/truth.json ]] && break
  if ! kill -0 "$SIM_PID" 2>/dev/null; then
    wait "$SIM_PID" && code=0 || code=$?
    SIM_PID=
    echo "daemon_load.sh: the simulator stopped (exit $code):" >&2
    cat "$WORK/sim.err" >&2
    exit 1
  fi
  sleep 0.1
done
[[ -s $WORK/truth.json ]] || { echo "daemon_load.sh: no truth file from the simulator" >&2; exit 1; }
"$LOAD" seed --truth "$WORK/truth.json" --state-dir "$WORK/state"

"${RUN[@]}" "$TURNCALD" --config "$WORK/turncald.toml" --socket "$WORK/t.sock" --state-dir "$WORK/state" \
  > "$WORK/daemon.log" 2>&1 &
DAEMON_PID=$!

if [[ $PERF == 1 ]]; then
  # Starts after the warm-up: daemon_load prints its "corrected output from" line first.
  (
    for _ in $(seq 1 1800); do
      grep -q 'corrected output from' "$WORK/measure.out" 2>/dev/null && break
      sleep 0.1
    done
    sleep "$SETTLE"
    exec perf record $PERF_ARGS -F 999 -p "$DAEMON_PID" -o "$WORK/perf.data" -- sleep $((DURATION < 30 ? DURATION : 30))
  ) > "$WORK/perf.log" 2>&1 &
  PERF_PID=$!
fi

set +e
"${RUN[@]}" "$LOAD" measure --socket "$WORK/t.sock" --seconds "$DURATION" --clients "$CLIENTS" \
  --devices "$DEVICES" --rate "$RATE" --interval "$INTERVAL" --settle "$SETTLE" --daemon-pid "$DAEMON_PID" \
  --sim-pid "$SIM_PID" --json-out "$WORK/result.json" | tee "$WORK/measure.out"
STATUS=${PIPESTATUS[0]}
set -e

if [[ -n ${REGISTRY:-} ]]; then
  echo "daemon_load.sh: registry: $("$TURNCAL" status --socket "$WORK/t.sock" --json |
    python3 -c 'import json, sys; print(json.load(sys.stdin)["registry"])')"
fi
if [[ $FIXTURE == 1 ]]; then
  echo "daemon_load.sh: batch: $("$TURNCAL" status --socket "$WORK/t.sock" --json | python3 -c '
import json, sys
b = json.load(sys.stdin)["batch"]
units = " ".join("%s:%s:%d" % (u["device"], u["state"], u["poses"]) for u in b["units"])
print("%s on %s: %d passed, %d waiting, %d held; seconds to the last gate %s; %s" % (
    b["id"], b["fixture"], b["passed"], b["waiting"], b["held"], b["seconds_to_last_gate"], units))')"
fi
echo "daemon_load.sh: after: $(uptime)"
echo "daemon_load.sh: top processes at the end:"
top -b -n 1 -w 160 | sed -n '7,14p'
if ! kill -0 "$DAEMON_PID" 2>/dev/null; then
  echo "daemon_load.sh: turncald is not running any more:" >&2
  tail -n 20 "$WORK/daemon.log" >&2
  STATUS=1
fi
if ! kill -0 "$SIM_PID" 2>/dev/null; then
  echo "daemon_load.sh: the simulator ended during the measurement (session too short?):" >&2
  tail -n 5 "$WORK/sim.err" >&2
fi
echo "daemon_load.sh: daemon log: $(grep -c '\[warning\]' "$WORK/daemon.log" || true) warnings," \
     "$(grep -c '\[error\]' "$WORK/daemon.log" || true) errors," \
     "$(grep -c 'POSE_CAPTURED' "$WORK/daemon.log" || true) poses captured," \
     "$(grep -c 'CALIBRATION_ACTIVE' "$WORK/daemon.log" || true) calibrations published"
exit "$STATUS"
