#!/usr/bin/env python3
"""End to end on ptys over temperature (issue 36): a calibration over temperature, then the
corrected output at two temperatures the calibration never saw.

1. Calibration. `turncal sim --live --controller` plays an industrial MIP IMU in a simulated
   climate chamber stepping 0 -> 20 -> 40 degC (four minutes at each, the die 3 s behind the air)
   and the table cycling the cube's 26 poses through it; turncald runs accel13@T and mag13@T
   (`[thermal] max_pose_span_c = 1`: a pose taken while the die still moves after a step is not
   used). Checks: both calibrations over temperature activated with their gates passed, over
   0 .. 40 degC; every usable pose in the latest fit (the session's last poses are solved once the
   device has been idle: turncald solves what a calibration over temperature deferred); no pose
   the fits used within 3 degC of 10 or 30 degC.
2. Verification. turncald is restarted listening only (configure = false, a socat pty pair): the
   active calibrations come back from the state directory. The same device (same seed, the same
   chamber middle, so the same polynomials in temperature) streams at 10 degC, then 30 degC,
   resting in three poses in turn, with no controller: nothing is calibrated. Over each 8-s rest
   at 10 and at 30 degC the mean corrected acceleration and magnetic field are the simulator's
   true output (plus the bias wander between the calibration's last pose and that rest, from the
   truth files' wander slices) within 3 sigma on every axis: sigma from the calibration's
   covariance at the sample's temperature (acc_sigma, mag_sigma) and the rest's scatter.

Usage: e2e_thermal_test.py TURNCAL TURNCALD
"""
import json
import math
import shutil
import signal
import subprocess
import sys
import time

from live_session import check, cube_poses, run_in_temp_dir, wait_for

TURNCAL, TURNCALD = sys.argv[1], sys.argv[2]
SPEED = 20
# The rest at home before the first move, device seconds: the daemon, started first, measures the
# noise over one second of its clock (20 device seconds) from fresh samples, and the poses keep
# their places in the chamber's steps (the simulator's default with a controller, 3 s of wall
# time, would move them a minute later).
START_S = 25
SEED = 5
SIM = ["--protocol", "mip", "--class", "industrial", "--rate", "100", "--seed", str(SEED),
       "--die-tau", "3", "--self-heating", "0", "--repeat-poses"]
CALIBRATION_CHAMBER = "0; soak 0 240; soak 20 240; soak 40 240"   # middle 20 degC
VERIFICATION_CHAMBER = "10; soak 10 60; soak 30 60"              # middle 20 degC: same device
UNVISITED_C = (10.0, 30.0)
MODELS = ("accel13@T", "mag13@T")
CLOCK_OFFSET_S = 10.0  # the simulated device's clock at session time 0 (sim/session_sim.h)


def config(d, port, configure):
    with open(f"{d}/turncald.toml", "w") as f:
        f.write(f"""socket = "{d}/t.sock"
state_dir = "{d}/state"
[station]
models = ["accel13@T", "mag13@T"]
sensor_class = "industrial"
[sequencer]
dwell_s = 2.0
[thermal]
max_pose_span_c = 1.0
[[device]]
name = "imu"
protocol = "mip"
port = "{port}"
configure = {"true" if configure else "false"}
""")


def start(d, log):
    daemon = subprocess.Popen([TURNCALD, "--config", f"{d}/turncald.toml"],
                              stdout=open(f"{d}/{log}", "w"), stderr=subprocess.STDOUT)
    check(wait_for(f"{d}/t.sock", 30), f"turncald's socket is up ({log})")
    return daemon


def watch(d, name):
    w = subprocess.Popen([TURNCAL, "watch", "--json", "--corrected", "--raw", "--uncertainty",
                          "--socket", f"{d}/t.sock"], stdout=open(f"{d}/{name}", "w"))
    end = time.time() + 30
    while time.time() < end and not open(f"{d}/{name}").readline():
        time.sleep(0.05)  # subscribed once its WATCH line is back
    return w


def result(d):
    out = subprocess.run([TURNCAL, "result", "--socket", f"{d}/t.sock", "--json"],
                         capture_output=True, text=True, timeout=60).stdout
    return json.loads(out)["devices"]["imu"]


def wait_for_fits(d, usable, seconds=120):
    """The result once both models' fits hold `usable` poses (the idle solve), or the last seen."""
    end = time.time() + seconds
    while True:
        r = result(d)
        fitted = [r["models"][m].get("temperature", {}).get("poses") for m in MODELS]
        if all(f == usable for f in fitted) or time.time() > end:
            return r
        time.sleep(0.5)


def mean_slices(slices, t0, t1, t_first, width):
    """Mean of the 1-s wander slices (starting at t_first) that lie inside [t0, t1]."""
    inside = [s for i, s in enumerate(slices) if t0 <= t_first + i * width and
              t_first + (i + 1) * width <= t1 + 1e-9]
    inside = inside or slices
    return [sum(s[k] for s in inside) / len(inside) for k in range(3)]


def calibrate(d):
    cube_poses(TURNCAL, f"{d}/poses.csv", 26)
    config(d, f"{d}/mip", configure=True)
    daemon = start(d, "daemon1.log")
    events = watch(d, "watch1.jsonl")
    sim = subprocess.run(
        [TURNCAL, "sim", *SIM, "--dwell", "4", "--poses", f"{d}/poses.csv", "--chamber",
         CALIBRATION_CHAMBER, "--truth-out", f"{d}/truth1.json", "--live", f"{d}/mip",
         "--controller", f"{d}/t.sock", "--live-speed", str(SPEED), "--answer-timeout", "60",
         "--retries", "5", "--start", str(START_S)], stdout=open(f"{d}/sim1.out", "w"), stderr=subprocess.PIPE, text=True,
        timeout=600)
    check(sim.returncode == 0, "the session in the chamber: every pose captured "
          f"(exit {sim.returncode}) {sim.stderr.strip()[-200:]}")
    time.sleep(0.5)
    captured, refused = [], 0
    for line in open(f"{d}/watch1.jsonl"):
        j = json.loads(line)
        if j.get("class") == "POSE_CAPTURED":
            captured.append(j["record"])
        elif j.get("class") == "ERROR" and "pose not used" in j.get("message", ""):
            refused += 1
    usable = len(captured) - refused // len(MODELS)
    r = wait_for_fits(d, usable)
    for m in MODELS:
        c = r["models"][m]
        t = c.get("temperature", {})
        check(c.get("active_version", 0) >= 1 and c["gate"]["pass"],
              f"{m} active (v{c.get('active_version')}), gate "
              f"{'pass' if c['gate']['pass'] else c['gate']['reasons'][:2]}")
        check(t.get("ok") and t["t_min_c"] <= 1.0 and t["t_max_c"] >= 39.0,
              f"{m} over {t.get('t_min_c')} .. {t.get('t_max_c')} degC")
        check(t.get("poses") == usable, f"{m}: the latest fit holds every usable pose "
              f"({t.get('poses')} of {usable}: {len(captured)} captured, {refused // 2} moving)")
    used = [c for c in captured if c["temp_spread"]["max"] - c["temp_spread"]["min"] <= 1.0]
    nearest = min(abs(x - u) for c in used for u in UNVISITED_C
                  for x in (c["temp_spread"]["min"], c["temp_spread"]["max"]))
    check(nearest >= 3.0, f"no pose used within 3 degC of 10 or 30 degC (nearest {nearest:.2f})")
    events.terminate()
    events.wait()
    daemon.send_signal(signal.SIGTERM)
    check(daemon.wait(timeout=30) == 0, "SIGTERM: turncald exits 0")


def verify(d):
    with open(f"{d}/poses2.csv", "w") as f:
        f.writelines(open(f"{d}/poses.csv").readlines()[:4])
    socat = subprocess.Popen(["socat", f"pty,raw,echo=0,link={d}/device",
                              f"pty,raw,echo=0,link={d}/simend"])
    check(wait_for(f"{d}/device", 10) and wait_for(f"{d}/simend", 10), "socat's pty pair is up")
    config(d, f"{d}/device", configure=False)
    daemon = start(d, "daemon2.log")
    r = result(d)
    check(all(r["models"][m].get("active_version", 0) >= 1 for m in MODELS),
          "the restarted turncald applies the stored calibrations over temperature")
    events = watch(d, "watch2.jsonl")
    sim = subprocess.run(
        [TURNCAL, "sim", *SIM, "--dwell", "8", "--poses", f"{d}/poses2.csv", "--chamber",
         VERIFICATION_CHAMBER, "--truth-out", f"{d}/truth2.json", "--live", f"{d}/simend",
         "--live-speed", str(SPEED)], stdout=open(f"{d}/sim2.out", "w"),
        stderr=subprocess.PIPE, text=True, timeout=300)
    check(sim.returncode == 0, f"the verification streamed (exit {sim.returncode})")
    time.sleep(1.0)
    events.terminate()
    events.wait()
    corrected = [j for j in map(json.loads, open(f"{d}/watch2.jsonl"))
                 if j.get("class") == "CORRECTED" and "acc_sigma" in j and "mag_sigma" in j]
    check(len(corrected) > 5000, f"{len(corrected)} corrected samples with their sigma")

    truth1, truth2 = json.load(open(f"{d}/truth1.json")), json.load(open(f"{d}/truth2.json"))
    width = truth2["thermal"]["wander_slice_s"]
    last = truth1["thermal"]["poses"][-1]  # the calibration's biases: over its last pose
    wander1 = {s: mean_slices(last["wander"][s], last["t_s"], last["dwell_end_s"], last["t_s"],
                              width) for s in ("acc", "mag")}
    compared, worst, flagged = {u: 0 for u in UNVISITED_C}, (0.0, ""), 0
    raw_means = {}  # (pose, temperature) -> the raw means and sigma: how much temperature moves it
    n_truth = len(truth2["poses"])
    for p in truth2["thermal"]["poses"]:
        t0, t1 = p["t_s"] + 0.5, p["dwell_end_s"] - 0.5
        inside = [c for c in corrected if t0 <= c["t_device"] - CLOCK_OFFSET_S <= t1]
        temps = [c["raw"]["temp"] for c in inside if "temp" in c.get("raw", {})]
        if len(inside) < 300 or not temps:
            continue
        temp = sum(temps) / len(temps)
        near = [u for u in UNVISITED_C if abs(temp - u) < 0.5 and max(temps) - min(temps) < 0.2]
        if not near:
            continue  # the die between the two
        flagged += sum(1 for c in inside if "temp_flags" in c)
        compared[near[0]] += 1
        true_output = truth2["poses"][p["index"] % n_truth]["true_output"]
        for s in ("acc", "mag"):
            wander2 = mean_slices(p["wander"][s], t0, t1, p["t_s"], width)
            n = len(inside)
            for k in range(3):
                values = [c[s][k] for c in inside]
                mean = sum(values) / n
                scatter = math.sqrt(sum((v - mean) ** 2 for v in values) / (n - 1) / n)
                cal = sum(c[f"{s}_sigma"][k] for c in inside) / n
                expected = true_output[s][k] + wander2[k] - wander1[s][k]
                z = abs(mean - expected) / math.hypot(scatter, cal)
                worst = max(worst, (z, f"{s}[{k}] at {temp:.2f} degC, pose {p['index']}"))
                raw = sum(c["raw"][s][k] for c in inside) / n
                raw_means.setdefault((p["index"] % n_truth, near[0]), {})[(s, k)] = (
                    raw - wander2[k], math.hypot(scatter, cal))
    check(all(compared[u] >= 3 for u in UNVISITED_C),
          f"rests compared at 10 and 30 degC: {compared[10.0]} and {compared[30.0]}")
    check(flagged == 0, f"no sample inside the range flagged ({flagged})")
    # The check has power: between 10 and 30 degC the raw output of each pose moves by many times
    # the sigma above (a correction that ignored temperature would fail it).
    moved = min((max(abs(a[key][0] - b[key][0]) / b[key][1] for key in a), pose)
                for (pose, u), a in raw_means.items() if u == UNVISITED_C[0]
                for (pose_b, v), b in raw_means.items() if pose_b == pose and v == UNVISITED_C[1])
    check(moved[0] >= 10.0, f"the raw output moves by >= {moved[0]:.0f} sigma between 10 and "
          f"30 degC (pose {moved[1]})")
    check(worst[0] <= 3.0, f"corrected output at unvisited temperatures: largest |mean - truth| = "
          f"{worst[0]:.2f} sigma ({worst[1]})")
    daemon.send_signal(signal.SIGTERM)
    check(daemon.wait(timeout=30) == 0, "SIGTERM: turncald exits 0")
    socat.terminate()


def main(d):
    if not shutil.which("socat"):
        print("skipped: socat is not installed")
        return
    calibrate(d)
    verify(d)


run_in_temp_dir(main, "turncal-e2e-thermal-")
