#!/usr/bin/env python3
"""End to end on ptys with a gyroscope (issue 21): static poses and rate segments in one session.

`turncal sim --live --controller` plays the table with one simulated MIP IMU whose gyro follows a
gyro12 truth: 14 static cube poses with 8 rate segments between them (+-100 deg/s about the inner,
middle and outer axes, and the outer with the middle at 90 deg), announced on turncald's socket as
`pose` and `rate` commands. turncald runs accel13, mag13 and gyro12. Checks:
  - every pose and rate segment captured; accel13, mag13 and gyro12 active with every parameter
    within 4 sigma of the simulator's truth;
  - `turncal watch --corrected --uncertainty` streams corrected gyro rates (gyr_frame, gyr_sigma):
    over each captured rate segment's window, the mean corrected rate's magnitude is the table's
    inertial rate's within 4 sigma (scatter, calibration sigma and the gyro's bias instability);
  - `turncal rate` from a shell reaches the daemon: a zero rate is refused with the reason.

Usage: e2e_gyro_test.py TURNCAL TURNCALD
"""
import json
import math
import signal
import subprocess
import sys
import tempfile
import time

from live_session import check, run_in_temp_dir, start_daemon_on_mip, wait_for, worst_sigma

TURNCAL, TURNCALD = sys.argv[1], sys.argv[2]
SPEED = 10
EARTH_RATE = 7.292115e-5


def write_poses(path):
    """14 cube directions with the 8 rate segments of 100 deg/s after the first of them."""
    with tempfile.TemporaryDirectory() as t:
        subprocess.run([TURNCAL, "sim", "--protocol", "gx2", "-o", f"{t}/p.tcap",
                        "--truth-out", f"{t}/t.json"], check=True, capture_output=True)
        cube = json.load(open(f"{t}/t.json"))["poses"][:14]
    rates = [(0, 0, 0, "inner"), (0, 0, 0, "middle"), (0, 0, 0, "outer"), (0, 90, 0, "outer")]
    segments = [(p, g, s, a, r) for r in (100, -100) for (p, g, s, a) in rates]
    with open(path, "w") as f:
        f.write("phi,gamma,psi,axis,rate_dps\n")
        for i, c in enumerate(cube):
            f.write(f"{c['phi_deg']},{c['gamma_deg']},{c['psi_deg']}\n")
            if i < len(segments):
                f.write("{},{},{},{},{}\n".format(*segments[i]))
    return len(cube) + len(segments)


def main(d):
    n_poses = write_poses(f"{d}/poses.csv")
    daemon = start_daemon_on_mip(TURNCALD, d, ["accel13", "mag13", "gyro12"])
    sim = subprocess.Popen(
        [TURNCAL, "sim", "--protocol", "mip", "--model", "gyro12", "--live", f"{d}/mip",
         "--controller", f"{d}/t.sock", "--live-speed", str(SPEED), "--poses", f"{d}/poses.csv",
         "--seed", "21", "--truth-out", f"{d}/truth.json", "--answer-timeout", "60",
         "--retries", "5"],
        stdout=open(f"{d}/sim.out", "w"), stderr=open(f"{d}/sim.err", "w"))
    check(wait_for(f"{d}/t.sock", 30), "turncald's socket is up")
    watch = subprocess.Popen([TURNCAL, "watch", "--json", "--corrected", "--uncertainty",
                              "--socket", f"{d}/t.sock"], stdout=open(f"{d}/watch.jsonl", "w"))
    rc = sim.wait(timeout=300)
    check(rc == 0, f"the session ended with every pose and rate segment captured (exit {rc}): "
          + open(f"{d}/sim.err").read().strip())

    # `turncal rate` from a shell reaches the daemon, which checks it (a wrong rate on a turning
    # table is rejected by the sequencer: tests/core/sequencer_rate_test.cc).
    r = subprocess.run([TURNCAL, "rate", "inner", "0", "--socket", f"{d}/t.sock"],
                       capture_output=True, text=True, timeout=60)
    check(r.returncode == 2 and "'rate_dps' must be a finite non-zero number" in r.stderr,
          f"turncal rate inner 0: exit {r.returncode}, {r.stderr.strip()[-120:]}")

    out = subprocess.run([TURNCAL, "result", "--socket", f"{d}/t.sock", "--json"],
                         capture_output=True, text=True, timeout=30).stdout
    result = json.loads(out)["devices"]["imu"]
    truth = json.load(open(f"{d}/truth.json"))
    check(result["poses"] >= n_poses, f"{result['poses']} records (want {n_poses})")
    for model in ("accel13", "mag13", "gyro12"):
        m = result["models"].get(model)
        if m is None:
            check(False, f"{model} in the result")
            continue
        check(m["active_version"] >= 1 and m["gate"]["pass"],
              f"{model} active (v{m['active_version']}), gate "
              f"{'pass' if m['gate']['pass'] else m['gate']['reasons']}")
        worst = worst_sigma(m, truth, model)
        check(worst[0] <= 4.0, f"{model}: largest |estimate - truth| = {worst[0]:.2f} sigma "
              f"({worst[1]})")
    watch.terminate()
    watch.wait()

    # Corrected gyro rates over each captured rate segment's window (the window is in sending
    # times; a CORRECTED line carries its read time, at most a few tens of ms later: the window is
    # shrunk by 0.2 s at both ends).
    windows, corrected = [], []
    for line in open(f"{d}/watch.jsonl"):
        j = json.loads(line)
        if j.get("class") == "POSE_CAPTURED" and "rate_axis" in j.get("pose", {}):
            r = j["record"]
            windows.append((j["index"], r["t_start"], r["t_end"], abs(j["pose"]["rate_dps"])))
        elif j.get("class") == "CORRECTED" and "gyr_frame" in j:
            corrected.append(j)
    check(len(corrected) > 0 and all("gyr_sigma" in c for c in corrected),
          f"{len(corrected)} CORRECTED samples carry the corrected gyro with gyr_sigma")
    inst = truth["gyr_bias_instability"]
    compared, worst = 0, (0.0, "")
    for index, t0, t1, rate_dps in windows:
        inside = [c for c in corrected if t0 + 0.2 <= c["t_host_ns"] * 1e-9 <= t1 - 0.2]
        if len(inside) < 50:
            continue  # before gyro12's first active calibration
        n = len(inside)
        mean = [sum(c["gyr"][k] for c in inside) / n for k in range(3)]
        scatter = math.sqrt(sum(sum((c["gyr"][k] - mean[k]) ** 2 for c in inside)
                                for k in range(3)) / (n - 1) / n)
        cal = max(max(c["gyr_sigma"]) for c in inside)
        sigma = math.sqrt(scatter ** 2 + cal ** 2 + 3 * inst ** 2) + 1e-4 * rate_dps * math.pi / 180
        # The inertial rate's magnitude: the table's plus the Earth's share along the axis.
        z = abs(math.sqrt(sum(x * x for x in mean)) - rate_dps * math.pi / 180) / sigma
        z_earth = EARTH_RATE / sigma
        worst = max(worst, (max(0.0, z - z_earth), f"rate segment {index}"))
        compared += 1
    check(compared >= 4, f"corrected gyro compared over {compared} rate segments")
    check(worst[0] <= 4.0, f"corrected gyro: largest | |mean| - rate | = {worst[0]:.2f} sigma "
          f"({worst[1]})")
    daemon.send_signal(signal.SIGTERM)
    check(daemon.wait(timeout=20) == 0, "SIGTERM: turncald exits 0")


run_in_temp_dir(main, "turncal-e2e-gyro-")
