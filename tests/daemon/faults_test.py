#!/usr/bin/env python3
"""Faults end to end (issue "Reliability and security"; docs/RELIABILITY.md): the real turncald on
ptys that `turncal sim --live --controller` creates (a simulated MIP and a simulated Xbus IMU on
one turntable, the simulator playing the lab's controller over the 26 cube poses).

  ber-1e-5, ber-1e-4, ber-1e-3
        every bit the devices send (samples and dialogue replies) is flipped with this
        probability. Every pose is answered (captured, or rejected with a reason); every active
        calibration is within 4 sigma of the truth; the counters account for every byte: the
        daemon read exactly the bytes the ptys took, and bytes_read = bytes_dialogue +
        bytes_ignored + bytes_decoded, bytes_decoded = bytes_in_frames + skipped_bytes +
        pending_bytes.
  unplug
        the MIP's pty goes away halfway through pose 5's dwell and when the table leaves pose 11,
        the Xbus's halfway through pose 17 and when the table leaves pose 21 (each for 2 session
        seconds; a new pty appears at the same path, the device powered up afresh). turncald
        reconnects and configures the device again; the interrupted pose is rejected with a
        reason and announced again, or captured; no captured pose is lost: both devices end with
        all 26 poses and calibrations within 4 sigma.
  kill20
        kill -9 of turncald at 20 random moments (seeded), each followed by a restart. Before
        each restart: every calibration file parses (never torn), and every pose whose capture
        the controller was told was saved is in the journal; after it, the daemon resumes with
        every journal record. The session ends with every pose and calibrations within 4 sigma.
  statedir
        the state directory is a 4 MiB tmpfs (needs mount: root, or a user namespace). Mid
        session it is filled up, then freed, then remounted read-only, then writable again. While
        writes fail: POSE_CAPTURED / CALIBRATION_ACTIVE say "saved": false, status.persistence
        counts the failures and quotes the error, the daemon keeps answering and streaming
        corrected samples. Afterwards every pose answered "saved": true is in the journal, the
        active calibration files parse, and a restarted daemon resumes with the saved poses.

Usage: faults_test.py TURNCAL TURNCALD [SCENARIO|all]
Prints `faults: N failure(s)` last; exit 1 on failure, 0 with a SKIP line when a scenario cannot
run here (statedir without mount permission).
"""
import glob
import json
import os
import random
import shutil
import signal
import socket
import subprocess
import sys
import tempfile
import time

from live_session import check, failures, wait_for
import live_session

TURNCAL, TURNCALD = sys.argv[1], sys.argv[2]
WHICH = sys.argv[3] if len(sys.argv) > 3 else "all"
SPEED = 10
N_POSES = 26
DEVICES = ["imu1", "imu2"]






def start_daemon(d, log_name, state=None):
    args = [TURNCALD, "--device", f"imu1=mip:{d}/mip", "--device", f"imu2=xbus:{d}/xbus",
            "--socket", f"{d}/t.sock", "--state-dir", state or f"{d}/state"]
    return subprocess.Popen(args, stdout=open(f"{d}/{log_name}", "w"), stderr=subprocess.STDOUT)






def sim_events(d, kind=None):
    out = []
    for line in open(f"{d}/sim.out"):
        try:
            j = json.loads(line)
        except ValueError:
            continue
        if kind is None or j.get("event") == kind:
            out.append(j)
    return out


def request(d, obj, timeout=10):
    """One request on a fresh connection; the first reply that is not a stream message."""
    s = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
    s.settimeout(timeout)
    s.connect(f"{d}/t.sock")
    f = s.makefile("rb")
    f.readline()  # banner
    s.sendall((json.dumps(obj) + "\n").encode())
    try:
        while True:
            line = f.readline()
            if not line:
                return None
            j = json.loads(line)
            if j.get("class") in ("STATUS", "RESULT", "ERROR", "OK", "DEVICES"):
                return j
    finally:
        s.close()


def result(d):
    r = subprocess.run([TURNCAL, "result", "--socket", f"{d}/t.sock", "--json"],
                       capture_output=True, text=True, timeout=30)
    return json.loads(r.stdout) if r.returncode == 0 and r.stdout.strip() else None


def check_truth(res, truth, label, want_poses=N_POSES):
    """Every active model within 4 sigma of the truth (the truth file's biases: over the last pose)."""
    if res is None:
        check(False, f"{label}: no result")
        return
    for i, name in enumerate(DEVICES):
        t = truth["devices"][i]
        dev = res["devices"][name]
        check(dev["poses"] >= want_poses, f"{label}: {name} has {dev['poses']} poses "
              f"(want {want_poses})")
        for model, m in dev["models"].items():
            if m["active_version"] < 1:
                check(False, f"{label}: {name} {model} has no active calibration "
                      f"(gate: {m['gate'].get('reasons')})")
                continue
            worst = live_session.worst_sigma(m, t, model)
            check(worst[0] <= 4.0, f"{label}: {name} {model} v{m['active_version']}: largest "
                  f"|estimate - truth| = {worst[0]:.2f} sigma ({worst[1]})")


def answered_all(d, label):
    """Every pose answered by every device in the end: captured, or rejected with a reason."""
    final = {}
    for a in sim_events(d, "answer"):
        final[(a["index"], a["device"])] = a
    missing = [(i, n) for i in range(N_POSES) for n in DEVICES if (i, n) not in final]
    check(not missing, f"{label}: every pose answered by both devices (missing: {missing[:5]})")
    bad = [a for a in final.values() if a["class"] == "POSE_REJECTED" and not a["reason"]]
    check(not bad, f"{label}: every rejection has a reason")
    rejected = [a for a in sim_events(d, "answer") if a["class"] == "POSE_REJECTED"]
    return rejected


POSES = []  # index -> (phi, gamma, psi) rounded: the journal's records carry angles, not indices


def load_poses(path):
    POSES.clear()
    for line in open(path).read().splitlines()[1:]:
        POSES.append(tuple(round(float(x), 3) for x in line.split(",")))


def record_key(r):
    p = r["pose"]
    return tuple(round(p[k], 3) for k in ("phi_deg", "gamma_deg", "psi_deg"))


def journal(state):
    """{device: [record]} from journal.jsonl (torn lines skipped), and the torn line count."""
    out, torn = {}, 0
    path = f"{state}/journal.jsonl"
    if not os.path.exists(path):
        return out, 0
    for line in open(path, "rb"):
        try:
            j = json.loads(line)
            out.setdefault(j["device"], []).append(j["record"])
        except (ValueError, KeyError):
            torn += 1
    return out, torn


def stop(daemon):
    daemon.send_signal(signal.SIGTERM)
    try:
        daemon.wait(timeout=20)
    except subprocess.TimeoutExpired:
        daemon.kill()


def scenario_ber(d, rate, seed):
    label = f"ber {rate:g}"
    daemon = start_daemon(d, "daemon.log")
    sim = live_session.start_sim(TURNCAL, d, seed, SPEED, "--bit-error-rate", f"{rate:g}")
    rc = sim.wait(timeout=400)
    summary = sim_events(d, "summary")
    check(bool(summary), f"{label}: the simulator finished (exit {rc}): "
          + open(f"{d}/sim.err").read().strip()[-300:])
    if not summary:
        stop(daemon)
        return
    summary = summary[-1]
    rejected = answered_all(d, label)
    reasons = sorted({r["reason"].split(";")[0][:60] for r in rejected})
    print(f"     {label}: {summary['captured']}/{N_POSES} poses captured by both, "
          f"{len(rejected)} rejections ({reasons[:4]})")
    # Counters: what the ptys took, the daemon read; every byte is in a frame, skipped, in a
    # dialogue, ignored or pending.
    time.sleep(0.5)
    status = request(d, {"cmd": "status"})
    for i, name in enumerate(DEVICES):
        sent = summary["devices"][i]
        c = status["devices"][name]["counters"]
        for _ in range(40):
            if c["bytes_read"] >= sent["bytes_written"]:
                break
            time.sleep(0.25)
            c = request(d, {"cmd": "status"})["devices"][name]["counters"]
        check(c["bytes_read"] == sent["bytes_written"],
              f"{label}: {name} read {c['bytes_read']} bytes, the pty took "
              f"{sent['bytes_written']} ({sent['bits_flipped']} bits flipped)")
        check(c["bytes_read"] == c["bytes_dialogue"] + c["bytes_ignored"] + c["bytes_decoded"],
              f"{label}: {name} bytes_read {c['bytes_read']} = dialogue {c['bytes_dialogue']} + "
              f"ignored {c['bytes_ignored']} + decoded {c['bytes_decoded']}")
        check(c["bytes_decoded"] == c["bytes_in_frames"] + c["skipped_bytes"] + c["pending_bytes"],
              f"{label}: {name} decoded {c['bytes_decoded']} = in frames {c['bytes_in_frames']} "
              f"+ skipped {c['skipped_bytes']} + pending {c['pending_bytes']}; "
              f"{c['bad_checksums']} bad checksums, {c['frames']} frames, "
              f"{c['lost_samples']} samples lost, {c['configure_failures']} dialogue retries")
    check_truth(result(d), json.load(open(f"{d}/truth.json")), label, want_poses=1)
    stop(daemon)


def scenario_unplug(d):
    daemon = start_daemon(d, "daemon.log")
    sim = live_session.start_sim(TURNCAL, d, 21, SPEED, "--unplug", "5:mid:0",
                                 "--unplug", "11:between:0", "--unplug", "17:mid:1",
                                 "--unplug", "21:between:1", "--unplug-s", "2")
    rc = sim.wait(timeout=400)
    check(rc == 0, "unplug: every pose captured by both devices: "
          + open(f"{d}/sim.err").read().strip()[-300:])
    unplugs = sim_events(d, "unplugged")
    replugs = sim_events(d, "replugged")
    check(len(unplugs) == 4 and len(replugs) == 4,
          f"unplug: {len(unplugs)} unplugs, {len(replugs)} replugs (want 4, 4)")
    status = request(d, {"cmd": "status"})
    for name in DEVICES:
        # Two unplugs each, and the end of the session (the simulator's ptys are gone now).
        c = status["devices"][name]["counters"]
        check(c["disconnects"] >= 2 and c["opens"] >= 3,
              f"unplug: {name} saw {c['disconnects']} disconnects and was opened {c['opens']} "
              "times (reconnected after each unplug)")
    interrupted = [a for a in sim_events(d, "answer")
                   if a["class"] == "POSE_REJECTED" and a["index"] in (5, 17)]
    print(f"     unplug: interrupted poses answered: "
          f"{[(a['index'], a['device'], a['reason'][:70]) for a in interrupted]}")
    rejected = answered_all(d, "unplug")
    check(all(r["reason"] for r in rejected), "unplug: every rejection has a reason")
    check_truth(result(d), json.load(open(f"{d}/truth.json")), "unplug")
    stop(daemon)


def scenario_kill20(d):
    rng = random.Random(20)
    state = f"{d}/state"
    daemon = start_daemon(d, "daemon0.log")
    sim = live_session.start_sim(TURNCAL, d, 22, SPEED)
    wait_for(f"{d}/t.sock")
    kills = 0
    worst_gap = 0.0
    while kills < 20 and sim.poll() is None:
        time.sleep(rng.uniform(0.2, 1.0))
        if sim.poll() is not None:
            break
        daemon.send_signal(signal.SIGKILL)
        daemon.wait()
        kills += 1
        # Acknowledged before the kill: POSE_CAPTURED with "saved": true.
        saved = {(a["device"], a["index"]) for a in sim_events(d, "answer")
                 if a["class"] == "POSE_CAPTURED" and a.get("saved")}
        records, torn = journal(state)
        in_journal = {(dev, POSES.index(record_key(r))) for dev, rs in records.items() for r in rs
                      if record_key(r) in POSES}
        lost = sorted(saved - in_journal)
        check(not lost, f"kill {kills}: {len(saved)} acknowledged captures all in the journal "
              f"({sum(len(v) for v in records.values())} records, {torn} torn lines; "
              f"lost: {lost[:4]})")
        for path in glob.glob(f"{state}/calibrations/*.json"):
            try:
                c = json.load(open(path))
                ok = isinstance(c.get("version"), int) and "params" in c
            except ValueError:
                ok = False
            if not ok:
                check(False, f"kill {kills}: {os.path.basename(path)} is torn")
        t0 = time.time()
        daemon = start_daemon(d, f"daemon{kills}.log")
        wait_for(f"{d}/t.sock", 10)
        # Resumed with every journal record.
        log = f"{d}/daemon{kills}.log"
        resumed = {}
        for _ in range(100):
            for line in open(log):
                if "SESSION_RESUMED" in line:
                    j = json.loads(line[line.index("{"):])
                    resumed[j["device"]] = j["poses"]
            if len(resumed) == len(DEVICES):
                break
            time.sleep(0.05)
        worst_gap = max(worst_gap, time.time() - t0)
        want = {dev: len(records.get(dev, [])) for dev in DEVICES}
        check(resumed == want, f"kill {kills}: resumed {resumed}, journal holds {want}")
    check(kills == 20, f"kill20: {kills} kills before the session ended")
    rc = sim.wait(timeout=400)
    check(rc == 0, "kill20: the session finished with every pose captured: "
          + open(f"{d}/sim.err").read().strip()[-300:])
    res = result(d)
    check_truth(res, json.load(open(f"{d}/truth.json")), "kill20")
    print(f"     kill20: longest restart to SESSION_RESUMED {worst_gap:.2f} s")
    stop(daemon)


def can_mount(path):
    os.makedirs(path, exist_ok=True)
    r = subprocess.run(["mount", "-t", "tmpfs", "-o", "size=4m,mode=0755", "tmpfs", path],
                       capture_output=True, text=True)
    return r.returncode == 0, r.stderr.strip()


def scenario_statedir(d):
    state = f"{d}/state"
    ok, why = can_mount(state)
    if not ok:
        print(f"SKIP statedir: cannot mount a tmpfs here ({why})")
        return
    try:
        run_statedir(d, state)
    finally:
        subprocess.run(["umount", "-l", state], capture_output=True)


def persistence(d):
    s = request(d, {"cmd": "status"})
    return s["persistence"], s


def run_statedir(d, state):
    daemon = start_daemon(d, "daemon.log", state)
    watch = subprocess.Popen([TURNCAL, "watch", "--socket", f"{d}/t.sock", "--json",
                              "--corrected"], stdout=open(f"{d}/watch.jsonl", "w"),
                             stderr=subprocess.DEVNULL)
    sim = live_session.start_sim(TURNCAL, d, 23, SPEED)

    def captured_count():
        return len([a for a in sim_events(d, "answer") if a["class"] == "POSE_CAPTURED"])

    def wait_captures(n, seconds=120):
        end = time.time() + seconds
        while time.time() < end and captured_count() < n and sim.poll() is None:
            time.sleep(0.05)

    def corrected_lines():
        return sum(1 for line in open(f"{d}/watch.jsonl") if '"CORRECTED"' in line)

    def faulty_phase(label, make, undo):
        n0 = captured_count()
        make()
        wait_captures(n0 + 6)
        p, s = persistence(d)
        check(p["failed_writes"] > 0 and p["last_error"],
              f"statedir {label}: status.persistence counts {p['failed_writes']} failed writes: "
              f"{p['last_error'][:90]}")
        answers = sim_events(d, "answer")[n0:]
        unsaved = [a for a in answers if a["class"] == "POSE_CAPTURED" and not a.get("saved")]
        claimed = [a for a in answers if a["class"] == "POSE_CAPTURED" and a.get("saved")]
        # (A full tmpfs may still take a journal line in the file's last page: "saved": true can
        # be true; every such claim is checked against the journal at the end.)
        check(len(unsaved) >= 1, f"statedir {label}: {len(unsaved)} captures answered "
              f"\"saved\": false, {len(claimed)} \"saved\": true while writes fail")
        # Still serving: samples decoded (status) and corrected samples streamed once a
        # calibration is active.
        c0, n0 = corrected_lines(), {k: v["counters"]["samples"] for k, v in s["devices"].items()}
        time.sleep(1.0)
        _, s1 = persistence(d)
        grown = {k: v["counters"]["samples"] - n0[k] for k, v in s1["devices"].items()}
        check(all(g > 100 for g in grown.values()) and all(
            v["state"] == "streaming" for v in s1["devices"].values()),
            f"statedir {label}: still answering and streaming ({grown} samples in 1 s, "
            f"{corrected_lines() - c0} corrected lines to a subscriber)")
        undo()
        n1 = captured_count()
        wait_captures(n1 + 4)
        p, _ = persistence(d)
        check(p["last_error"] == "" and p["journal_open"],
              f"statedir {label} undone: writes succeed again ({p['writes']} writes, "
              f"{p['failed_writes']} failed)")

    filler = f"{state}/filler"

    def fill():
        with open(filler, "wb") as f:
            try:
                while True:
                    f.write(b"\0" * 65536)
                    f.flush()
            except OSError:
                pass

    wait_for(f"{d}/t.sock")
    wait_captures(3)
    faulty_phase("full", fill, lambda: os.remove(filler))
    # Read-only: a file system with a file open for writing cannot be remounted read-only, so
    # turncald is stopped, the directory remounted read-only, and turncald started on it (it
    # resumes from the journal, which it can read, and the controller reconnects).
    stop(daemon)
    subprocess.run(["mount", "-o", "remount,ro", state], check=True)
    daemon = start_daemon(d, "daemon_ro.log", state)
    wait_for(f"{d}/t.sock")
    watch.terminate()
    watch = subprocess.Popen([TURNCAL, "watch", "--socket", f"{d}/t.sock", "--json",
                              "--corrected"], stdout=open(f"{d}/watch.jsonl", "a"),
                             stderr=subprocess.DEVNULL)
    faulty_phase("read-only", lambda: None,
                 lambda: subprocess.run(["mount", "-o", "remount,rw", state], check=True))
    rc = sim.wait(timeout=400)
    check(rc == 0, "statedir: the session finished: " + open(f"{d}/sim.err").read().strip()[-200:])
    watch.terminate()
    # Nothing claimed saved that is not: each capture answered saved is in the journal.
    saved = {(a["device"], a["index"]) for a in sim_events(d, "answer")
             if a["class"] == "POSE_CAPTURED" and a.get("saved")}
    records, torn = journal(state)
    in_journal = {(dev, POSES.index(record_key(r))) for dev, rs in records.items() for r in rs
                  if record_key(r) in POSES}
    check(saved <= in_journal, f"statedir: all {len(saved)} captures answered saved are in the "
          f"journal ({sum(len(v) for v in records.values())} records, {torn} torn lines)")
    events = [json.loads(line) for line in open(f"{d}/watch.jsonl") if '"CALIBRATION_ACTIVE"' in line]
    for name in DEVICES:
        for path in glob.glob(f"{state}/calibrations/{name}*.json"):
            c = json.load(open(path))
            model = c.get("model")
            saved_versions = [e["version"] for e in events if e["device"] == name
                              and e["model"] == model and e.get("saved")]
            check(saved_versions and c["version"] == max(saved_versions),
                  f"statedir: {os.path.basename(path)} holds v{c['version']}, the last version "
                  f"announced saved (v{max(saved_versions) if saved_versions else None})")
    stop(daemon)
    daemon = start_daemon(d, "daemon2.log", state)
    wait_for(f"{d}/t.sock")
    time.sleep(1.0)
    log = open(f"{d}/daemon2.log").read()
    resumed = {json.loads(l[l.index("{"):])["device"]: json.loads(l[l.index("{"):])["poses"]
               for l in log.splitlines() if "SESSION_RESUMED" in l}
    want = {dev: len(records.get(dev, [])) for dev in DEVICES}
    check(resumed == want, f"statedir: restarted, resumed {resumed} (journal {want})")
    stop(daemon)


SCENARIOS = {
    "ber-1e-5": lambda d: scenario_ber(d, 1e-5, 31),
    "ber-1e-4": lambda d: scenario_ber(d, 1e-4, 32),
    "ber-1e-3": lambda d: scenario_ber(d, 1e-3, 33),
    "unplug": scenario_unplug,
    "kill20": scenario_kill20,
    "statedir": scenario_statedir,
}

for name, fn in SCENARIOS.items():
    if WHICH not in ("all", name):
        continue
    d = tempfile.mkdtemp(prefix=f"turncal-faults-{name}-")
    t0 = time.time()
    try:
        live_session.cube_poses(TURNCAL, f"{d}/poses.csv", N_POSES)
        load_poses(f"{d}/poses.csv")
        fn(d)
    finally:
        for p in subprocess.run(["pgrep", "-f", d], capture_output=True, text=True).stdout.split():
            try:
                os.kill(int(p), signal.SIGKILL)
            except ProcessLookupError:
                pass
        subprocess.run(["umount", "-l", f"{d}/state"], capture_output=True)
        print(f"     {name}: {time.time() - t0:.0f} s")
        if failures or os.environ.get("TURNCAL_KEEP"):
            print(f"(kept {d} for inspection)")
        else:
            shutil.rmtree(d, ignore_errors=True)

print(f"faults: {len(failures)} failure(s)")
sys.exit(1 if failures else 0)
