#!/usr/bin/env python3
"""End to end against a real PostgreSQL server (issue 24): two simulated stations calibrate four
IMUs into one registry, through their outboxes.

The test starts its own server (initdb and pg_ctl in a temporary directory, a Unix socket and TLS
on 127.0.0.1 with a self-signed certificate, scram-sha-256 passwords: the stations read theirs
from a mode-600 file). Then:

  1. station line-a (over TLS, verify-full; turncald, `turncal sim --live --controller`, a MIP IMU 6251.00001 and an
     Xbus IMU 03A00001, 9 poses): every calibration it activated is in the registry once, with
     its poses, and the registry's document is the station's file; mag13 written into the MIP
     IMU (`turncal device-write`) is in the registry's device_writes once;
  2. a password file that others may read is refused, and so is a server whose certificate
     another CA signed; `status` says why;
  3. station line-b (6251.00003, 03A00004): the server is stopped mid-session (after the first
     calibration arrived); the station keeps calibrating, `status` shows the outbox's depth and
     the last error; with the server still down turncald is killed (-9) with entries in its
     outbox (between the outbox and the insert), and the newest entry is removed (as a crash
     between a calibration's file and its entry leaves it);
  4. the server starts again; turncald starts (the reconciliation queues the calibration whose
     entry was removed) with a test hook that holds after the first commit, before that entry
     leaves the outbox, and is killed (-9) there: the entry is in the registry and still in the
     outbox;
  5. turncald starts normally: the outbox drains, the held entry is found already there (not
     written twice), and the registry holds every calibration of line-b's state directory once;
  6. IMU 6251.00001 moves to line-b (a second session there, `turncal reset` between):
     `turncal registry history 6251.00001` shows both stations' calibrations, `latest` shows the
     latest passing one (line-b's), export to CSV and JSON hold every calibration,
     `registry stations` lists both stations, `registry certificate` writes a certificate
     whose hash verifies and is registered, and `registry verify` refuses a forgery whose hash
     was recomputed after an edit.

Usage: e2e_registry_test.py TURNCAL TURNCALD   (exit 77: PostgreSQL is not installed)
"""
import csv
import glob
import io
import json
import os
import signal
import subprocess
import sys
import tempfile
import time

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "daemon"))
sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from live_session import check, cube_poses, failures, finish_dir, wait_for  # noqa: E402
import pg_server  # noqa: E402

TURNCAL, TURNCALD = sys.argv[1], sys.argv[2]
SPEED = 10
PASSWORD = "s3cret-station-pw"


def run(*args, timeout=120, env=None):
    return subprocess.run([TURNCAL, *args], capture_output=True, text=True, timeout=timeout,
                          env=env)


def wait_until(predicate, seconds=120, step=0.1):
    end = time.time() + seconds
    while time.time() < end:
        value = predicate()
        if value:
            return value
        time.sleep(step)
    return predicate()


class Station:
    def __init__(self, d, name, db):
        self.d, self.name, self.daemon, self.runs = d, name, None, 0
        os.makedirs(d, exist_ok=True)
        with open(f"{d}/password", "w") as f:
            f.write(PASSWORD + "\n")
        os.chmod(f"{d}/password", 0o600)
        with open(f"{d}/turncald.toml", "w") as f:
            f.write('[station]\nmodels = ["accel13", "mag13"]\n'
                    f'[registry]\nconninfo = "{db}"\npassword_file = "{d}/password"\n'
                    f'station = "{name}"\nretry_max_s = 1\n')

    def start(self, env_extra=None):
        env = dict(os.environ, **(env_extra or {}))
        env.pop("PGPASSWORD", None)  # the station's password comes from its file only
        self.runs += 1
        self.daemon = subprocess.Popen(
            [TURNCALD, "--config", f"{self.d}/turncald.toml", "--device", f"mip=mip:{self.d}/mip",
             "--device", f"xbus=xbus:{self.d}/xbus", "--socket", f"{self.d}/t.sock",
             "--state-dir", f"{self.d}/state"],
            stdout=open(f"{self.d}/daemon{self.runs}.log", "w"), stderr=subprocess.STDOUT, env=env)
        check(wait_until(lambda: self.status() is not None, 30),
              f"{self.name}: turncald (run {self.runs}) answers")

    def log(self):
        return open(f"{self.d}/daemon{self.runs}.log").read()

    def kill9(self):
        self.daemon.send_signal(signal.SIGKILL)
        self.daemon.wait()
        if os.path.exists(f"{self.d}/t.sock"):
            os.unlink(f"{self.d}/t.sock")

    def stop(self):
        self.daemon.send_signal(signal.SIGTERM)
        self.daemon.wait(timeout=60)

    def status(self):
        r = run("status", "--socket", f"{self.d}/t.sock", "--json", timeout=30)
        if r.returncode != 0:
            return None
        try:
            return json.loads(r.stdout)
        except ValueError:
            return None

    def registry(self):
        s = self.status()
        return s["registry"] if s else None

    def simulate(self, serials, seed, poses, *extra):
        return subprocess.Popen(
            [TURNCAL, "sim", "--protocol", "mip", "--protocol", "xbus", "--live", f"{self.d}/mip",
             "--live", f"{self.d}/xbus", "--controller", f"{self.d}/t.sock", "--live-speed",
             str(SPEED), "--poses", poses, "--seed", str(seed), "--serial", serials[0],
             "--serial", serials[1], "--answer-timeout", "60", "--retries", "5", *extra],
            stdout=open(f"{self.d}/sim{seed}.out", "w"), stderr=open(f"{self.d}/sim{seed}.err", "w"))

    def calibration_files(self):
        """Every calibration the state directory holds (active and earlier), by registry key."""
        docs = {}
        for path in glob.glob(f"{self.d}/state/calibrations/*.json") + \
                glob.glob(f"{self.d}/state/history/*.json"):
            c = json.load(open(path))
            if c.get("class") != "CALIBRATION":
                continue
            ident = (c.get("provenance") or {}).get("device_identity") or {}
            serial = ident.get("serial") or ident.get("device_id") or c["device"]
            docs[f"{self.name}/{serial}/{c['model']}/v{c['version']}/{c['time']}"] = c
        return docs

    def outbox(self):
        return sorted(glob.glob(f"{self.d}/state/outbox/*.json"))


def registry_keys(pg, station):
    rows = pg.psql("SELECT c.idempotency_key FROM calibrations c JOIN stations s "
                   f"ON s.id = c.station_id WHERE s.name = '{station}'")
    return [r[0] for r in rows]


def check_all_once(pg, st, what):
    files = st.calibration_files()
    keys = registry_keys(pg, st.name)
    missing = set(files) - set(keys)
    extra = set(keys) - set(files)
    check(len(files) > 0 and not missing and not extra and len(keys) == len(set(keys)),
          f"{what}: the registry holds each of the {len(files)} calibrations of {st.name}'s state "
          f"directory once ({len(keys)} rows, missing {sorted(missing)[:3]}, "
          f"extra {sorted(extra)[:3]})")
    return files


def line_a(d, pg):
    """1. line-a: a MIP and an Xbus IMU, the registry up throughout, reached over TLS (TCP,
    sslmode=verify-full against the server's certificate). Returns the station, stopped."""
    a = Station(f"{d}/a", "line-a", pg.tls_conninfo())
    a.start()
    tls = wait_until(lambda: pg.psql(
        "SELECT s.ssl, s.version FROM pg_stat_ssl s JOIN pg_stat_activity a USING (pid) "
        "WHERE a.application_name = 'turncald'"), 30)
    check(tls and tls[0][0] == "t", f"line-a reaches the registry over TLS: {tls}")
    sim = a.simulate(["6251.00001", "03A00001"], 11, f"{d}/poses.csv", "--hold-end", "3000")
    check(wait_until(lambda: '"holding_end"' in open(f"{a.d}/sim11.out").read(), 300, 0.2),
          "line-a: the 9 poses were answered; the table holds")
    # What is written into a device goes to the registry too.
    r = run("device-write", "mip", "--model", "mag13", "--yes", "--socket", f"{a.d}/t.sock")
    check(r.returncode == 0, f"line-a: mag13 written into 6251.00001 (exit {r.returncode})")
    sim.terminate()
    sim.wait()
    check(wait_until(lambda: (a.registry() or {}).get("depth", 1) == 0 and not a.outbox(), 60),
          f"line-a: the outbox drained: {a.registry()}")
    files_a = check_all_once(pg, a, "line-a")
    check(a.registry()["sent"] == len(files_a) + 1 and a.registry()["already_there"] == 0,
          f"line-a: status counts {a.registry()['sent']} sent (the calibrations and the write), "
          "0 already there")
    # The registry's document is the station's file; its poses are the calibration's.
    key, doc = sorted(files_a.items())[-1]
    row = pg.psql("SELECT document, (SELECT count(*) FROM calibration_poses p WHERE "
                  f"p.calibration_id = c.id), passed FROM calibrations c WHERE idempotency_key = '{key}'")
    check(row and json.loads(row[0][0]) == doc, f"line-a: {key}: the registry's document is the file")
    check(row and int(row[0][1]) == len(doc["provenance"]["poses"]) and row[0][2] == "t",
          f"line-a: {key}: {row[0][1] if row else '?'} poses, passed")
    writes = pg.psql("SELECT d.serial, w.operation, w.outcome, w.model FROM device_writes w "
                     "JOIN devices d ON d.id = w.device_id")
    check(writes == [["6251.00001", "write", "verified", "mag13"]] or
          (len(writes) == 1 and writes[0][0] == "6251.00001" and writes[0][1] == "write"),
          f"line-a: the write into the device is in the registry once: {writes}")
    a.stop()
    return a


def line_a_refusals(d, pg, a):
    """2. A password file others may read, and a server certificate another CA signed, are
    refused with their reason in `status`."""
    os.chmod(f"{a.d}/password", 0o644)
    a.start()
    r = wait_until(lambda: (a.registry() or {}).get("last_error"), 30)
    check(r and "may be read by group or others" in r, f"a readable password file is refused: {r}")
    a.stop()
    os.chmod(f"{a.d}/password", 0o600)
    # A server whose certificate another CA signed is refused (verify-full), not used.
    subprocess.run(["openssl", "req", "-x509", "-newkey", "rsa:2048", "-nodes", "-keyout",
                    f"{d}/other.key", "-out", f"{d}/other.crt", "-days", "2", "-subj",
                    "/CN=localhost"], check=True, capture_output=True)
    toml = open(f"{a.d}/turncald.toml").read()
    open(f"{a.d}/turncald.toml", "w").write(toml.replace(pg.ca, f"{d}/other.crt"))
    a.start()
    r = wait_until(lambda: (a.registry() or {}).get("last_error"), 30)
    check(r and "certificate verify failed" in r, f"a server certificate from another CA is refused: {r}")
    a.stop()
    open(f"{a.d}/turncald.toml", "w").write(toml)


def line_b_server_stops(d, pg, db):
    """3. line-b: the server stops mid-session; kill -9 with entries in the outbox, the newest
    entry removed (a crash between a calibration's file and its entry). Returns the station, the
    outbox's depth and the removed entry's key."""
    b = Station(f"{d}/b", "line-b", db)
    b.start()
    sim = b.simulate(["6251.00003", "03A00004"], 12, f"{d}/poses.csv")
    check(wait_until(lambda: (b.registry() or {}).get("sent", 0) >= 1, 120),
          "line-b: the first calibration reached the registry")
    pg.stop()
    check(sim.wait(timeout=300) == 0, "line-b: the session went on without the registry")
    reg = wait_until(lambda: (lambda r: r if r and r["depth"] > 0 and r["last_error"] else None)(
        b.registry()), 60)
    check(reg is not None and not reg["connected"],
          f"line-b: status shows the outbox waiting and why: depth {reg and reg['depth']}, "
          f"error {reg and reg['last_error']!r}")
    text = run("status", "--socket", f"{b.d}/t.sock").stdout
    check("outbox" in text and "last error" in text, "line-b: `turncal status` shows the outbox")
    waiting = len(b.outbox())
    check(waiting == reg["depth"], f"line-b: {waiting} entries in outbox/ as status says")
    b.kill9()  # between the outbox and the insert
    # A crash between a calibration's file and its outbox entry leaves exactly this: the newest
    # entry missing. The next start's reconciliation must find it.
    lost = b.outbox()[-1]
    lost_key = json.load(open(lost))["key"]
    os.unlink(lost)
    return b, waiting, lost_key


def line_b_restarts(pg, b, waiting, lost_key):
    """4. The server is back; turncald holds after its first commit and is killed there. 5. A
    normal start drains the outbox; the committed entry is not written twice."""
    pg.start()
    b.start({"TURNCAL_TEST_REGISTRY_HOLD_AFTER_COMMIT": "1"})
    check(wait_until(lambda: "holding before it leaves the outbox" in b.log(), 60),
          "line-b: the first entry was committed and turncald holds")
    check("1 calibration(s) of this state directory were not yet sent; queued" in b.log(),
          "line-b: the calibration without an outbox entry was queued again at the start")
    held = [k for k in registry_keys(pg, "line-b")]
    b.kill9()
    check(len(b.outbox()) == waiting, f"line-b: the committed entry is still in the outbox "
          f"({len(b.outbox())} of {waiting})")

    # 5. A normal start drains the outbox; the committed entry is not written twice.
    b.start()
    check(wait_until(lambda: (b.registry() or {}).get("depth", 1) == 0 and not b.outbox(), 60),
          f"line-b: the outbox drained after the restarts: {b.registry()}")
    reg = b.registry()
    check(reg["already_there"] == 1 and reg["sent"] == waiting - 1,
          f"line-b: {reg['sent']} sent, {reg['already_there']} already there (the held one)")
    files_b = check_all_once(pg, b, "line-b after a stopped server and two kill -9")
    check(lost_key in registry_keys(pg, "line-b"), f"line-b: {lost_key} (its entry lost) arrived")
    check(len(held) < len(files_b), "line-b: calibrations arrived after the restarts")


def moved_imu(d, pg, b, db):
    """6. 6251.00001 moves from line-a to line-b: history across stations, latest, export,
    stations."""
    check(run("reset", "--socket", f"{b.d}/t.sock").returncode == 0, "line-b: reset")
    sim = b.simulate(["6251.00001", "03A00004"], 13, f"{d}/poses.csv")
    check(sim.wait(timeout=300) == 0, "line-b: the moved IMU's 9 poses were answered")
    check(wait_until(lambda: (b.registry() or {}).get("depth", 1) == 0 and not b.outbox(), 60),
          "line-b: the outbox drained")
    check_all_once(pg, b, "line-b after the second session")
    r = run("registry", "history", "6251.00001", "--db", db, env=dict(os.environ))
    stations_seen = {line.split()[2] for line in r.stdout.splitlines()[2:] if line.strip()}
    check(r.returncode == 0 and stations_seen == {"line-a", "line-b"},
          f"registry history 6251.00001 shows both stations: {sorted(stations_seen)}")
    print(r.stdout[:600])
    r = run("registry", "latest", "6251.00001", "--model", "accel13", "--json", "--db", db)
    latest = json.loads(r.stdout) if r.returncode == 0 else []
    newest_b = max((c for c in b.calibration_files().values()
                    if c["model"] == "accel13" and c["device"] == "mip"),
                   key=lambda c: (c["time"], c["version"]))
    check(len(latest) == 1 and latest[0]["station"] == "line-b" and
          latest[0]["version"] == newest_b["version"] and latest[0]["document"] == newest_b,
          f"registry latest: line-b's accel13 v{newest_b['version']}")
    r = run("registry", "history", "NOSUCH", "--db", db)
    check(r.returncode == 1 and "no calibration" in r.stdout, "an unknown serial: exit 1, said")
    r = run("registry", "export", "--format", "csv", "-o", f"{d}/all.csv", "--db", db)
    rows = list(csv.DictReader(open(f"{d}/all.csv", newline=""))) if r.returncode == 0 else []
    n_total = int(pg.psql("SELECT count(*) FROM calibrations")[0][0])
    check(len({x["key"] for x in rows}) == n_total and
          all(x["serial"] in ("6251.00001", "03A00001", "6251.00003", "03A00004") for x in rows),
          f"export CSV: {len(rows)} parameter rows of all {n_total} calibrations, four serials")
    r = run("registry", "export", "--format", "json", "--serial", "03A00004", "--db", db)
    exported = json.loads(r.stdout) if r.returncode == 0 else []
    n_4 = int(pg.psql("SELECT count(*) FROM calibrations c JOIN devices d ON d.id = c.device_id "
                      "WHERE d.serial = '03A00004'")[0][0])
    check(len(exported) == n_4 and all(e["calibration"]["params"] for e in exported),
          f"export JSON of 03A00004: {len(exported)} whole documents")
    r = run("registry", "stations", "--json", "--db", db)
    stations = {s["station"]: s for s in json.loads(r.stdout)} if r.returncode == 0 else {}
    check(set(stations) == {"line-a", "line-b"} and stations["line-b"]["calibrations"] > 0,
          f"registry stations: {sorted(stations)} with their last contact")


def batches(pg, stations, db):
    """7. The batches (issue 38): every calibration names its session's batch; a restarted
    station keeps it, `reset` begins another. `registry yield` (per batch and per station) and
    `registry batch ID` agree with the stations' own files."""
    expected = {}  # (station, batch) -> {serial: {model: (version, passed)}}
    units_on_fixture = {}
    for st in stations:
        files = st.calibration_files().values()
        unnamed = [f"{c['device']} {c['model']} v{c['version']}" for c in files
                   if not (c.get("batch") or {}).get("id") or c["batch"].get("units") != 2]
        check(files and not unnamed,
              f"{st.name}: each of its {len(files)} calibrations names its batch of 2 units "
              f"(not: {unnamed[:3]})")
        for c in files:
            b = c.get("batch") or {}
            ident = (c.get("provenance") or {}).get("device_identity") or {}
            serial = ident.get("serial") or ident.get("device_id") or c["device"]
            models = expected.setdefault((st.name, b.get("id")), {}).setdefault(serial, {})
            passed = bool(c["gate"]["pass"]) and "override" not in c
            if c["model"] not in models or models[c["model"]][0] < c["version"]:
                models[c["model"]] = (c["version"], passed)
            units_on_fixture[(st.name, b.get("id"))] = b.get("units")
    per_station = {}
    for (station, batch), units in expected.items():
        per_station.setdefault(station, set()).add(batch)
    check(len(per_station.get("line-b", ())) == 2 and len(per_station.get("line-a", ())) == 1,
          f"line-a has one batch, line-b two (restarts keep it, reset begins one): {per_station}")
    r = run("registry", "yield", "--json", "--db", db)
    rows = json.loads(r.stdout) if r.returncode == 0 else []
    got = {(x["station"], x["batch"]): x for x in rows}
    check(r.returncode == 0 and set(got) == set(expected),
          f"registry yield: the batches {sorted(got)} are the stations' {sorted(expected)}")
    for key, units in expected.items():
        passed = sum(all(p for _, p in m.values()) for m in units.values())
        row = got.get(key, {})
        check(row.get("units") == units_on_fixture[key] and row.get("passed") == passed and
              abs(row.get("yield_percent", -1) - round(100.0 * passed / units_on_fixture[key], 1))
              < 1e-9,
              f"registry yield {key}: {row.get('passed')}/{row.get('units')} passed "
              f"({row.get('yield_percent')} %), the files say {passed}/{units_on_fixture[key]}")
    r = run("registry", "yield", "--by", "station", "--json", "--db", db)
    by_station = {x["station"]: x for x in json.loads(r.stdout)} if r.returncode == 0 else {}
    for station, ids in per_station.items():
        row = by_station.get(station, {})
        check(row.get("batches") == len(ids) and row.get("units") == 2 * len(ids),
              f"registry yield --by station {station}: {row}")
    key = sorted(k for k in expected if k[0] == "line-b")[-1]
    r = run("registry", "batch", key[1], "--json", "--db", db)
    listed = json.loads(r.stdout) if r.returncode == 0 else []
    check({x["serial"] for x in listed} == set(expected[key]) and
          all(x["station"] == "line-b" for x in listed),
          f"registry batch {key[1]}: its units {sorted(x['serial'] for x in listed)}")
    r = run("registry", "batch", "NOSUCH", "--db", db)
    check(r.returncode == 1, f"registry batch NOSUCH: exit {r.returncode}, said")


def registry_certificate(d, db):
    """A certificate of the moved IMU's latest passing accel13, straight from the registry; a
    forgery with a recomputed hash passes certificate --verify but not registry verify."""
    r = run("registry", "certificate", "6251.00001", "--model", "accel13", "-o", f"{d}/cert.html",
            "--db", db)
    v = run("certificate", "--verify", f"{d}/cert.html")
    html = open(f"{d}/cert.html").read() if r.returncode == 0 else ""
    check(r.returncode == 0 and v.returncode == 0 and "6251.00001" in html and "line-b" in html,
          f"registry certificate: line-b's accel13 of 6251.00001, hash verified ({v.stdout.strip()})")
    r = run("registry", "verify", f"{d}/cert.html", "--db", db)
    check(r.returncode == 0 and "verified" in r.stdout,
          f"registry verify: the certificate is registered ({r.stdout.strip()})")
    # A forgery: one digit changed and the hash recomputed by the public recipe. The file is
    # self-consistent (certificate --verify passes) but the registry did not issue it.
    import hashlib
    import re
    h = re.search(r'turncal-certificate-sha256" content="([0-9a-f]{64})', html).group(1)
    forged = html.replace("line-b", "line-x", 1).replace(h, "0" * 64)
    new_h = hashlib.sha256(forged.encode()).hexdigest()
    open(f"{d}/forged.html", "w").write(forged.replace("0" * 64, new_h))
    check(run("certificate", "--verify", f"{d}/forged.html").returncode == 0,
          "a forgery with a recomputed hash passes certificate --verify (the hash alone)")
    r = run("registry", "verify", f"{d}/forged.html", "--db", db)
    check(r.returncode == 1 and "did not issue it" in r.stdout,
          f"registry verify refuses the forgery: {r.stdout.strip()}")


def line_t(d, pg):
    """6. line-t: a consumer magnetometer calibrated over temperature (mag13@T) in a simulated
    chamber ramping 0 -> 40 degC; its calibrations reach the registry with their polynomials
    (migration 3, the temperature column) and the parameters at t0 as the parameters."""
    t = Station(f"{d}/t", "line-t", pg.conninfo())
    with open(f"{t.d}/turncald.toml", "w") as f:
        f.write('[station]\nmodels = ["mag13@T"]\nsensor_class = "consumer"\n'
                f'[registry]\nconninfo = "{pg.conninfo()}"\npassword_file = "{t.d}/password"\n'
                'station = "line-t"\nretry_max_s = 1\n')
    t.start()
    sim = t.simulate(["6251.00077", "03A00077"], 31, f"{d}/poses.csv", "--class", "consumer",
                     "--chamber", "0; ramp 40 6 120", "--die-tau", "30", "--repeat-poses",
                     "--hold-end", "3000")
    check(wait_until(lambda: '"holding_end"' in open(f"{t.d}/sim31.out").read(), 400, 0.2),
          "line-t: the chamber's poses were answered; the table holds")
    sim.terminate()
    sim.wait()
    check(wait_until(lambda: (t.registry() or {}).get("depth", 1) == 0 and not t.outbox(), 60),
          f"line-t: the outbox drained: {t.registry()}")
    files = check_all_once(pg, t, "line-t")
    rows = pg.psql("SELECT c.model, c.temperature->>'t_min_c', c.temperature->>'t_max_c', "
                   "c.parameters->'bx'->>'value', c.passed, c.document FROM calibrations c "
                   "JOIN stations s ON s.id = c.station_id WHERE s.name = 'line-t'")
    check(rows and all(r[0] == "mag13@T" and r[1] and r[2] and r[3] for r in rows),
          f"line-t: {len(rows)} calibrations over temperature with their range and parameters "
          f"at t0: {[r[:5] for r in rows][:2]}")
    check(rows and float(rows[-1][2]) - float(rows[-1][1]) >= 10.0,
          f"line-t: the calibrated range spans at least 10 degC: {rows[-1][1:3] if rows else ''}")
    check(rows and all(json.loads(r[5]) in files.values() for r in rows),
          "line-t: the registry's documents are the station's files")
    t.stop()


def main(d):
    if not pg_server.available():
        print("SKIP: PostgreSQL (initdb, pg_ctl, psql) is not installed: apt-get install postgresql")
        return 77
    pg = pg_server.PgServer(f"{d}/pg", tls=True)
    pg.init(password=PASSWORD)
    os.environ["PGPASSWORD"] = PASSWORD  # psql's, for the checks
    db = pg.conninfo()
    cube_poses(TURNCAL, f"{d}/poses.csv", 9)
    a = line_a(d, pg)
    line_a_refusals(d, pg, a)
    b, waiting, lost_key = line_b_server_stops(d, pg, db)
    line_b_restarts(pg, b, waiting, lost_key)
    moved_imu(d, pg, b, db)
    batches(pg, [a, b], db)
    registry_certificate(d, db)
    line_t(d, pg)
    dup = pg.psql("SELECT count(*) - count(DISTINCT document) FROM calibrations")[0][0]
    check(dup == "0", "no calibration document is in the registry twice")
    b.stop()
    pg.stop()
    return 0


if __name__ == "__main__":
    d = tempfile.mkdtemp(prefix="turncal_registry_")
    code = 1
    try:
        code = main(d)
    except Exception as e:  # a crash is a failure, with the directory kept
        check(False, f"the test crashed: {e!r}")
    if code != 77:
        try:
            pg_server.PgServer(f"{d}/pg").stop("immediate")
        except Exception:  # noqa: BLE001 - the server may not have started
            pass
    finish_dir(d)
    if code == 77:
        sys.exit(77)
    print(f"registry: {len(failures)} failure(s)")
    sys.exit(1 if failures else 0)
