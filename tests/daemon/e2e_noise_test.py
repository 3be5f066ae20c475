#!/usr/bin/env python3
"""Issue 39 on a pty: turncald measures a device's rest live ({"cmd":"noise"}). A simulated MIP
IMU at rest streams at 20 x real time (no table, no controller); `turncal noise --live imu
--seconds 12` starts the measurement, shows its progress from "status" answers, stops it and
prints the analysis, which turncald also saves in the state directory's rest_noise/:
  - the gyroscope's white density is the simulated one within 10 % (tens of thousands of
    samples: a few % of scatter);
  - the Allan deviation scatters about the true white-noise curve N / sqrt(2 tau) as its edf
    says, at every cluster time up to 10 s: each point's chi-squared deviate (Wilson-Hilferty)
    within 4, and the 95 % intervals miss at a quarter of the points at most (neighbouring
    points are strongly correlated: one excursion spans several);
  - an unknown device and a stop with nothing running are clear errors.

Usage: e2e_noise_test.py TURNCAL TURNCALD
"""
import json
import math
import os
import shutil
import subprocess
import sys
import time

from live_session import check, wait_for
import live_session

TURNCAL, TURNCALD = sys.argv[1], sys.argv[2]
SPEED = 20
GYR_NOISE = 2e-4  # rad/s/sqrt(Hz)


def main(d):
    if not shutil.which("socat"):
        print("skipped: socat is not installed")
        return
    with open(f"{d}/rest.csv", "w") as f:
        f.write("phi,gamma,psi\n0,0,0\n")
    with open(f"{d}/turncald.toml", "w") as f:
        f.write(f"""[station]
models = ["accel13"]
[[device]]
name = "imu"
protocol = "mip"
port = "{d}/device"
configure = false
""")
    socat, daemon = live_session.start_on_pty_pair(TURNCALD, d)
    sock = ["--socket", f"{d}/t.sock"]
    r = subprocess.run([TURNCAL, "noise", "--live", "nosuch", "--seconds", "1"] + sock,
                       capture_output=True, text=True, timeout=30)
    check(r.returncode == 2 and "no device 'nosuch' (devices: imu)" in r.stderr,
          f"an unknown device: exit {r.returncode}: {r.stderr.strip()}")
    r = subprocess.run([TURNCAL, "noise", "--live", "imu", "--stop"] + sock,
                       capture_output=True, text=True, timeout=30)
    check(r.returncode == 1 and "nothing is measured on imu" in r.stderr,
          f"a stop with nothing running: exit {r.returncode}: {r.stderr.strip()}")
    sim = subprocess.Popen(
        [TURNCAL, "sim", "--protocol", "mip", "--live", f"{d}/sim", "--live-speed", str(SPEED),
         "--poses", f"{d}/rest.csv", "--dwell", "2000", "--seed", "39", "--gyr-noise",
         str(GYR_NOISE)],
        stdout=open(f"{d}/sim.out", "w"), stderr=open(f"{d}/sim.err", "w"))
    # Its samples reach the daemon (it measured the start-up noise): the rest is measured on a
    # streaming device.
    end = time.time() + 60
    while time.time() < end and "NOISE_MEASURED" not in open(f"{d}/daemon.log").read():
        time.sleep(0.2)
    check("NOISE_MEASURED" in open(f"{d}/daemon.log").read(), "the simulated IMU streams")
    r = subprocess.run([TURNCAL, "noise", "--live", "imu", "--seconds", "12", "--json",
                        "--progress", "always"] + sock, capture_output=True, text=True,
                       timeout=120)
    check(r.returncode == 0, f"turncal noise --live imu: exit {r.returncode} {r.stderr[-300:]}")
    check("turncal noise: imu:" in r.stderr and "samples" in r.stderr,
          f"the progress lines: {r.stderr.strip().splitlines()[:2]}")
    res = json.loads(r.stdout) if r.returncode == 0 else {}
    samples = res.get("samples", 0)
    check(res.get("class") == "NOISE" and res.get("state") == "stopped" and samples > 5000,
          f"the measurement: {res.get('state')}, {samples} samples over "
          f"{res.get('seconds', 0):.0f} s of the device's time")
    saved = res.get("file", "")
    check(saved.startswith(f"{d}/state/rest_noise/imu.") and os.path.exists(saved) and
          json.load(open(saved))["samples"] == samples, f"saved: {saved}")
    gyr = [a for a in res.get("axes", []) if a["triad"] == "gyr"]
    check(len(gyr) == 3, f"three gyro axes ({len(gyr)})")
    misses = points = 0
    worst = (0.0, 0.0)
    for a in gyr:
        n = a["white_density"]
        check(abs(n - GYR_NOISE) < 0.1 * GYR_NOISE,
              f"gyr {a['axis']}: white density {n:.4g} against {GYR_NOISE:g} rad/s/sqrt(Hz)")
        for p in a["allan"]:
            if p["tau_s"] > 10:
                continue
            truth = GYR_NOISE / math.sqrt(2 * p["tau_s"])  # turncal's convention: N^2 / (2 T)
            points += 1
            misses += not (p["ci95"][0] <= truth <= p["ci95"][1])
            # (adev / truth)^2 is chi^2_edf / edf: its Wilson-Hilferty normal deviate.
            nu = p["edf"]
            z = (((p["adev"] / truth) ** 2) ** (1 / 3) - (1 - 2 / (9 * nu))) / math.sqrt(2 / (9 * nu))
            worst = max(worst, (abs(z), p["tau_s"]))
    check(points > 30 and misses <= 0.25 * points and worst[0] <= 4,
          f"N/sqrt(2 tau) against the Allan points up to 10 s: outside the 95 % interval at "
          f"{misses} of {points}, the largest deviate {worst[0]:.2f} (at {worst[1]:.3g} s)")
    for p in (sim, daemon, socat):
        p.terminate()
    check(daemon.wait(timeout=20) == 0, "SIGTERM: turncald exits 0")


live_session.run_in_temp_dir(main, "turncal-e2e-noise-")
