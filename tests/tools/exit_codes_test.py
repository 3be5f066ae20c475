#!/usr/bin/env python3
"""Every turncal command returns the exit code its --help documents (tools/help_text.h).

For each subcommand `turncal --help` lists, the test reads the EXIT STATUS section of
`turncal COMMAND --help` ("CODE what it means; CODE ..."), runs a refusal -- a wrong argument, a
missing file, a daemon that cannot be reached (a --socket that does not exist), a registry that
cannot be reached -- and checks that the command exits with the code whose text names that
refusal. A command without a case here fails the test, so a new command brings its own.
Usage: exit_codes_test.py TURNCAL
"""
import os
import re
import subprocess
import sys
import tempfile

turncal = os.path.abspath(sys.argv[1])
failures = 0


def fail(message):
    global failures
    failures += 1
    print("FAIL:", message)


def run(args, cwd):
    return subprocess.run([turncal] + args, cwd=cwd, capture_output=True, text=True, timeout=120)


def exit_status(command):
    """{code: text} from the EXIT STATUS section of `turncal COMMAND --help`."""
    text = subprocess.run([turncal, command, "--help"], capture_output=True, text=True).stdout
    m = re.search(r"\nEXIT STATUS\n(.*?)\n\n?SEE ALSO\n", text, re.S)
    if not m:
        return {}
    flat = " ".join(line.strip() for line in m.group(1).splitlines())
    # "0 done; 1 ...; 2 ..." and "0; 2 ...": a code opens the text or follows "; ".
    parts = re.split(r"(?:^|;\s+)(\d)(?=[\s,;]|$)", flat)
    return {int(parts[i]): parts[i + 1].strip(" ,;") for i in range(1, len(parts) - 1, 2)}


NO_SOCKET = ["--socket", "/nonexistent/turncal.sock"]
UNREACHABLE = "cannot be reached"
MISTAKE = "command-line mistake"
# command -> [(arguments of a refusal, words of the documented code's text that name it)]
CASES = {
    "status": [(NO_SOCKET, UNREACHABLE)],
    "devices": [(NO_SOCKET, UNREACHABLE), (["--bogus"], MISTAKE)],
    "result": [(NO_SOCKET, UNREACHABLE)],
    "report": [(NO_SOCKET, UNREACHABLE),
               (["--state-dir", "/nonexistent", "-o", "r.html"], "no active calibration")],
    "next-pose": [(NO_SOCKET, UNREACHABLE)],
    "watch": [(NO_SOCKET + ["--count", "1"], UNREACHABLE)],
    "pose": [(["0", "0", "0"] + NO_SOCKET, UNREACHABLE), (["0", "0"], MISTAKE)],
    "rate": [(["outer", "100"] + NO_SOCKET, UNREACHABLE)],
    "reset": [(NO_SOCKET, UNREACHABLE)],
    "publish": [(["imu1", "accel13", "--operator", "A", "--reason", "r"] + NO_SOCKET,
                 UNREACHABLE)],
    "device-write": [(["imu1", "--model", "accel13"] + NO_SOCKET, UNREACHABLE)],
    "registry": [(["history", "6251.1", "--db", "host=/nonexistent port=1 connect_timeout=2"],
                  UNREACHABLE), (["nosuch"], MISTAKE)],
    "certificate": [(["--state-dir", "/nonexistent", "--device", "imu1", "-o", "c.html"],
                     "no such calibration"),
                    (["--verify", "/nonexistent/cert.html"], "unreadable file")],
    "capture": [(["--device", "nonsense", "-o", "bad.tcap"], MISTAKE)],
    "decode": [(["/nonexistent.bin", "--protocol", "mip"], "cannot be read"),
               (["/nonexistent.bin", "--protocol", "nmea"], MISTAKE)],
    "models": [(["--bogus"], MISTAKE)],
    "fit-sim": [(["--model", "accel99"], "unknown model"),
                (["--class", "military"], MISTAKE)],
    "montecarlo": [(["--model", "accel99", "--runs", "2"], MISTAKE),
                   (["--pipeline", "--model", "accel99", "--runs", "2"], MISTAKE),
                   (["--thermal", "-20,warm", "--runs", "2"], MISTAKE),
                   (["--thermal", "25", "--runs", "2"], MISTAKE),
                   (["--thermal", "20,30", "--model", "mag13", "--runs", "2"], MISTAKE),
                   (["--device-rate", "20", "--runs", "2"], MISTAKE),
                   (["--thermal", "0,40", "--pipeline", "--runs", "2"], MISTAKE),
                   (["--chamber", "0; ramp 40 4", "--runs", "2"], MISTAKE),
                   (["--pipeline", "--chamber", "0; ramp", "--runs", "2"], MISTAKE),
                   (["--pipeline", "--model", "mag22", "--chamber", "0; ramp 40 4",
                     "--runs", "2"], MISTAKE),
                   (["--pipeline", "--keep", "/tmp", "--keep-p-below", "2", "--runs", "2"],
                    MISTAKE),
                   (["--pipeline", "--keep-p-below", "0.01", "--runs", "2"], MISTAKE)],
    "free": [(["/nonexistent.tcap"], "cannot be read"),
             (["/nonexistent.tcap", "--max-motion-points", "3"], MISTAKE)],
    "free-montecarlo": [(["--protocol", "nmea", "--runs", "2"], MISTAKE),
                        (["--model", "accel13"], MISTAKE),
                        (["--model", "accel9", "--hand", "10", "--runs", "2"], MISTAKE),
                        (["--model", "magellipsoid", "--hand", "10", "--magnet", "2",
                          "--magnet-peak", "0", "--runs", "2"], MISTAKE)],
    "noise": [(["/nonexistent.tcap"], "cannot be read")],
    "characterise": [(["/nonexistent.json"], "cannot be read"), (["--noise-to", "-1"], MISTAKE)],
    "noise-montecarlo": [(["--runs", "1"], MISTAKE)],
    "sim": [(["--protocol", "nmea", "-o", "x.tcap"], MISTAKE),
            (["--protocol", "mip", "--chamber", "0; ramp hot", "-o", "x.tcap"], MISTAKE),
            (["--protocol", "mip", "--repeat-poses", "-o", "x.tcap"], MISTAKE),
            (["--protocol", "mip", "--hand", "10", "--faults", "-o", "x.tcap"], MISTAKE),
            (["--protocol", "mip", "--hand", "10", "--hand-pauses", "1", "--hand-pause", "0.2",
              "-o", "x.tcap"], MISTAKE),
            (["--protocol", "mip", "--hand", "10", "--magnet", "-1", "-o", "x.tcap"], MISTAKE),
            (["--protocol", "mip", "--hand", "10", "--magnet", "4", "--magnet-s", "0",
              "-o", "x.tcap"], MISTAKE)],
    "poses": [(["--design", "nosuch"], MISTAKE)],
    "observability": [(["--model", "accel13", "--poses", "/nonexistent.csv"],
                       "unreadable pose list"),
                      (["--model", "accel13"], MISTAKE)],
    "plan": [(["--phi", "10:0:5"], MISTAKE),
             (["--poses", "/nonexistent.csv"], "unreadable pose list"),
             # 672 grid poses and 2000 rates (280000 rate segments): more candidates than the planner
             # takes.
             (["--model", "gyro12", "--rates", ",".join(["100"] * 2000)], "planner refuses")],
    "plan-vs-cube": [(["--model", "accel99"], MISTAKE)],
    "plan-thermal": [(["--model", "gyro12"], MISTAKE), (["--range", "0", "5"], MISTAKE),
                     (["--end-cubes", "0,-1"], MISTAKE)],
    "sequence": [(["/nonexistent.tcap"], "cannot be read")],
}

commands = re.findall(r"^  ([a-z][a-z-]*)\b",
                      subprocess.run([turncal, "--help"], capture_output=True,
                                     text=True).stdout.split("Subcommands:")[-1], re.M)
if not commands:
    fail("no subcommands in turncal --help")
checked = 0
with tempfile.TemporaryDirectory() as scratch:
    for command in commands:
        codes = exit_status(command)
        if not codes:
            fail(f"turncal {command} --help: no EXIT STATUS codes")
            continue
        if command not in CASES:
            fail(f"turncal {command}: no refusal case in exit_codes_test.py")
            continue
        for args, words in CASES[command]:
            documented = [c for c, text in codes.items() if words in text]
            if len(documented) != 1:
                fail(f"turncal {command} --help: the EXIT STATUS names '{words}' under "
                     f"{documented or 'no code'}: {codes}")
                continue
            r = run([command] + args, scratch)
            checked += 1
            if r.returncode != documented[0]:
                fail(f"turncal {command} {' '.join(args)[:80]}: exit {r.returncode}, its help "
                     f"says {documented[0]} ({words}); stderr: {r.stderr.strip()[-200:]}")
print(f"exit codes: {len(commands)} commands, {checked} refusals checked, {failures} failure(s)")
sys.exit(1 if failures else 0)
