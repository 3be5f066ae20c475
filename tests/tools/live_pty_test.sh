#!/usr/bin/env bash
# End to end through a real pty pair: `turncal sim --live` writes a simulated Xbus device into
# one end at 10x real time, `turncal capture` reads the other end through the serial transport
# (termios backend), and every simulated sample arrives decoded. Usage: live_pty_test.sh TURNCAL
set -euo pipefail
turncal=$1
command -v socat > /dev/null || { echo "SKIP: socat is not installed"; exit 0; }
dir=$(mktemp -d)
trap 'kill $socat_pid $capture_pid 2> /dev/null || true; rm -rf "$dir"' EXIT
printf 'phi,gamma,psi\n0,0,0\n90,0,45\n0,90,90\n' > "$dir/poses.csv"
socat pty,raw,echo=0,link="$dir/device" pty,raw,echo=0,link="$dir/sim" & socat_pid=$!
for _ in $(seq 100); do [[ -e "$dir/device" && -e "$dir/sim" ]] && break; sleep 0.05; done
"$turncal" capture --device mti=xbus:"$dir/device"@115200 -o "$dir/live.tcap" 2> "$dir/capture.log" &
capture_pid=$!
sleep 0.5
"$turncal" sim --protocol xbus --seed 2 --dwell 1 --poses "$dir/poses.csv" --live "$dir/sim" \
  --live-speed 10 --truth-out "$dir/truth.json" > "$dir/events.jsonl"
sleep 0.5
kill -TERM $capture_pid
wait $capture_pid
expected=$(python3 -c "import json; print(json.load(open('$dir/truth.json'))['samples'])")
summary=$("$turncal" decode "$dir/live.tcap" --json | tail -n 1)
echo "$summary"
grep -q '"bad_checksums":0' <<< "$summary"
grep -q "\"samples\":$expected," <<< "$summary"
grep -q 'opened (termios' "$dir/capture.log"
events=$(grep -c '"event":"pose"' "$dir/events.jsonl")
echo "live: $expected samples through the pty, $events pose events on stdout"
[[ $events == 3 ]]
