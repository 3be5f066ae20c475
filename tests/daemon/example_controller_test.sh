#!/usr/bin/env bash
# The example controller (tools/examples/turntable_controller.py) drives a real turncald session:
# `turncal sim --live` streams a simulated Xbus IMU into one end of a pty pair at 2x real time
# and prints each pose event when its table has settled there; turncald reads the other end (no
# configuration dialogue: the simulator only streams); the controller reads the poses CSV, runs
# --table-cmd (a script that returns once the simulator's table is at that pose), announces the
# pose on the socket and waits for POSE_CAPTURED. Passes when the controller exits 0, reports
# every pose captured, turncald's `result` holds that many poses, and their fit is consistent
# (p-value >= 1e-3 for every model; poses labelled with another pose's angles give p = 0).
#
# Why not a replayed capture (`--device imu=xbus:replay:FILE`): a replay delivers its samples with
# the capture's recorded times, while a pose announced on the socket is stamped with
# CLOCK_MONOTONIC, so such a pose never finds samples after its announcement.
#
# Usage: example_controller_test.sh TURNCAL TURNCALD [SOURCE_DIR]   (KEEP=1: keep the temporary
# directory with every log)
set -euo pipefail
turncal=$1
turncald=$2
src=${3:-$(cd "$(dirname "$0")/../.." && pwd)}
controller=$src/tools/examples/turntable_controller.py
command -v socat > /dev/null || { echo "SKIP: socat is not installed"; exit 0; }
command -v python3 > /dev/null || { echo "SKIP: python3 is not installed"; exit 0; }
dir=$(mktemp -d)
pids=()
cleanup() {
  for p in "${pids[@]}"; do kill "$p" 2> /dev/null || true; done
  wait 2> /dev/null || true
  [[ -n "${KEEP:-}" ]] || rm -rf "$dir"
}
trap cleanup EXIT

# The first pose is (0, 0, 0), where the table rests at the start: the daemon measures the noise
# there (it needs the first second of the stream still). Every pose differs, so the table command
# can tell them apart. The fifth is a rate segment (issue 21: the controller announces it with
# {"cmd":"rate"}; the simulated gyro follows a gyro12 truth; the daemon's accel13 and mag13 leave
# its record alone).
cat > "$dir/poses.csv" << 'EOF'
phi,gamma,psi,axis,rate_dps
0,0,0
90,0,45
0,90,90
-90,45,180
0,0,0,outer,90
180,-45,270
45,35.26438968,0
EOF
n_poses=$(($(wc -l < "$dir/poses.csv") - 1))

# The table command (tools/examples/sim_table.py): returns once the simulator printed the pose
# event of these angles (the table has settled there and holds it for --dwell seconds of simulated
# time).
table_cmd="python3 $src/tools/examples/sim_table.py $dir/events.jsonl"

cat > "$dir/turncald.toml" << EOF
socket = "$dir/t.sock"
state_dir = "$dir/state"
[[device]]
name = "imu"
protocol = "xbus"
port = "$dir/device"
configure = false
EOF

socat pty,raw,echo=0,link="$dir/device" pty,raw,echo=0,link="$dir/sim" 2> "$dir/socat.log" &
pids+=($!)
for _ in $(seq 100); do [[ -e "$dir/device" && -e "$dir/sim" ]] && break; sleep 0.05; done
"$turncald" --config "$dir/turncald.toml" > "$dir/turncald.log" 2>&1 &
pids+=($!)
for _ in $(seq 600); do [[ -S "$dir/t.sock" ]] && break; sleep 0.05; done
[[ -S "$dir/t.sock" ]] || { cat "$dir/turncald.log"; echo "FAIL: turncald did not listen"; exit 1; }

"$turncal" sim --protocol xbus --model gyro12 --seed 3 --dwell 8 --poses "$dir/poses.csv" --live "$dir/sim" \
  --live-speed 2 > "$dir/events.jsonl" 2> "$dir/sim.err" &
pids+=($!)

status=0
python3 "$controller" --socket "$dir/t.sock" --poses "$dir/poses.csv" --retries 0 \
  --timeout 30 --table-cmd "$table_cmd" --json \
  > "$dir/controller.out" 2> "$dir/controller.err" || status=$?
cat "$dir/controller.out"
summary=$(tail -n 1 "$dir/controller.out")
result=$("$turncal" result --json --socket "$dir/t.sock") || result='{}'
poses=$(python3 -c 'import json, sys; print(json.loads(sys.argv[1])["devices"]["imu"]["poses"])' \
  "$result" 2> /dev/null) || poses="?"
# A pose announced before the table reached it is captured at the previous pose's angles, or
# rejected: with such labels the fit's p-value is ~0 (checked: 0). 1e-3 is the gate's
# min_p_value.
fit=$(python3 -c '
import json, sys
models = json.loads(sys.argv[1])["devices"]["imu"]["models"]
print(" ".join("%s:p=%.3g" % (m, v["p_value"]) for m, v in sorted(models.items())))
sys.exit(0 if all(v["ok"] and v["p_value"] >= 1e-3 for v in models.values()) else 1)' "$result" \
  2> /dev/null) && fit_ok=1 || fit_ok=0
captured=$(python3 -c 'import json, sys; print(json.loads(sys.argv[1])["captured"])' "$summary" \
  2> /dev/null || echo "?")
echo "controller exit $status, $captured of $n_poses poses captured by its count, $poses in turncald's result; fit $fit"
if [[ $status != 0 || $captured != "$n_poses" || $poses != "$n_poses" || $fit_ok != 1 ]]; then
  echo "--- controller stderr"; cat "$dir/controller.err"
  echo "--- turncald log"; cat "$dir/turncald.log"
  echo "--- simulator"; cat "$dir/sim.err" "$dir/events.jsonl"
  echo "FAIL"
  exit 1
fi
echo "example controller: $n_poses poses captured"
