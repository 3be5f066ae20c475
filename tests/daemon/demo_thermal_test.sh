#!/usr/bin/env bash
# DEMO_THERMAL=1 ./scripts/demo's session (scripts/demo-thermal) against the built programs: a
# simulated consumer MIP IMU in a chamber ramping 0 -> 40 degC on a pty, turncald calibrating
# accel13@T and mag13@T. Passes when the session ends, both models have an estimate over at least
# 30 degC of range, the magnetometer's gate passed and the report plots it against temperature.
# Usage: demo_thermal_test.sh TURNCAL TURNCALD SOURCE_DIR
set -uo pipefail
turncal=$1 turncald=$2 src=$3
dir=$(mktemp -d)
trap 'rm -rf "$dir"' EXIT
if ! "$src/scripts/demo-thermal" "$turncal" "$turncald" "$dir" > "$dir/demo.log" 2>&1; then
  echo "demo thermal: the demo failed; its log:"
  tail -30 "$dir/demo.log"
  exit 1
fi
python3 - "$dir" << 'PY'
import json, sys
d = sys.argv[1]
models = json.load(open(f"{d}/result.json"))["devices"]["imu"]["models"]
bad = []
for name in ("accel13@T", "mag13@T"):
    t = models[name]["temperature"]
    if not t["ok"] or t["t_max_c"] - t["t_min_c"] < 30:
        bad.append(f"{name}: {t.get('error')} range {t.get('t_min_c')} .. {t.get('t_max_c')}")
if not models["mag13@T"]["gate"]["pass"]:
    bad.append("mag13@T gate: " + "; ".join(models["mag13@T"]["gate"]["reasons"]))
html = open(f"{d}/report.html").read()
if "mag13@T: over temperature" not in html or 'class="thermal-parameter"' not in html:
    bad.append("the report has no plot over temperature")
print("demo thermal: " + ("ok" if not bad else "FAILED: " + " | ".join(bad)))
PY
