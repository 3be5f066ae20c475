"""What the end-to-end scripts share (e2e_live_test.py, faults_test.py): ok/FAIL lines, the cube
poses as CSV, waiting for a path, and `turncal sim --live --controller` with a simulated MIP and
Xbus IMU on one table (ptys DIR/mip and DIR/xbus, turncald's socket DIR/t.sock)."""
import json
import math
import os
import shutil
import signal
import subprocess
import sys
import tempfile
import time

failures = []


def check(ok, message):
    print(("ok   " if ok else "FAIL ") + message, flush=True)
    if not ok:
        failures.append(message)


def cube_poses(turncal, path, n_poses):
    """The first n_poses of the simulator's default plan (the cube directions), as CSV."""
    with tempfile.TemporaryDirectory() as d:
        subprocess.run([turncal, "sim", "--protocol", "gx2", "-o", f"{d}/p.tcap",
                        "--truth-out", f"{d}/t.json"], check=True, capture_output=True)
        poses = json.load(open(f"{d}/t.json"))["poses"][:n_poses]
    with open(path, "w") as f:
        f.write("phi,gamma,psi\n")
        for p in poses:
            f.write(f"{p['phi_deg']},{p['gamma_deg']},{p['psi_deg']}\n")


def wait_for(path, seconds=10):
    end = time.time() + seconds
    while time.time() < end and not os.path.exists(path):
        time.sleep(0.05)
    return os.path.exists(path)


def start_sim(turncal, d, seed, speed, *extra):
    """The simulated table with its two IMUs, playing the controller on DIR/t.sock."""
    return subprocess.Popen(
        [turncal, "sim", "--protocol", "mip", "--protocol", "xbus", "--live", f"{d}/mip",
         "--live", f"{d}/xbus", "--controller", f"{d}/t.sock", "--live-speed", str(speed),
         "--poses", f"{d}/poses.csv", "--seed", str(seed), "--truth-out", f"{d}/truth.json",
         "--answer-timeout", "60", "--retries", "5", *extra],
        stdout=open(f"{d}/sim.out", "w"), stderr=open(f"{d}/sim.err", "w"))


def worst_sigma(model_result, device_truth, model):
    """Largest |estimate - truth| / sigma over a model's parameters, and which parameter. The
    truth file holds what each parameter estimates (the biases: over the last pose)."""
    worst = (0.0, "")
    for p, v in model_result["params"].items():
        true = device_truth["models"][model][p]
        if v["sigma"] is None:
            continue
        worst = max(worst, (abs(v["value"] - true) / v["sigma"], p))
    return worst


def finish_dir(d):
    """Kills what still runs in the temporary directory DIR, then keeps it when a check failed or
    TURNCAL_KEEP_E2E is set (and says so), or removes it."""
    for p in subprocess.run(["pgrep", "-f", d], capture_output=True, text=True).stdout.split():
        os.kill(int(p), signal.SIGKILL)
    if failures or os.environ.get("TURNCAL_KEEP_E2E"):
        print(f"(kept {d} for inspection)")
    else:
        shutil.rmtree(d, ignore_errors=True)


def run_in_temp_dir(main, prefix):
    """main(DIR) in a new temporary directory, then finish_dir(DIR); the end line `e2e: N
    failure(s)` and exit 1 on a failure, 0 otherwise (an exception propagates after the clean-up)."""
    d = tempfile.mkdtemp(prefix=prefix)
    try:
        main(d)
    finally:
        finish_dir(d)
    print(f"e2e: {len(failures)} failure(s)")
    sys.exit(1 if failures else 0)


def start_on_pty_pair(turncald, d):
    """A socat pty pair (the daemon's end DIR/device, the simulator's DIR/sim) and turncald on
    DIR/turncald.toml (socket DIR/t.sock, state DIR/state, log DIR/daemon.log), each checked up.
    Returns (socat, turncald)."""
    socat = subprocess.Popen(["socat", f"pty,raw,echo=0,link={d}/device",
                              f"pty,raw,echo=0,link={d}/sim"])
    check(wait_for(f"{d}/device", 10) and wait_for(f"{d}/sim", 10), "socat's pty pair is up")
    daemon = subprocess.Popen(
        [turncald, "--config", f"{d}/turncald.toml", "--socket", f"{d}/t.sock", "--state-dir",
         f"{d}/state"], stdout=open(f"{d}/daemon.log", "w"), stderr=subprocess.STDOUT)
    check(wait_for(f"{d}/t.sock", 30), "turncald's socket is up")
    return socat, daemon


def start_daemon_on_mip(turncald, d, models):
    """turncald with [station] models = MODELS on one MIP device, imu on the pty DIR/mip; its
    socket DIR/t.sock, state DIR/state, configuration DIR/turncald.toml, log DIR/daemon.log."""
    with open(f"{d}/turncald.toml", "w") as f:
        f.write("[station]\nmodels = [" + ", ".join(f'"{m}"' for m in models) + "]\n")
    return subprocess.Popen(
        [turncald, "--config", f"{d}/turncald.toml", "--device", f"imu=mip:{d}/mip", "--socket",
         f"{d}/t.sock", "--state-dir", f"{d}/state"],
        stdout=open(f"{d}/daemon.log", "w"), stderr=subprocess.STDOUT)


def in_window(lines, record):
    """The CORRECTED lines of a pose record's window: those whose sensor time ("t_sensor", the
    clock of the record's t_sensor_start and t_sensor_end) is in [t_sensor_start, t_sensor_end):
    the first sample's time, the last one's plus one sample period (docs/protocol.md). Exact
    however the daemon's reads bunched up under load; 0.1 ms of slack for the device clock's
    jitter (a sample period is 1 ms or more)."""
    t0, t1 = record["t_sensor_start"] - 1e-4, record["t_sensor_end"] - 1e-4
    return [j for j in lines if "t_sensor" in j and t0 <= j["t_sensor"] < t1]


def gap_free(lines, inside):
    """True when no line of the stream is missing in or next to the window's lines INSIDE (a slow
    client drops lines): the device times around them step by at most 1.5 sample periods."""
    if len(inside) < 2:
        return False
    times = [j["t_device"] for j in lines]
    steps = sorted(b - a for a, b in zip(times, times[1:]) if b > a)
    period = steps[len(steps) // 2]
    first = next(k for k, j in enumerate(lines) if j is inside[0])
    last = first + len(inside) - 1
    if first == 0 or last + 1 >= len(lines) or lines[last] is not inside[-1]:
        return False
    span = times[first - 1:last + 2]
    return all(0 < b - a <= 1.5 * period for a, b in zip(span, span[1:]))


def window_z(inside, true, device_truth):
    """|mean - truth| / sigma of each axis of both triads over a record window's corrected lines
    INSIDE (each with acc_sigma and mag_sigma), against TRUE (the pose's true_output): sigma
    combines the window's scatter of the mean, the largest calibration sigma of its lines and the
    class's bias instability. [(z, "acc[k]")]."""
    out = []
    n = len(inside)
    for triad, inst in (("acc", device_truth["acc_bias_instability"]),
                        ("mag", device_truth["mag_bias_instability"])):
        for k in range(3):
            xs = [s[triad][k] for s in inside]
            mean = sum(xs) / n
            scatter = math.sqrt(sum((x - mean) ** 2 for x in xs) / (n - 1) / n)
            cal = max(s[f"{triad}_sigma"][k] for s in inside)
            sigma = math.sqrt(scatter ** 2 + cal ** 2 + inst ** 2)
            out.append((abs(mean - true[triad][k]) / sigma, f"{triad}[{k}]"))
    return out
