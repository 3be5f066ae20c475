#!/usr/bin/env python3
"""turncal free and free-montecarlo (issue 22). A simulated tumble as bytes (`turncal sim` with
random table orientations; the pose events are ignored in free mode) calibrates with every free
model, each gated and with its misfit reduced; the HTML report holds the coverage sphere; bad
input exits 2. On imu_tk's real Xsens recording (skipped without ../shared/fixtures) the intervals,
accel9's | |f| - g | and gyro9g's gravity-direction residual are the figures docs/ACCURACY.md
quotes, and gyro9's chi^2 says the g-sensitivity is missing. The MIP SDK's real magnetometer-only
packets run through free mode to a sphere, refused with the reason. A short Monte Carlo keeps its
z spread near 1. turncald's free pose source on the same bytes (`turncald --replay FILE --once
--pose-source free`, also on the raw MIP stream): every model activated, its documents re-fitted by
`turncal report`, the raw stream's held repeats dropped and the sphere refused with the reason."""
import json
import math
import os
import random
import re
import subprocess
import sys
import tempfile

TURNCAL = sys.argv[1]
TURNCALD = sys.argv[2]
SANITIZED = os.environ.get("TURNCAL_SANITIZED") == "1"
failures = 0


def check(ok, what):
    global failures
    print(("ok   " if ok else "FAIL ") + what)
    failures += not ok


def run(args):
    return subprocess.run([TURNCAL] + args, capture_output=True, text=True)


def turncald(args):
    return subprocess.run([TURNCALD] + args, capture_output=True, text=True)


def model(result, name):
    return next((m for m in result["models"] if m["model"] == name), None)


with tempfile.TemporaryDirectory() as d:
    # 20 orientations of a three-axis table, angles drawn at random.
    rng = random.Random(5)
    poses = os.path.join(d, "tumble.csv")
    with open(poses, "w") as f:
        f.write("phi,gamma,psi\n")
        for _ in range(20):
            f.write(f"{rng.uniform(-180, 180):.2f},{rng.uniform(-90, 90):.2f},"
                    f"{rng.uniform(-180, 180):.2f}\n")
    capture = os.path.join(d, "tumble.tcap")
    r = run(["sim", "--protocol", "xbus", "--poses", poses, "--model", "accel13", "--model",
             "mag13", "--model", "gyro12", "--no-rate-segments", "--dwell", "3", "--seed", "3",
             "-o", capture])
    check(r.returncode == 0, f"turncal sim writes a tumble: exit {r.returncode} {r.stderr[-300:]}")
    field = math.sqrt(0.2523**2 + 0.0217**2 + 0.4004**2)  # the simulator's |B_NED|, Gauss
    html = os.path.join(d, "free.html")
    r = run(["free", capture, "--field", f"{field:.6f}", "--gravity", "9.778214", "--json",
             "--html", html])
    check(r.returncode == 0, f"turncal free on the simulated tumble: exit {r.returncode} "
          f"{r.stderr[-300:]}")
    if r.stdout.strip():
        res = json.loads(r.stdout)
        check(19 <= len(res["intervals"]) <= 21,
              f"the intervals found: {len(res['intervals'])} of 20 orientations")
        for name in ["accel9", "gyro9", "magellipsoid", "accmag"]:
            m = model(res, name)
            check(m is not None and m["ok"] and m["gate"]["passed"],
                  f"{name}: fitted and gated ({m and m.get('gate')})")
            if m and m["ok"]:
                check(m["rank"] == len(m["parameters"]), f"{name}: full rank {m['rank']}")
                before = {f["kind"]: f["rms"] for f in m["misfit_before"]}
                for f in m["misfit_after"]:
                    check(f["rms"] < 0.1 * before[f["kind"]],
                          f"{name}: {f['kind']} misfit RMS {f['rms']:.3g} from {before[f['kind']]:.3g}")
                check("advice" in m, f"{name}: advice '{m.get('advice', {}).get('text')}'")
        text = open(html).read() if os.path.exists(html) else ""
        check("<svg" in text and "Coverage sphere" in text, "the HTML report has the coverage sphere")
    # The same bytes through turncald's free pose source, persisted, then reported.
    state = os.path.join(d, "state")
    out = os.path.join(d, "result.json")
    # Every interval's refit takes the magnetometer's samples in motion between the orientations
    # too (issue 37: 600 a fit, the drift whitened); instrumented, 100 keep the run in time.
    extra = []
    if SANITIZED:
        config = os.path.join(d, "turncald.toml")
        with open(config, "w") as f:
            f.write("[free]\nmax_motion_points = 100\n")
        extra = ["--config", config]
    r = turncald(["--replay", capture, "--once", "--pose-source", "free", "--state-dir", state,
                  "--result-out", out] + extra)
    check(r.returncode == 0, f"turncald --pose-source free: exit {r.returncode} {r.stderr[-300:]}")
    if os.path.exists(out):
        res = json.load(open(out))
        dev = res["devices"]["imu"]
        check(res["pose_source"] == "free" and res["pose_commands_ignored"] == 20,
              f"turncald: free, {res.get('pose_commands_ignored')} pose events ignored")
        check(dev["poses"] == 20, f"turncald: {dev['poses']} intervals of 20 orientations")
        for name in ["accel9", "gyro9", "magellipsoid", "accmag"]:
            m = dev["models"].get(name, {})
            check(m.get("gate", {}).get("pass") and m.get("active_version", 0) >= 1 and
                  os.path.exists(os.path.join(state, "calibrations", f"imu.{name}.json")),
                  f"turncald {name}: gate {m.get('gate')}, active v{m.get('active_version')}")
        report = os.path.join(d, "report.html")
        r = run(["report", "--state-dir", state, "-o", report])
        text = open(report).read() if os.path.exists(report) else ""
        check(r.returncode == 0 and text.count("the stored values agree") == 4,
              f"turncal report re-fits the 4 free documents: exit {r.returncode} {r.stderr[-200:]}")
    r = run(["free", os.path.join(d, "none.tcap")])
    check(r.returncode == 2 and "cannot" in r.stderr, f"a missing file: exit {r.returncode}")
    r = run(["free", poses, "--columns", "t,ax,ay"])
    check(r.returncode == 2, f"a triad with two columns: exit {r.returncode} {r.stderr.strip()}")
    r = run(["free", capture, "--models", "accel13"])
    check(r.returncode == 2 and "unknown free model" in r.stderr,
          f"a model that is not a free model: exit {r.returncode} {r.stderr.strip()}")

    # Instrumented (TURNCAL_SANITIZED=1), 3 tumbles run the same code; the spread is checked
    # in the optimised suite.
    runs = 3 if SANITIZED else 30
    r = run(["free-montecarlo", "--model", "accel9", "--runs", str(runs), "--json"])
    check(r.returncode in (0, 1), f"free-montecarlo runs: exit {r.returncode} {r.stderr[-200:]}")
    if r.stdout.strip():
        mc = json.loads(r.stdout)
        check(mc["ok"] == runs, f"{runs} of {runs} tumbles estimated ({mc['ok']})")
        # 30 runs estimate a std to ~13 %: 1 within 4 of those.
        for p in mc["params"] if not SANITIZED else []:
            check(0.5 < p["std_z"] < 1.5, f"accel9 {p['name']}: std z {p['std_z']:.2f}")
        # An honest sigma fails a row of 600 on one of 9 parameters with P <= 9 x 0.00077
        # (union bound, whatever their correlation): at least 98 % of 1000 simulated rows pass.
        chance, of600 = mc["honest_row_pass_chance"], mc["honest_row_pass_chance_600"]
        check(0 <= chance <= 1 and of600 >= 0.98,
              f"an honest sigma passes {chance:.2f} of rows of {runs}, {of600:.3f} of 600")

shared = os.environ.get("TURNCAL_SHARED_DIR", os.path.join(os.path.dirname(__file__), "../../../shared"))
acc = os.path.join(shared, "fixtures/imu_tk/xsens_acc.mat")
gyr = os.path.join(shared, "fixtures/imu_tk/xsens_gyro.mat")
if not os.path.exists(acc):
    print(f"skipped: {acc} is absent (the real Xsens recording)")
elif SANITIZED:
    # 53 s instrumented for numbers the optimised suite checks; the text log's reader runs
    # instrumented in text_log_test on the same files.
    print("skipped instrumented: imu_tk's recording (checked in the optimised suite)")
else:
    common = [acc, gyr, "--acc-offset", "32768", "--acc-scale", "0.0026391", "--gyr-offset",
              "32768", "--gyr-scale", "0.0001598", "--gravity", "9.81744"]
    r = run(["free"] + common + ["--models", "accel9,gyro9,gyro9g", "--json"])
    check(r.returncode == 0, f"imu_tk: exit {r.returncode} {r.stderr[-300:]}")
    if r.stdout.strip():
        res = json.loads(r.stdout)
        check(38 <= len(res["intervals"]) <= 41, f"imu_tk: {len(res['intervals'])} intervals")
        a = model(res, "accel9")
        after = {f["kind"]: f for f in a["misfit_after"]}["norm"]
        check(after["rms"] < 0.002 and after["max"] < 0.004,
              f"imu_tk accel9: | |f| - g | RMS {after['rms']:.4g} max {after['max']:.4g} m/s^2")
        g9 = model(res, "gyro9")
        g9g = model(res, "gyro9g")
        check(g9["chi2"] / g9["dof"] > 10, f"imu_tk gyro9: chi2/dof {g9['chi2'] / g9['dof']:.1f}")
        check(g9g["chi2"] / g9g["dof"] < 3, f"imu_tk gyro9g: chi2/dof {g9g['chi2'] / g9g['dof']:.2f}")
        direction = {f["kind"]: f for f in g9g["misfit_after"]}["direction"]
        check(direction["rms"] < 0.004 and direction["max"] < 0.008,
              f"imu_tk gyro9g: direction RMS {math.degrees(direction['rms']):.3f} deg, max "
              f"{math.degrees(direction['max']):.3f} deg")
    r = run(["free"] + common + ["--models", "accel9,gyro9"])
    check("gyro9g" in r.stdout and "hint" in r.stdout, "imu_tk text: gyro9's hint names gyro9g")

mip = os.path.join(shared, "fixtures/microstrain/mip_sdk/mip_data.bin")
if not os.path.exists(mip):
    print(f"skipped: {mip} is absent (the real MIP device capture)")
else:
    # The 0x80 packets whose only field is the magnetometer (0x06): a compass stream.
    data = open(mip, "rb").read()
    out = bytearray()
    i = 0
    while i + 4 <= len(data):
        if data[i] == 0x75 and data[i + 1] == 0x65:
            n = data[i + 3]
            packet = data[i:i + 4 + n + 2]
            fields, j = [], 4
            while j < 4 + n:
                fields.append(packet[j + 1])
                j += packet[j]
            if data[i + 2] == 0x80 and fields == [0x06]:
                out += packet
            i += 4 + n + 2
        else:
            i += 1
    with tempfile.TemporaryDirectory() as d:
        compass = os.path.join(d, "compass.bin")
        open(compass, "wb").write(out)
        r = run(["free", compass, "--protocol", "mip"])
        check(r.returncode == 2 and "--rate" in r.stderr,
              f"MIP magnetometer without time stamps asks for --rate: {r.stderr.strip()}")
        # Still-only (issue 22's path): two short rests cannot carry even a sphere.
        r = run(["free", compass, "--protocol", "mip", "--rate", "50", "--sensor-class",
                 "consumer", "--still-only", "--json"])
        check(r.returncode == 1, f"MIP magnetometer, still only: exit {r.returncode} (refused)")
        if r.stdout.strip():
            res = json.loads(r.stdout)
            m = res["models"][0] if res["models"] else {}
            check(m.get("model") in ("magsphere", "magellipsoid") and not m.get("ok", True),
                  f"MIP magnetometer, still only: no calibration: {m.get('note')}")
            # Its rests are one orientation (their means 1.7 mG apart, 16 times their noise):
            # refused as a magnetometer that did not turn (or for rank).
            check(not m.get("gate", {}).get("passed", True) and
                  any("rank" in why or "did not turn" in why for why in m["gate"]["reasons"]),
                  f"MIP magnetometer, still only: refused, one orientation: {m.get('gate')}")
        # The capture is not static (the device turned: 73 of the 576 bins): its samples in
        # motion carry a sphere, not an ellipsoid, and the sphere does not fit the consumer
        # class's noise (chi^2/dof ~10: the covariance inflated by it, and said).
        r = run(["free", compass, "--protocol", "mip", "--rate", "50", "--sensor-class",
                 "consumer", "--json"])
        check(r.returncode == 0, f"MIP magnetometer in motion: exit {r.returncode}")
        if r.stdout.strip():
            res = json.loads(r.stdout)
            m = res["models"][0] if res["models"] else {}
            motion = res.get("motion", {})
            check(500 <= motion.get("points", 0) <= 736 and
                  abs(motion.get("sigma", [0])[0] - 0.0005) < 1e-4,
                  f"MIP magnetometer in motion: the points and their noise: {motion.get('summary')}")
            check(m.get("model") == "magsphere" and "cannot carry an ellipsoid" in m.get("note", "")
                  and re.search(r"coverage 12\.[0-9] %", m.get("note", "")),
                  f"MIP magnetometer in motion: a sphere, with the coverage: {m.get('note')}")
            # 72 or 73 bins: the corrected directions move with the fit.
            check(70 <= m.get("coverage", {}).get("filled", 0) <= 75,
                  f"MIP magnetometer in motion: coverage {m.get('coverage')}")
            # Its values' residuals correlate from one to the next (0.57 at 40 ms: the smooth
            # misfit, or the device's filter): whitened together.
            corr = m.get("correlation", {})
            check(corr.get("whitened") and 0.4 < corr.get("lag_one", 0) < 0.75,
                  f"MIP magnetometer in motion: the correlation {corr}")
            check(m.get("chi2", 0) / max(m.get("dof", 1), 1) > 5,
                  f"MIP magnetometer in motion: the sphere's chi2/dof "
                  f"{m.get('chi2', 0) / max(m.get('dof', 1), 1):.2f} (inflated)")
        # The same bytes through turncald's free pose source.
        r = turncald(["--replay", compass, "--protocol", "mip", "--once", "--pose-source", "free"])
        check(r.returncode == 2 and "--rate" in r.stderr,
              f"turncald: a raw stream without time asks for --rate: {r.stderr.strip()[-200:]}")
        out = os.path.join(d, "compass.json")
        # Instrumented, its refits in motion were 54 % of this test (649 s of the sanitizer
        # suite, 2026-11-29): 100 points a fit there, as for the tumble above.
        extra, points = [], (400, 736)
        if SANITIZED:
            config = os.path.join(d, "turncald.toml")
            with open(config, "w") as f:
                f.write("[free]\nmax_motion_points = 100\n")
            extra, points = ["--config", config], (50, 100)
        r = turncald(["--replay", compass, "--protocol", "mip", "--rate", "50", "--once",
                      "--pose-source", "free", "--result-out", out] + extra)
        check(r.returncode == 0, f"turncald raw MIP magnetometer: exit {r.returncode}")
        if os.path.exists(out):
            res = json.load(open(out))
            m = res["devices"]["compass"]["models"].get("magellipsoid", {})
            check(res["raw"]["held_repeats_dropped"] > 0,
                  f"turncald: held repeats dropped: {res['raw']}")
            # The station takes the samples in motion too ([free] motion): the same sphere as
            # `turncal free`, refused (the class's noise does not explain its misfit).
            motion = res["devices"]["compass"]["free"]["motion"]
            check(points[0] <= motion.get("points", 0) <= points[1],
                  f"turncald raw MIP magnetometer: the points in motion: {motion.get('summary')}")
            # (Capped at 100 points, the coverage is of those: 6.8 %.)
            coverage = r"coverage [0-9.]+ %" if SANITIZED else r"coverage 12\.[0-9] %"
            check(m.get("model") == "magsphere" and "cannot carry an ellipsoid" in m.get("note", "")
                  and re.search(coverage, m.get("note", "")) and not m["gate"]["pass"],
                  f"turncald raw MIP magnetometer: a sphere, refused with the reason: "
                  f"{m.get('note', '')[:160]} {m.get('gate')}")

print(f"free: {failures} failure(s)")
sys.exit(1 if failures else 0)
