#!/usr/bin/env python3
"""turncal noise: on a simulated 200 s rest of known white density it recovers the density (the
Allan deviation of 100 000 samples scatters by well under 5 % at the short cluster times that
fix N); the plot is written; a missing file is exit 2; on imu_tk's real Xsens recording (raw
counts, the 50 s rest first) it reports every axis with a fitted curve (skipped without
../shared/fixtures)."""
import json
import os
import subprocess
import sys
import tempfile

TURNCAL = sys.argv[1]
failures = 0


def check(ok, what):
    global failures
    print(("ok   " if ok else "FAIL ") + what)
    failures += not ok


with tempfile.TemporaryDirectory() as d:
    poses = os.path.join(d, "rest.csv")
    open(poses, "w").write("phi,gamma,psi\n0,0,0\n")
    capture = os.path.join(d, "rest.tcap")
    density = 1e-3  # m/s^2/sqrt(Hz)
    subprocess.run([TURNCAL, "sim", "--protocol", "mip", "--poses", poses, "--dwell", "200",
                    "--acc-noise", str(density), "--acc-bias-instability", "0", "--seed", "4",
                    "-o", capture], check=True, capture_output=True)
    svg = os.path.join(d, "allan.svg")
    r = subprocess.run([TURNCAL, "noise", capture, "--from", "5", "--svg", svg, "--json"],
                       capture_output=True, text=True)
    check(r.returncode == 0, f"turncal noise on a simulated rest: exit {r.returncode} {r.stderr}")
    if r.returncode == 0:
        axes = [a for a in json.loads(r.stdout)["axes"] if a["triad"] == "acc"]
        check(len(axes) == 3, "three accelerometer axes")
        for a in axes:
            n = a["white_density"]
            check(abs(n - density) < 0.05 * density,
                  f"acc {a['axis']}: white density {n:.4g} against {density:g} (5 %)")
        check(os.path.exists(svg) and "<svg" in open(svg).read(), "the plot is written")
    r = subprocess.run([TURNCAL, "noise", os.path.join(d, "none.tcap")], capture_output=True)
    check(r.returncode == 2, f"a missing file: exit {r.returncode}")

shared = os.environ.get("TURNCAL_SHARED_DIR", os.path.join(os.path.dirname(__file__), "../../../shared"))
acc = os.path.join(shared, "fixtures/imu_tk/xsens_acc.mat")
if not os.path.exists(acc):
    print(f"skipped: {acc} is absent (the real Xsens recording)")
else:
    r = subprocess.run([TURNCAL, "noise", acc, "--triad", "acc", "--to", "45", "--json"],
                       capture_output=True, text=True)
    check(r.returncode == 0, f"imu_tk xsens_acc.mat: exit {r.returncode}")
    if r.returncode == 0:
        axes = json.loads(r.stdout)["axes"]
        check(len(axes) == 3 and all(a["samples"] == 4501 for a in axes),
              "imu_tk: 3 axes of 4501 samples (45 s at 100 Hz)")
        for a in axes:
            # Raw counts of a 16-bit accelerometer: a white density of a fraction of a count.
            check(0.2 < a["white_density"] < 1.0 and a["rms_log_error"] < 0.2,
                  f"imu_tk acc {a['axis']}: N {a['white_density']:.3f} counts/sqrt(Hz), fit "
                  f"error {a['rms_log_error']:.3f}")

print(f"noise: {failures} failure(s)")
sys.exit(1 if failures else 0)
