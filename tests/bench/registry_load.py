#!/usr/bin/env python3
"""How many calibrations per second a station's registry outbox sustains (issue 24,
docs/PERFORMANCE.md "Registry"), against a real PostgreSQL server this script starts (initdb and
pg_ctl in a temporary directory, a Unix socket; fsync on, as a real server runs).

A real calibration document is made first (`turncal sim` then `turncald --replay --once
--state-dir`): accel13 and mag13 of a simulated MIP IMU, 26 poses with their records. N copies
with distinct versions go into a state directory's history/ as earlier calibrations that were
never sent. turncald then starts with [registry]: its outbox queues them (one fsynced file each)
and sends them, one transaction each (station, device, calibration, its poses). The script polls
`turncal status` and reports the queue rate and the send rate.

Usage: tests/bench/registry_load.py BUILD_DIR [N]     (N: default 2000)
Last line: {"class":"REGISTRY_LOAD_RESULT",...}
"""
import json
import os
import shutil
import signal
import subprocess
import sys
import tempfile
import time

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, os.path.join(HERE, "..", "registry"))
import pg_server  # noqa: E402

build = os.path.abspath(sys.argv[1])
n = int(sys.argv[2]) if len(sys.argv) > 2 else 2000
turncal, turncald = f"{build}/tools/turncal", f"{build}/daemon/turncald"
work = tempfile.mkdtemp(prefix="turncal_registry_load_")
pg = pg_server.PgServer(f"{work}/pg", fsync=True)
daemon = None
try:
    pg.init()
    subprocess.run([turncal, "sim", "--protocol", "mip", "-o", f"{work}/s.tcap", "--seed", "3"],
                   check=True, capture_output=True)
    subprocess.run([turncald, "--replay", f"{work}/s.tcap", "--once", "--state-dir",
                    f"{work}/seed"], check=True, capture_output=True)
    docs = []
    for name in sorted(os.listdir(f"{work}/seed/calibrations")):
        docs.append(json.load(open(f"{work}/seed/calibrations/{name}")))
    os.makedirs(f"{work}/state/history")
    size = 0
    for i in range(n):
        doc = dict(docs[i % len(docs)])
        doc["version"] = 1000 + i
        text = json.dumps(doc)
        size += len(text)
        with open(f"{work}/state/history/{doc['device']}.{doc['model']}.v{doc['version']}.json",
                  "w") as f:
            f.write(text)
    with open(f"{work}/turncald.toml", "w") as f:
        f.write(f'[registry]\nconninfo = "{pg.conninfo()}"\nstation = "bench"\n')
    t0 = time.time()
    daemon = subprocess.Popen(
        [turncald, "--config", f"{work}/turncald.toml", "--device", "imu=mip:/nonexistent/tty",
         "--socket", f"{work}/t.sock", "--state-dir", f"{work}/state"],
        stdout=open(f"{work}/daemon.log", "w"), stderr=subprocess.STDOUT)
    samples = []
    while True:
        r = subprocess.run([turncal, "status", "--socket", f"{work}/t.sock", "--json"],
                           capture_output=True, text=True)
        if r.returncode == 0:
            reg = json.loads(r.stdout)["registry"]
            samples.append((time.time() - t0, reg["sent"], reg["depth"]))
            if reg["sent"] + reg["already_there"] >= n:
                break
            if reg["rejected"]:
                raise SystemExit(f"rejected entries: {reg}")
        if time.time() - t0 > 1800:
            raise SystemExit("timeout")
        time.sleep(0.2)
    t_end = samples[-1][0]
    # The send rate over the middle of the run (first to last status that saw progress).
    first = next(s for s in samples if s[1] > 0)
    rate = (samples[-1][1] - first[1]) / max(1e-9, samples[-1][0] - first[0])
    rows = int(pg.psql("SELECT count(*) FROM calibrations")[0][0])
    poses = int(pg.psql("SELECT count(*) FROM calibration_poses")[0][0])
    db_bytes = int(pg.psql("SELECT pg_database_size('turncal')")[0][0])
    result = {"class": "REGISTRY_LOAD_RESULT", "calibrations": n, "rows": rows,
              "pose_rows": poses, "mean_document_bytes": size // n,
              "total_s": round(t_end, 2), "send_rate_per_s": round(rate, 1),
              "overall_rate_per_s": round(n / t_end, 1), "database_bytes": db_bytes,
              "machine": os.uname().machine, "cpus": os.cpu_count()}
    print(json.dumps(result))
finally:
    if daemon:
        daemon.send_signal(signal.SIGTERM)
        daemon.wait(timeout=60)
    pg.stop("immediate")
    shutil.rmtree(work, ignore_errors=True)
