#!/usr/bin/env python3
"""Issue 38 end to end on ptys: a fixture of 8 units on one simulated table.

`turncal sim --live --controller` streams 8 simulated IMUs (MIP and Xbus alternating, each with
its own serial and truth) in 4 orientations, 2 units each, and plays the table's controller on
turncald's socket. turncald has the fixture's 8 slots in turncald.toml, and a 9th unit whose pty
never sends a byte. Along the way:

  - unit 3 sits in its slot rotated (the simulator mounts it "-y+x+z", its slot says "+x-y-z"):
    it is named (MOUNT), its calibrations are held; the test sets its mount and sends SIGHUP, and
    the poses already taken calibrate it;
  - unit 5's pty goes away in the middle of pose 6 and comes back (--unplug): it resumes;
  - the 9th unit never streams: the batch goes on and `status` says what it waits for.

Checked: every gate of the 8 passes; their parameters are within 4 sigma of the truth; their
corrected output (`turncal watch --corrected --uncertainty`) against the true output at their
last 4 poses; the batch slot by slot in `status` (8 passed, each with its time, the 9th waiting
and why), on every calibration, and in the report's summary; the daemon's loop and solve times.

Usage: e2e_batch_test.py TURNCAL TURNCALD
"""
import json
import math
import os
import signal
import subprocess
import sys
import time

from live_session import check, failures, in_window, wait_for
import live_session

TURNCAL, TURNCALD = sys.argv[1], sys.argv[2]
SPEED = 10
N_POSES = 12
UNITS = 8
PROTOCOLS = ["mip", "xbus"] * 4
SLOT_MOUNTS = ["+x+y+z", "-y+x+z", "+x-y-z", "+z+x+y"] * 2  # the fixture's slots 1..8
WRONG = 2  # unit 3 (index 2): its slot says +x-y-z, it sits -y+x+z (the fixture's 4 kept)
PHYSICAL = [("-y+x+z" if i == WRONG else m) for i, m in enumerate(SLOT_MOUNTS)]
SERIALS = [f"6251.{i + 1:05d}" if p == "mip" else f"03A0{i + 1:04d}"
           for i, p in enumerate(PROTOCOLS)]
UNPLUGGED = 4  # unit 5


def write_config(d, silent_port, fixed):
    lines = ['[station]', 'models = ["accel13", "mag13"]', '', '[fixture]', 'name = "cube8"',
             'batch = "LOT-38"']
    for i, m in enumerate(SLOT_MOUNTS + ["+x+y+z"]):
        lines += ['[[fixture.slot]]', f'name = "{i + 1}"', f'mount = "{m}"']
    for i in range(UNITS):
        lines += ['[[device]]', f'name = "imu{i + 1}"', f'protocol = "{PROTOCOLS[i]}"',
                  f'port = "{d}/p{i + 1}"', 'rate_hz = 100']
        lines += [f'mount = "{PHYSICAL[i]}"'] if fixed and i == WRONG else [f'slot = "{i + 1}"']
    lines += ['[[device]]', 'name = "imu9"', 'protocol = "mip"', f'port = "{silent_port}"',
              'slot = "9"']
    with open(f"{d}/turncald.toml", "w") as f:
        f.write("\n".join(lines) + "\n")


def events(d, kind):
    out = []
    for line in open(f"{d}/watch.jsonl"):
        if f'"class":"{kind}"' in line:
            out.append(json.loads(line))
    return out


def client(d, *args):
    r = subprocess.run([TURNCAL, *args, "--socket", f"{d}/t.sock", "--json"],
                       capture_output=True, text=True, timeout=30)
    return json.loads(r.stdout) if r.returncode == 0 else None


def corrected_z(d, truth):
    """|mean - truth| / sigma of every axis of both triads at each unit's last 4 captured poses
    with calibrated output: [(z, label)]."""
    records, lines = {}, {}
    for line in open(f"{d}/watch.jsonl"):
        j = json.loads(line)
        if j.get("class") == "POSE_CAPTURED":
            records[(j["device"], j["index"])] = j["record"]
        elif j.get("class") == "CORRECTED":
            lines.setdefault(j["device"], []).append(j)
    zs, per_unit = [], {}
    for i in range(UNITS):
        name, t = f"imu{i + 1}", truth["devices"][i]
        done = 0
        for index in sorted((k for (dev, k) in records if dev == name), reverse=True):
            inside = [s for s in in_window(lines.get(name, []), records[(name, index)])
                      if "acc_sigma" in s and "mag_sigma" in s]
            if len(inside) < 20 or done == 4:
                continue
            for z, axis in live_session.window_z(inside, t["poses"][index]["true_output"], t):
                zs.append((z, f"{name} pose {index} {axis}"))
            done += 1
        per_unit[name] = done
    return zs, per_unit


def main(d):
    live_session.cube_poses(TURNCAL, f"{d}/poses.csv", N_POSES)
    # The 9th unit: a pty nobody writes to (a unit that is plugged in and never streams).
    master, slave = os.openpty()
    silent_port = os.ttyname(slave)
    write_config(d, silent_port, fixed=False)
    sim_args = [TURNCAL, "sim", "--rate", "100", "--controller", f"{d}/t.sock", "--live-speed",
                str(SPEED), "--poses", f"{d}/poses.csv", "--seed", "38", "--truth-out",
                f"{d}/truth.json", "--answer-timeout", "20", "--retries", "8", "--unplug",
                f"6:mid:{UNPLUGGED}"]
    for i in range(UNITS):
        sim_args += ["--protocol", PROTOCOLS[i], "--live", f"{d}/p{i + 1}", "--serial",
                     SERIALS[i], f"--mount={PHYSICAL[i]}"]
    sim = subprocess.Popen(sim_args, stdout=open(f"{d}/sim.out", "w"),
                           stderr=open(f"{d}/sim.err", "w"))
    check(wait_for(f"{d}/p{UNITS}", 30), "the simulator made the 8 units' ptys")
    daemon = subprocess.Popen(
        [TURNCALD, "--config", f"{d}/turncald.toml", "--socket", f"{d}/t.sock", "--state-dir",
         f"{d}/state"], stdout=open(f"{d}/daemon.log", "w"), stderr=subprocess.STDOUT)
    check(wait_for(f"{d}/t.sock", 30), "turncald listens")
    watch = subprocess.Popen([TURNCAL, "watch", "--json", "--corrected", "--uncertainty",
                              "--socket", f"{d}/t.sock"], stdout=open(f"{d}/watch.jsonl", "w"))
    # Unit 3 is named from its first poses; the operator sets its mount and reloads.
    deadline = time.time() + 300
    while time.time() < deadline and not any(e["device"] == f"imu{WRONG + 1}"
                                              for e in events(d, "MOUNT")):
        time.sleep(0.1)
    named = [e for e in events(d, "MOUNT") if e["device"] == f"imu{WRONG + 1}"]
    check(bool(named), f"imu{WRONG + 1} is named: {named[-1]['message'] if named else 'no MOUNT'}")
    others = [e["device"] for e in events(d, "MOUNT") if e["device"] != f"imu{WRONG + 1}"]
    check(not others, f"no other unit is named: {others}")
    held = [e for e in events(d, "CALIBRATION_ACTIVE") if e["device"] == f"imu{WRONG + 1}"]
    check(not held, f"imu{WRONG + 1}: nothing activated while it sits wrong ({len(held)})")
    write_config(d, silent_port, fixed=True)
    daemon.send_signal(signal.SIGHUP)
    deadline = time.time() + 60
    while time.time() < deadline and not events(d, "RELOADED"):
        time.sleep(0.1)
    check(bool(events(d, "RELOADED")), "SIGHUP: the configuration with imu3's mount is reloaded")

    rc = sim.wait(timeout=900)
    # The simulator counts the poses imu9 never answered (it never streams); every pose must
    # have been captured by each of the 8 units.
    captured = {}
    for line in open(f"{d}/sim.out"):
        j = json.loads(line)
        if j.get("event") == "answer" and j.get("class") == "POSE_CAPTURED":
            captured.setdefault(j["device"], set()).add(j["index"])
    # A unit may miss a pose its sequencer rejects: the batch goes on and the gates pass without
    # it. (Seen before the simulator's rest at home lasted 3 s of wall time: imu3's pose 11, "gyr
    # y scatter 0.00168 rad/s above the still limit 0.00166", the start-up noise measured from
    # the same 100 samples replayed ten times; docs/BATCH.md. A daemon stalled at its start for
    # over 2 s could again see such replays.)
    short = {f"imu{i + 1}": N_POSES - len(captured.get(f"imu{i + 1}", ()))
             for i in range(UNITS) if len(captured.get(f"imu{i + 1}", ())) != N_POSES}
    check(rc in (0, 1) and sum(short.values()) <= 2,
          f"the table took its {N_POSES} poses, each captured by the 8 units but {short} "
          f"(the simulator's exit {rc}: " + open(f"{d}/sim.err").read().strip()[-300:] + ")")
    result = client(d, "result")
    status = client(d, "status")
    truth = json.load(open(f"{d}/truth.json"))
    for i in range(UNITS):
        name = f"imu{i + 1}"
        dev = result["devices"][name]
        for model, m in dev["models"].items():
            worst = live_session.worst_sigma(m, truth["devices"][i], model)
            check(m["gate"]["pass"] and m["active_version"] >= 1 and worst[0] <= 4.0,
                  f"{name} ({PROTOCOLS[i]}, {PHYSICAL[i]}) {model}: gate "
                  f"{'pass' if m['gate']['pass'] else m['gate']['reasons'][:1]}, v"
                  f"{m['active_version']}, largest |estimate - truth| {worst[0]:.2f} sigma "
                  f"({worst[1]})")
    watch.terminate()
    watch.wait()
    zs, per_unit = corrected_z(d, truth)
    check(all(n == 4 for n in per_unit.values()),
          f"corrected output compared at 4 poses of every unit: {per_unit}")
    # 8 units x 4 poses x 6 axes = 192 values: by chance 0.52 of them beyond 3 sigma, and 1.2 %
    # of sessions have one beyond 4.
    over3 = sorted((z for z in zs if z[0] > 3.0), reverse=True)
    worst = max(zs) if zs else (float("nan"), "")
    rms = math.sqrt(sum(z * z for z, _ in zs) / len(zs)) if zs else float("nan")
    check(len(zs) == 192 and worst[0] <= 4.0 and len(over3) <= 3,
          f"corrected output: {len(zs)} axes, RMS z {rms:.2f}, {len(over3)} beyond 3 sigma "
          f"{[f'{z:.2f} {w}' for z, w in over3]}, largest {worst[0]:.2f} ({worst[1]})")

    batch = status["batch"]
    units = {u["device"]: u for u in batch["units"]}
    want = {f"imu{i + 1}": (None if i == WRONG else str(i + 1)) for i in range(UNITS)}
    check(batch["id"] == "LOT-38" and batch["fixture"] == "cube8" and batch["passed"] == UNITS,
          f"status: batch {batch['id']} on {batch['fixture']}: {batch['passed']} passed, "
          f"{batch['waiting']} waiting, {batch['held']} held")
    for i in range(UNITS):
        u = units[f"imu{i + 1}"]
        check(u["state"] == "passed" and u["serial"] == SERIALS[i] and u["seconds"] > 0 and
              u["slot"] == want[f"imu{i + 1}"],
              f"status: slot {u['slot']} imu{i + 1} {u['serial']} {u['state']} after "
              f"{u['seconds']} s, {u['poses']} poses")
    silent = units["imu9"]
    check(silent["state"] == "waiting" and silent["poses"] == 0 and "does not stream" in silent["why"],
          f"status: imu9 (never streams) {silent['state']}: {silent['why']} (link "
          f"{silent.get('link')})")
    check(batch["seconds_to_last_gate"] is None, "no time to the last gate while imu9 waits")
    unplugs = [l for l in open(f"{d}/sim.out") if '"event":"unplugged"' in l]
    check(len(unplugs) == 1 and status["devices"][f"imu{UNPLUGGED + 1}"]["counters"]["opens"] >= 2,
          f"imu{UNPLUGGED + 1} was unplugged mid-pose and reopened "
          f"({status['devices'][f'imu{UNPLUGGED + 1}']['counters']['opens']} opens)")
    docs = [json.load(open(f"{d}/state/calibrations/{f}"))
            for f in os.listdir(f"{d}/state/calibrations") if f.endswith(".json")]
    slots = {c["device"]: c["batch"]["slot"] for c in docs if c["batch"]["id"] == "LOT-38"}
    check(len(docs) == 2 * UNITS and slots == want,
          f"each of the {len(docs)} calibrations names the batch and its slot (imu3's mount is "
          f"its own now): {slots}")
    text = subprocess.run([TURNCAL, "status", "--socket", f"{d}/t.sock"], capture_output=True,
                          text=True, timeout=30).stdout
    check("batch LOT-38 on fixture cube8" in text and text.count(" passed ") >= UNITS,
          "turncal status prints the batch slot by slot:\n" +
          text[text.find("batch LOT-38"):text.find("\n\n", text.find("batch LOT-38"))])
    loop, solve = status["loop_ms"], status["solve_ms"]
    print(f"note: with 9 devices (8 streaming 100 Hz at {SPEED}x) the loop's longest pose took "
          f"{loop['max']:.1f} ms of CPU; the worker's longest update {solve['max']:.0f} ms",
          flush=True)
    check(loop["max"] < 20, f"pose updates stay off the event loop: {loop['max']:.1f} ms at most")
    daemon.send_signal(signal.SIGTERM)
    check(daemon.wait(timeout=60) == 0, "SIGTERM: turncald exits 0")
    html = open(f"{d}/state/reports/imu1.html").read() \
        if os.path.exists(f"{d}/state/reports/imu1.html") else ""
    check('<section class="batch"><h2>Batch LOT-38</h2>' in html and html.count("<tr") >= 9,
          f"reports/imu1.html opens with the batch's summary ({len(html)} bytes)")
    os.close(master)
    os.close(slave)


live_session.run_in_temp_dir(main, "turncal-e2e-batch-")
