#!/usr/bin/env python3
"""`turncal registry drift` against a real PostgreSQL server (issue 39 item 3).

A simulated unit calibrated 12 times over a year (months 0-7 once, months 9 and 11 twice on the
same day, switched off and on between) with a known bias trend, turn-on scatter and calibration
sigma goes into a registry the test starts, with a failed calibration (left out) and a session
that published two versions (only its last counts). Then `turncal registry drift SERIAL --json`:
12 calibrations; the trend per month and the recalibration date within 3 sigma of the truth; the
repeatability's 95 % interval holds the truth; --tolerance doubles the interval; the text output
names the date; an unknown serial is exit 1 and a malformed --tolerance exit 2. The certificate
of the unit's latest calibration (`turncal registry certificate`) shows the drift table with the
recalibration date, its data block the summary, and it verifies.

Usage: registry_drift_test.py TURNCAL   (exit 77: PostgreSQL is not installed)
"""
import datetime
import json
import os
import random
import subprocess
import sys
import tempfile

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import pg_server  # noqa: E402

TURNCAL = sys.argv[1]
MONTH_S = 30.4375 * 86400
failures = 0


def check(ok, what):
    global failures
    print(("ok   " if ok else "FAIL ") + what)
    failures += not ok


def drift(db, *args):
    return subprocess.run([TURNCAL, "registry", "drift", *args, "--db", db], capture_output=True,
                          text=True, timeout=60)


def main(d):
    if not pg_server.available():
        print("SKIP: PostgreSQL (initdb, pg_ctl, psql) is not installed")
        return 77
    pg = pg_server.PgServer(os.path.join(d, "pg"))
    pg.init()
    try:
        db = pg.conninfo()
        r = subprocess.run([TURNCAL, "registry", "migrate", "--db", db], capture_output=True,
                           text=True)
        check(r.returncode == 0, f"migrate: {r.stdout.strip()} {r.stderr.strip()}")
        truth = {"bias": 0.05, "per_month": 3e-5, "sigma": 2e-5, "turn_on": 3e-5,
                 "tolerance": 1e-4}
        rng = random.Random(39)
        t0 = datetime.datetime(2026, 1, 1, tzinfo=datetime.timezone.utc).timestamp()
        times = [t0 + m * MONTH_S + 10 * 3600 for m in range(8)]
        for m in (9, 11):
            times += [t0 + m * MONTH_S + 9 * 3600, t0 + m * MONTH_S + 15 * 3600]
        pg.psql("INSERT INTO stations (name) VALUES ('line-d')")
        pg.psql("INSERT INTO devices (serial, serial_reported) VALUES ('6251.00039', true)")
        pg.psql("INSERT INTO batches (station_id, name) VALUES (1, 'session-a'), (1, 'session-b')")

        def insert(key, t, bias, passed=True, version=1, batch=None):
            params = {"bx": {"value": bias, "sigma": truth["sigma"]},
                      "sx": {"value": 1.0, "sigma": 1e-5}}
            stamp = datetime.datetime.fromtimestamp(t, datetime.timezone.utc).isoformat()
            pg.psql(
                "INSERT INTO calibrations (idempotency_key, station_id, device_id, device_name, "
                "model, version, passed, parameters, tolerances, calibrated_at, document, "
                f"batch_id) VALUES ('{key}', 1, 1, 'imu1', 'accel13', {version}, {passed}, "
                f"'{json.dumps(params)}', '{json.dumps({'bx': truth['tolerance']})}', "
                f"'{stamp}', '{{}}', {batch if batch else 'NULL'})")

        for i, t in enumerate(times):
            bias = (truth["bias"] + truth["per_month"] * (t - t0) / MONTH_S +
                    rng.gauss(0, truth["turn_on"]) + rng.gauss(0, truth["sigma"]))
            # The first session published a wild version 1 before its last (version 2).
            if i == 0:
                insert("k0v1", t - 600, 0.09, version=1, batch=1)
                insert(f"k{i}", t, bias, version=2, batch=1)
            else:
                insert(f"k{i}", t, bias)
        insert("failed", times[3] + 3600, 0.2, passed=False)

        r = drift(db, "6251.00039", "--json")
        check(r.returncode == 0, f"drift --json: exit {r.returncode} {r.stderr.strip()}")
        if r.returncode == 0:
            rows = {x["parameter"]: x for x in json.loads(r.stdout)}
            bx = rows["bx"]
            check(bx["calibrations"] == 12,
                  f"12 calibrations counted (one a session, the failed one left out): "
                  f"{bx['calibrations']}")
            trend = bx["trend"]
            z = (trend["per_month"] - truth["per_month"]) / trend["sigma_per_month"]
            check(abs(z) < 3 and trend["resolved"],
                  f"trend {trend['per_month']:.3g} +- {trend['sigma_per_month']:.2g} / month "
                  f"against {truth['per_month']:g} (z {z:.2f})")
            last = times[-1]
            date_true = last + truth["tolerance"] / (truth["per_month"] / MONTH_S)
            recal = bx["recalibrate"]
            z = (recal["t_s"] - date_true) / (recal["sigma_days"] * 86400)
            check(abs(z) < 3,
                  f"recalibrate on {recal['date']} +- {recal['sigma_days']:.0f} d against "
                  f"{datetime.datetime.fromtimestamp(date_true, datetime.timezone.utc).date()} "
                  f"(z {z:.2f}); not before {recal['not_before']}")
            rep = bx["repeatability"]
            rep_true = (truth["turn_on"] ** 2 + truth["sigma"] ** 2) ** 0.5
            check(rep["same_day_groups"] == 2 and rep["ci95"][0] <= rep_true <= rep["ci95"][1],
                  f"repeatability {rep['value']:.3g} ({rep['ci95'][0]:.2g}-{rep['ci95'][1]:.2g}) "
                  f"holds {rep_true:.3g}")
            check(rows["sx"]["recalibrate"]["date"] is None,
                  "sx: no tolerance recorded, no date")
            r2 = drift(db, "6251.00039", "--json", "--tolerance", "bx=2e-4")
            bx2 = {x["parameter"]: x for x in json.loads(r2.stdout)}["bx"]
            gap1, gap2 = recal["t_s"] - last, bx2["recalibrate"]["t_s"] - last
            check(abs(gap2 / gap1 - 2) < 1e-6, f"--tolerance bx=2e-4 doubles the interval: "
                  f"{gap1 / 86400:.0f} d -> {gap2 / 86400:.0f} d")
        # The certificate of the unit's latest calibration shows the drift (issue 39 item 3): the
        # latest session's document is a real accel13 calibration (tests/report's).
        doc = open(os.path.join(os.path.dirname(os.path.abspath(__file__)),
                                "../report/certificate_accel13.json")).read()
        pg.psql(f"UPDATE calibrations SET document = $doc${doc}$doc$ "
                f"WHERE idempotency_key = 'k{len(times) - 1}'")
        cert = os.path.join(d, "cert.html")
        r = subprocess.run([TURNCAL, "registry", "certificate", "6251.00039", "--model", "accel13",
                            "-o", cert, "--db", db], capture_output=True, text=True)
        check(r.returncode == 0, f"registry certificate: exit {r.returncode} {r.stderr.strip()}")
        if r.returncode == 0:
            html = open(cert).read()
            check("Drift over the unit's calibrations" in html and 'id="drift-accel13-bx"' in html
                  and recal["date"] in html and recal["not_before"] in html,
                  f"the certificate shows bx's drift: recalibrate {recal['date']}, not before "
                  f"{recal['not_before']}")
            data = json.loads(html.split('id="turncal-certificate-data">')[1].split("</script>")[0])
            bxd = [x for x in data.get("drift", []) if x["parameter"] == "bx"]
            check(len(bxd) == 1 and "history" not in bxd[0] and bxd[0]["calibrations"] == 12,
                  "its data block holds the drift's summary (12 calibrations, no history)")
            r = subprocess.run([TURNCAL, "certificate", "--verify", cert], capture_output=True,
                               text=True)
            check(r.returncode == 0, f"the certificate with its drift verifies: {r.stdout.strip()}")
        r = drift(db, "6251.00039")
        check(r.returncode == 0 and "bx" in r.stdout and "Recalibrate" in r.stdout,
              f"text: exit {r.returncode}\n{r.stdout}")
        r = drift(db, "0000.00000")
        check(r.returncode == 1 and "no passing calibration" in r.stderr,
              f"an unknown serial: exit {r.returncode}: {r.stderr.strip()}")
        r = drift(db, "6251.00039", "--tolerance", "bx")
        check(r.returncode == 2 and "NAME=VALUE" in r.stderr,
              f"a malformed --tolerance: exit {r.returncode}: {r.stderr.strip()}")
    finally:
        pg.stop()
    print(f"registry drift: {failures} failure(s)")
    return 1 if failures else 0


if __name__ == "__main__":
    with tempfile.TemporaryDirectory() as d:
        sys.exit(main(d))
