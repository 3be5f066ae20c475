#!/usr/bin/env python3
"""End to end on a pty without a table (issue 22, the free pose source): `turncal sim --live`
streams a simulated MIP IMU tumbled through 20 random orientations into a pty pair (socat) at 10x
real time, with no controller; turncald runs `pose_source = "free"` with accel9 and magellipsoid,
listening only (configure = false). Checks:
  - turncald finds the static intervals itself (at least 18 of 20; a host that freezes may cost
    one) and activates accel9 and magellipsoid (its samples in motion too), written to the state
    directory;
  - `turncal status` and `turncal result` say free mode; `turncal next-pose` names an orientation
    to add; `turncal pose` is refused with the reason;
  - `turncal watch --corrected --uncertainty` streams samples corrected with the free
    calibrations: over the session after the first activation, the mean of |acc| is gravity's
    magnitude and the mean of |mag| the field's, each within 4 sigma (the samples' scatter and the
    calibration's sigma), in the "accelerometer" and "magnetometer" frames; the raw means are not.

The sequencer times a MIP device by its own clock, so the 10x changes nothing it judges but the
start-up noise measurement, timed on the host's clock: 0.1 s of it is the simulator's 1 s rest.

Usage: e2e_free_test.py TURNCAL TURNCALD
"""
import json
import math
import os
import random
import shutil
import signal
import subprocess
import sys
import time

from live_session import check, run_in_temp_dir, wait_for
import live_session

TURNCAL, TURNCALD = sys.argv[1], sys.argv[2]
SPEED = 10
GRAVITY = math.sqrt(0.0167**2 + 9.7782**2)               # the simulator's |g_NED|
FIELD = math.sqrt(0.2523**2 + 0.0217**2 + 0.4004**2)     # |B_NED|, Gauss


def main(d):
    if not shutil.which("socat"):
        print("skipped: socat is not installed")
        return
    rng = random.Random(22)
    with open(f"{d}/poses.csv", "w") as f:
        f.write("phi,gamma,psi\n")
        # 16 orientations for the gates, then 4 more whose samples are corrected (the fits of
        # the magnetometer's samples in motion take a while; the stream must outlast them).
        for _ in range(20):
            f.write(f"{rng.uniform(-180, 180):.2f},{rng.uniform(-90, 90):.2f},"
                    f"{rng.uniform(-180, 180):.2f}\n")
    with open(f"{d}/turncald.toml", "w") as f:
        f.write(f"""[station]
pose_source = "free"
models = ["accel9", "magellipsoid"]
[sequencer]
startup_s = 0.1
[gate]
scale_factor = 300e-6
[[device]]
name = "imu"
protocol = "mip"
port = "{d}/device"
configure = false
""")
    socat, daemon = live_session.start_on_pty_pair(TURNCALD, d)
    watch = subprocess.Popen([TURNCAL, "watch", "--json", "--corrected", "--raw", "--uncertainty",
                              "--socket", f"{d}/t.sock"], stdout=open(f"{d}/watch.jsonl", "w"))
    # The live guidance as an operator's log (standard output not a terminal): a line per tenth of
    # the sphere the magnetometer's coverage fills, with what to do next.
    watch_log = subprocess.Popen([TURNCAL, "watch", "--socket", f"{d}/t.sock"],
                                 stdout=open(f"{d}/watch.log", "w"))
    time.sleep(0.5)  # the watch subscribed (its first line comes back at once)
    sim = subprocess.run(
        [TURNCAL, "sim", "--protocol", "mip", "--live", f"{d}/sim", "--live-speed", str(SPEED),
         "--poses", f"{d}/poses.csv", "--dwell", "3", "--seed", "22", "--truth-out",
         f"{d}/truth.json"], stdout=open(f"{d}/sim.out", "w"), stderr=subprocess.PIPE, text=True,
        timeout=300)
    check(sim.returncode == 0, f"the simulated tumble streamed (exit {sim.returncode}) "
          + sim.stderr.strip()[-200:])

    def result():
        out = subprocess.run([TURNCAL, "result", "--socket", f"{d}/t.sock", "--json"],
                             capture_output=True, text=True, timeout=30).stdout
        return json.loads(out)["devices"]["imu"]

    # The last interval ends with the stream; its fit runs on the worker: wait for it (the
    # magellipsoid's intervals include the magnetometer's samples in motion, issue 37).
    end = time.time() + 120
    r = result()
    while time.time() < end and not all(
            r["models"].get(m, {}).get("intervals", 0) -
            r["models"].get(m, {}).get("motion_points", 0) == r["poses"] and r["poses"] > 0
            for m in ("accel9", "magellipsoid")):
        time.sleep(0.2)
        r = result()
    check(r.get("pose_source") == "free", f"result: pose source {r.get('pose_source')}")
    check(r["poses"] >= 18, f"{r['poses']} static intervals found of 20 orientations "
          f"({r['free']['skipped']} still segments skipped)")
    for name in ("accel9", "magellipsoid"):
        m = r["models"].get(name, {})
        check(m.get("active_version", 0) >= 1 and m.get("gate", {}).get("pass"),
              f"{name}: active v{m.get('active_version')}, gate {m.get('gate')}")
        check(os.path.exists(f"{d}/state/calibrations/imu.{name}.json"),
              f"{name}: calibrations/imu.{name}.json written")

    status = subprocess.run([TURNCAL, "status", "--socket", f"{d}/t.sock"], capture_output=True,
                            text=True, timeout=30).stdout
    check("free mode: intervals" in status, "turncal status says free mode")
    nxt = subprocess.run([TURNCAL, "next-pose", "--socket", f"{d}/t.sock"], capture_output=True,
                         text=True, timeout=30)
    check(nxt.returncode == 0 and "next orientation for imu" in nxt.stdout and " up" in nxt.stdout,
          f"turncal next-pose: {nxt.stdout.strip()[-160:]}")
    pose = subprocess.run([TURNCAL, "pose", "0", "0", "0", "--socket", f"{d}/t.sock"],
                          capture_output=True, text=True, timeout=30)
    check(pose.returncode != 0 and "free mode" in pose.stderr,
          f"turncal pose refused: exit {pose.returncode}, {pose.stderr.strip()[-140:]}")
    # A free calibration's plan for the device (issue 23), refused here because turncald only
    # listens (configure = false): it has not read what the device stores.
    plan = subprocess.run([TURNCAL, "device-write", "imu", "--model", "magellipsoid", "--dry-run",
                           "--socket", f"{d}/t.sock"], capture_output=True, text=True, timeout=30)
    check(plan.returncode == 1 and "write magellipsoid v" in plan.stdout and
          "REFUSED: imu has not told turncald what it stores" in plan.stdout and
          "configure = false" in plan.stdout,
          f"device-write --dry-run of magellipsoid plans and refuses: exit {plan.returncode}, "
          f"{plan.stdout.strip()} {plan.stderr.strip()}")

    watch.terminate()
    watch.wait()
    watch_log.terminate()
    watch_log.wait()
    # The magnetometer's coverage while it filled (COVERAGE, every half second of values).
    coverage = [j for j in map(json.loads, open(f"{d}/watch.jsonl")) if j.get("class") == "COVERAGE"]
    check(len(coverage) >= 10 and all(len(j["rows"]) == 18 for j in coverage) and
          coverage[-1]["fraction"] > coverage[0]["fraction"] and
          coverage[-1]["centre"] == "the magellipsoid fit",
          f"{len(coverage)} COVERAGE events, "
          f"{coverage[0]['fraction'] if coverage else 0:.3f} to "
          f"{coverage[-1]['fraction'] if coverage else 0:.3f} of the sphere, centred by "
          f"{coverage[-1]['centre'] if coverage else None}")
    log = open(f"{d}/watch.log").read()
    check("imu: magnetometer coverage" in log and "points along the field" in log and
          "values in motion: gate" in log,
          "turncal watch logs the coverage, the region to turn into and the fits: " +
          " | ".join(line[:120] for line in log.splitlines() if "coverage" in line)[:400])
    # Corrected samples after both calibrations applied.
    rows = []
    for line in open(f"{d}/watch.jsonl"):
        j = json.loads(line)
        if j.get("class") == "CORRECTED" and "acc_frame" in j and "mag_frame" in j:
            rows.append(j)
    check(len(rows) > 500, f"{len(rows)} samples corrected by both free calibrations")
    if len(rows) > 500:
        check(all(j["acc_frame"] == "accelerometer" and j["mag_frame"] == "magnetometer"
                  for j in rows), "frames: accelerometer and magnetometer")
        for key, magnitude in (("acc", GRAVITY), ("mag", FIELD)):
            norms = [math.sqrt(sum(x * x for x in j[key])) for j in rows]
            raw = [math.sqrt(sum(x * x for x in j["raw"][key])) for j in rows]
            n = len(norms)
            mean = sum(norms) / n
            scatter = math.sqrt(sum((x - mean) ** 2 for x in norms) / (n - 1) / n)
            cal = max(max(j[f"{key}_sigma"]) for j in rows)
            z = abs(mean - magnitude) / math.sqrt(scatter**2 + cal**2)
            z_raw = abs(sum(raw) / n - magnitude) / math.sqrt(scatter**2 + cal**2)
            check(z <= 4.0, f"corrected |{key}| mean {mean:.6f} vs {magnitude:.6f}: {z:.2f} sigma "
                  f"(raw: {z_raw:.0f} sigma)")
    daemon.send_signal(signal.SIGTERM)
    check(daemon.wait(timeout=20) == 0, "SIGTERM: turncald exits 0")
    socat.terminate()


run_in_temp_dir(main, "turncal-e2e-free-")
