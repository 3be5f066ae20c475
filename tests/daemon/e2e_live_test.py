#!/usr/bin/env python3
"""End to end through real ptys and the real socket (issue "The daemon", acceptance).

`turncal sim --live --controller` plays a turntable carrying a simulated MIP and a simulated Xbus
IMU: it creates a pty per device, answers turncald's configuration dialogues through the device
emulator, announces 26 poses on turncald's socket and holds the table until both devices answered.
turncald runs on the two ptys. Scenarios (each a fresh state directory):

  clean  the session runs through; both devices end with active accel13 and mag13 calibrations
         whose parameters are within 4 sigma of the simulator's truth; corrected samples from
         `turncal watch --json --corrected --uncertainty` match the true specific force and field
         of their pose within 4 sigma (calibration sigma from the sample, noise from the window's
         scatter, bias wander from the sensor class); `turncald --replay REC --once` on the
         session turncald recorded gives the same estimates (within 1e-3 sigma).
  kill   kill -9 turncald once pose 13 is answered, start it again: it reports the 13 poses
         from its journal, the controller announces the rest, and the session finishes with 26.

Usage: e2e_live_test.py TURNCAL TURNCALD [clean|kill|all]
"""
import json
import os
import re
import signal
import subprocess
import sys
import tempfile
import time

from live_session import check, failures, gap_free, in_window, wait_for
import live_session

TURNCAL, TURNCALD = sys.argv[1], sys.argv[2]
WHICH = sys.argv[3] if len(sys.argv) > 3 else "all"
SPEED = 10
N_POSES = 26






def start_daemon(d, log_name, record=None):
    args = [TURNCALD, "--device", f"imu1=mip:{d}/mip", "--device", f"imu2=xbus:{d}/xbus",
            "--socket", f"{d}/t.sock", "--state-dir", f"{d}/state"]
    if record:
        args += ["--record", record]
    return subprocess.Popen(args, stdout=open(f"{d}/{log_name}", "w"), stderr=subprocess.STDOUT)






def answers(d):
    """{index: {device: class}} from the simulator's output."""
    out = {}
    for line in open(f"{d}/sim.out"):
        j = json.loads(line)
        if j.get("event") == "answer":
            out.setdefault(j["index"], {})[j["device"]] = j["class"]
    return out


def client(d, *args):
    r = subprocess.run([TURNCAL, *args, "--socket", f"{d}/t.sock", "--json"],
                       capture_output=True, text=True, timeout=30)
    return r.returncode, r.stdout


def check_truth(result, truth, label):
    """Every parameter of every active model within 4 sigma of the truth."""
    for i, name in enumerate(["imu1", "imu2"]):
        t = truth["devices"][i]
        dev = result["devices"][name]
        check(dev["poses"] == N_POSES, f"{label}: {name} has {dev['poses']} poses (want {N_POSES})")
        for model, m in dev["models"].items():
            check(m["active_version"] >= 1 and m["gate"]["pass"],
                  f"{label}: {name} {model} active (v{m['active_version']}), gate "
                  f"{'pass' if m['gate']['pass'] else m['gate']['reasons']}")
            worst = live_session.worst_sigma(m, t, model)
            check(worst[0] <= 4.0, f"{label}: {name} {model}: largest |estimate - truth| = "
                  f"{worst[0]:.2f} sigma ({worst[1]})")


def check_corrected(d, truth, result):
    """Corrected samples in each captured window against the pose's true output."""
    records = {}  # (device, index) -> pose record
    in_stream = {}  # (device, index) -> samples the window saw (used, outliers and flagged)
    lines = {}  # device -> [CORRECTED line]
    for line in open(f"{d}/watch.jsonl"):
        j = json.loads(line)
        if j.get("class") == "POSE_CAPTURED":
            records[(j["device"], j["index"])] = j["record"]
            c = j["counts"]
            in_stream[(j["device"], j["index"])] = c["used"] + c["outliers"] + c["flagged"]
        elif j.get("class") == "CORRECTED":
            lines.setdefault(j["device"], []).append(j)
    # Every CORRECTED line carries the sensor time of the records' windows: where the watcher
    # lost no line, a window holds exactly the samples the sequencer saw in it (the record's and
    # the outliers and flagged samples it left out).
    exact, counted = 0, 0
    for (device, index), r in records.items():
        inside = in_window(lines.get(device, []), r)
        if gap_free(lines.get(device, []), inside):
            counted += 1
            exact += len(inside) == in_stream[(device, index)]
    check(counted >= 10 and exact == counted,
          f"the lines whose t_sensor is in a record's window are its samples: {exact} of "
          f"{counted} windows without a lost line")
    compared = 0
    worst = (0.0, "")
    for i, name in enumerate(["imu1", "imu2"]):
        t = truth["devices"][i]
        for (device, index), r in records.items():
            if device != name:
                continue
            inside = [s for s in in_window(lines.get(name, []), r) if "acc_sigma" in s]
            if len(inside) < 20:
                continue  # before the first active calibration
            for z, axis in live_session.window_z(inside, t["poses"][index]["true_output"], t):
                worst = max(worst, (z, f"{name} pose {index} {axis}"))
            compared += 1
    check(compared >= 20, f"corrected output compared at {compared} captured windows")
    check(worst[0] <= 4.0, f"corrected output: largest |mean - truth| = {worst[0]:.2f} sigma "
          f"({worst[1]})")


def scenario_clean(d):
    daemon = start_daemon(d, "daemon.log", record=f"{d}/live.tcap")
    sim = live_session.start_sim(TURNCAL, d, 11, SPEED)
    wait_for(f"{d}/t.sock")
    time.sleep(0.3)
    watch = subprocess.Popen([TURNCAL, "watch", "--json", "--corrected", "--uncertainty",
                              "--socket", f"{d}/t.sock"], stdout=open(f"{d}/watch.jsonl", "w"))
    rc = sim.wait(timeout=300)
    time.sleep(0.5)
    check(rc == 0, f"clean: the simulator's session ended with every pose captured (exit {rc}): "
          + open(f"{d}/sim.err").read().strip())
    code, out = client(d, "result")
    live = json.loads(out)
    truth = json.load(open(f"{d}/truth.json"))
    check_truth(live, truth, "clean")
    watch.terminate()
    watch.wait()
    check_corrected(d, truth, live)
    code, out = client(d, "status")
    status = json.loads(out)
    for name, s in status["devices"].items():
        check(s["counters"]["bad_checksums"] == 0 and s["identity"] is not None,
              f"status: {name} configured by its dialogue ({s['identity'].get('protocol')}), "
              f"0 bad checksums, {s['counters']['samples']} samples")
    solve, loop = status["solve_ms"], status["loop_ms"]
    check(loop["max"] < 5, f"pose updates run off the event loop: a captured pose took at most "
          f"{loop['max']:.1f} ms of its CPU; the worker's longest update (solve, observability, gate) "
          f"{solve['max']:.1f} ms")
    # Samples lost in the daemon's streams (device-clock or counter gaps after streaming began):
    # only those the emulator withheld while the daemon had it idle, and those the simulator
    # dropped because nobody read its pty for a wall second (its queue), may be missing: every
    # frame written reached a sample. Whether the daemon keeps up at all is a speed target, met
    # in the load benchmark on a quiet host (docs/PERFORMANCE.md); here a host that does not
    # schedule the daemon for a second (CI beside other machines) is reported, not failed.
    sim_err = open(f"{d}/sim.err").read()
    withheld = sum(int(w) for w in re.findall(r"(\d+) withheld", sim_err))
    dropped = sum(int(w) for w in re.findall(r"(\d+) dropped \(unread\)", sim_err))
    lost = sum(s["station"]["samples"]["lost"] for s in status["devices"].values())
    check(lost <= withheld + dropped, f"{lost} samples lost in the streams (at most the {withheld} "
          f"withheld during configuration and the {dropped} the simulator dropped unread)")
    if dropped:
        runs = [l.strip() for l in open(f"{d}/sim.out") if '"event":"dropped"' in l]
        print(f"note: the simulator dropped {dropped} frames nobody read for a wall second, in "
              f"{len(runs)} run(s): " + " ".join(runs[:5]), flush=True)
    daemon.send_signal(signal.SIGTERM)
    check(daemon.wait(timeout=20) == 0, "SIGTERM: turncald exits 0")
    # The daemon wrote each device's report with its active calibrations (the last one at the
    # latest when it stopped), every model in it.
    for name, dev in live["devices"].items():
        path = f"{d}/state/reports/{name}.html"
        html = open(path).read() if os.path.exists(path) else ""
        versions = {m: v["active_version"] for m, v in dev["models"].items()}
        ok = all(f'id="residuals-{m}"' in html and f'id="convergence-{m}"' in html
                 for m in dev["models"])
        check(ok, f"{path}: the report holds every model's plots ({len(html)} bytes; active "
              f"versions {versions})")
    r = subprocess.run([TURNCALD, "--replay", f"{d}/live.tcap", "--once", "--result-out",
                        f"{d}/replay.json"], capture_output=True, text=True, timeout=300)
    check(r.returncode == 0, f"turncald --replay live.tcap --once (exit {r.returncode})")
    replay = json.load(open(f"{d}/replay.json"))
    worst = (0.0, "")
    for name, dev in live["devices"].items():
        check(replay["devices"][name]["poses"] == dev["poses"],
              f"replay: {name} {replay['devices'][name]['poses']} poses, live {dev['poses']}")
        for model, m in dev["models"].items():
            for p, v in m["params"].items():
                w = replay["devices"][name]["models"][model]["params"][p]
                if v["sigma"]:
                    worst = max(worst, (abs(w["value"] - v["value"]) / v["sigma"], f"{name} {model} {p}"))
    check(worst[0] <= 1e-6, f"replay vs live: largest difference {worst[0]:.2e} sigma ({worst[1]})")


def scenario_kill(d):
    daemon = start_daemon(d, "daemon1.log")
    sim = live_session.start_sim(TURNCAL, d, 12, SPEED)
    deadline = time.time() + 200
    while time.time() < deadline:
        a = answers(d)
        if len(a.get(12, {})) == 2:
            break
        time.sleep(0.02)
    daemon.send_signal(signal.SIGKILL)
    daemon.wait()
    before = answers(d)
    check(len(before.get(12, {})) == 2, "kill: pose 13 answered by both devices before kill -9")
    time.sleep(0.5)
    daemon = start_daemon(d, "daemon2.log")
    rc = sim.wait(timeout=300)
    check(rc == 0, "kill: the session finished with every pose captured after the restart: "
          + open(f"{d}/sim.err").read().strip())
    log = open(f"{d}/daemon2.log").read()
    resumed = [json.loads(l[l.index("{"):]) for l in log.splitlines() if "SESSION_RESUMED" in l]
    poses = {r["device"]: r["poses"] for r in resumed}
    check(poses.get("imu1", 0) >= 13 and poses.get("imu2", 0) >= 13,
          f"kill: the restarted daemon resumed with {poses} poses from its journal")
    code, out = client(d, "result")
    check_truth(json.loads(out), json.load(open(f"{d}/truth.json")), "kill")
    daemon.send_signal(signal.SIGTERM)
    daemon.wait(timeout=20)


for name, fn in (("clean", scenario_clean), ("kill", scenario_kill)):
    if WHICH not in ("all", name):
        continue
    d = tempfile.mkdtemp(prefix=f"turncal-e2e-{name}-")
    try:
        live_session.cube_poses(TURNCAL, f"{d}/poses.csv", N_POSES)
        fn(d)
    finally:
        live_session.finish_dir(d)

print(f"e2e: {len(failures)} failure(s)")
sys.exit(1 if failures else 0)
