#!/usr/bin/env bash
# `turncal noise` against a plain vectorised overlapping Allan deviation in numpy, on the same
# file (docs/PERFORMANCE.md, "Noise: hours of data"; issue 39).
#
# Usage: tests/bench/noise_speed.sh BUILD_DIR [HOURS] [RATE]     (defaults: 10 h at 400 Hz)
#
#   1. numpy writes HOURS of a six-axis rest at RATE Hz as WORK/imu.npy (columns t, acc x y z,
#      gyr x y z; white noise and a random-walking bias; float64).
#   2. `turncal noise imu.npy --triad acc,gyr --json` reads it as a stream: wall time and peak
#      memory (/usr/bin/time).
#   3. tests/bench/noise_allan.py loads the same file and computes the overlapping Allan
#      deviation at turncal's cluster sizes the way allantools does (cumulative sum, one numpy
#      pass per size): load and compute times, peak memory, and the largest difference from
#      turncal's values.
#   4. CAPTURE=1 also simulates the rest as a MIP capture (`turncal sim`, a few GB of memory
#      while it builds) and times `turncal noise` on it: decoding included.
# Needs python3-numpy (apt-get install python3-numpy; PYTHON=/usr/bin/python3 by default). WORK=DIR keeps the files there.
set -euo pipefail
BUILD=$(cd "${1:?usage: noise_speed.sh BUILD_DIR [HOURS] [RATE]}" && pwd)
HOURS=${2:-10}
RATE=${3:-400}
HERE=$(cd "$(dirname "$0")" && pwd)
TURNCAL=$BUILD/tools/turncal
PYTHON=${PYTHON:-/usr/bin/python3}  # Debian's, where python3-numpy installs
"$PYTHON" -c 'import numpy' 2>/dev/null || { echo "noise_speed.sh: needs python3-numpy" >&2; exit 1; }
if [[ -n ${WORK:-} ]]; then mkdir -p "$WORK"; else WORK=$(mktemp -d /tmp/noise_speed.XXXXXX); trap 'rm -rf "$WORK"' EXIT; fi
echo "noise_speed.sh: $HOURS h at $RATE Hz, six axes; machine: $(nproc) cores, $(lscpu | sed -n 's/^Model name: *//p'); work $WORK"

"$PYTHON" - "$WORK/imu.npy" "$HOURS" "$RATE" <<'PY'
import sys
import numpy as np
path, hours, rate = sys.argv[1], float(sys.argv[2]), float(sys.argv[3])
n = int(hours * 3600 * rate)
rng = np.random.default_rng(1)
data = np.empty((n, 7))
data[:, 0] = np.arange(n) / rate
white = [2e-3 * np.sqrt(rate / 2)] * 3 + [1e-4 * np.sqrt(rate / 2)] * 3
walk = [2e-5 / np.sqrt(rate)] * 3 + [1e-6 / np.sqrt(rate)] * 3
offset = [0.0, 0.0, -9.81, 0.0, 0.0, 0.0]
for c in range(6):
    data[:, c + 1] = offset[c] + white[c] * rng.standard_normal(n) + \
        np.cumsum(walk[c] * rng.standard_normal(n))
np.save(path, data)
print(f"noise_speed.sh: wrote {n} samples x 6 axes ({data.nbytes / 1e9:.2f} GB)")
PY

measure() {  # label, output file, then the command; prints wall s and peak MB
  local label=$1 output=$2
  shift 2
  /usr/bin/time -f "%e %M" -o "$WORK/time.txt" "$@" > "$output"
  read -r wall kb < "$WORK/time.txt"
  echo "noise_speed.sh: $label: ${wall} s, peak memory $((kb / 1024)) MB"
}
measure "turncal noise on imu.npy" "$WORK/turncal.json" "$TURNCAL" noise "$WORK/imu.npy" \
  --triad acc,gyr --progress never --json
python3 -c 'import json,sys; r=json.load(open(sys.argv[1])); a=r["axes"][0]; print("noise_speed.sh: turncal: %d axes x %d samples, %d cluster sizes each up to %.3g s; read and summed in %.2f s" % (len(r["axes"]), a["samples"], len(a["allan"]), a["allan"][-1]["tau_s"], r["read_s"]))' "$WORK/turncal.json"
measure "numpy (load + compute)" "$WORK/numpy.json" "$PYTHON" "$HERE/noise_allan.py" "$WORK/imu.npy" \
  "$WORK/turncal.json"
echo "noise_speed.sh: numpy: $(cat "$WORK/numpy.json")"

if [[ ${CAPTURE:-0} == 1 ]]; then
  printf 'phi,gamma,psi\n0,0,0\n' > "$WORK/rest.csv"
  DWELL=$(python3 -c "print(int($HOURS * 3600))")
  measure "turncal sim (the MIP capture)" /dev/null "$TURNCAL" sim --protocol mip \
    --poses "$WORK/rest.csv" --dwell "$DWELL" --rate "$RATE" --seed 1 -o "$WORK/rest.tcap"
  echo "noise_speed.sh: capture $(du -h "$WORK/rest.tcap" | cut -f1)"
  measure "turncal noise on the MIP capture (decoding included)" "$WORK/capture.txt" "$TURNCAL" \
    noise "$WORK/rest.tcap" --triad acc,gyr --progress never
  head -1 "$WORK/capture.txt"
fi
