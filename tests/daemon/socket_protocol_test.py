#!/usr/bin/env python3
"""The socket protocol against the real turncald (docs/protocol.md; issue "The daemon",
acceptance): malformed, oversized and unknown requests each get an ERROR on a connection that
stays usable while other clients go on being served; a subscriber that never reads does not slow
the pipeline or grow the daemon's memory without bound, and is told what it lost (DROPPED);
mutating commands from a uid that is not allowed are refused (SO_PEERCRED); SIGHUP reloads the
configuration; SIGTERM stops cleanly (exit 0, socket removed).

The device is a replayed simulated capture (replay:FILE?speed=40) through the live service.
Usage: socket_protocol_test.py TURNCAL TURNCALD
"""
import json
import os
import shutil
import signal
import socket
import subprocess
import sys
import tempfile
import time

TURNCAL, TURNCALD = sys.argv[1], sys.argv[2]
failures = []
# Under AddressSanitizer (TURNCAL_SANITIZED=1) the quarantine and red zones inflate RSS: the
# bound is checked in the normal build only.
SANITIZED = os.environ.get("TURNCAL_SANITIZED") == "1"


def check(ok, message):
    print(("ok   " if ok else "FAIL ") + message, flush=True)
    if not ok:
        failures.append(message)


class Client:
    def __init__(self, path, buffer=None):
        self.s = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
        if buffer:
            self.s.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, buffer)
        self.s.connect(path)
        self.f = self.s.makefile("rb")
        self.banner = json.loads(self.f.readline())

    def send_raw(self, data):
        self.s.sendall(data)

    def send(self, obj):
        self.send_raw((json.dumps(obj) + "\n").encode())

    def reply(self, timeout=10, want=None):
        """The next line that is not a stream message (or whose class is `want`)."""
        self.s.settimeout(timeout)
        while True:
            j = json.loads(self.f.readline())
            kind = j.get("class")
            if want and kind == want:
                return j
            if not want and kind not in ("DEVICE", "POSE_STARTED", "POSE_COLLECTING",
                                         "POSE_PROGRESS", "SAMPLE", "CORRECTED", "DROPPED",
                                         "ESTIMATE", "NOISE_MEASURED", "NOISE_RETRY"):
                return j


def rss_kb(pid):
    for line in open(f"/proc/{pid}/status"):
        if line.startswith("VmRSS:"):
            return int(line.split()[1])
    return 0


d = tempfile.mkdtemp(prefix="turncal-socket-")
daemon = None
try:
    subprocess.run([TURNCAL, "sim", "--protocol", "xbus", "--seed", "3", "-o", f"{d}/s.tcap"],
                   check=True, capture_output=True)
    sock = f"{d}/t.sock"
    config = f"{d}/turncald.toml"
    with open(config, "w") as f:
        f.write(f'socket = "{sock}"\nstate_dir = "{d}/state"\ncontrol_users = ["root"]\n'
                f'[[device]]\nname = "imu"\nprotocol = "xbus"\nport = "replay:{d}/s.tcap?speed=40"\n')
    daemon = subprocess.Popen([TURNCALD, "--config", config], stdout=open(f"{d}/d.log", "w"),
                              stderr=subprocess.STDOUT)
    for _ in range(200):
        if os.path.exists(sock):
            break
        time.sleep(0.05)
    mode = os.stat(sock).st_mode & 0o777
    check(mode == 0o660, f"the socket is created with mode {oct(mode)} (0660)")

    # A slow subscriber: watches raw samples and events, then reads nothing.
    slow = Client(sock, buffer=4096)
    slow.send({"cmd": "watch", "raw": True, "events": True})

    a = Client(sock)
    check(a.banner.get("class") == "VERSION" and a.banner.get("proto_major") == 1,
          f"banner: {a.banner}")
    bad = [b"this is not json\n", b"[1,2,3]\n", b'{"no_cmd":1}\n', b'{"cmd":"launch"}\n',
           b'{"cmd":"watch","max_rate_hz":-1}\n', b'{"cmd":"pose","phi_deg":"x"}\n',
           b'{"cmd":"' + b"x" * 100000 + b'"}\n']
    for request in bad:
        a.send_raw(request)
        r = a.reply()
        check(r.get("class") == "ERROR", f"{request[:40]!r}... -> ERROR: {r.get('message', r)[:90]}")
    a.send({"cmd": "status", "id": 42})
    r = a.reply()
    check(r.get("class") == "STATUS" and r.get("id") == 42,
          "the same connection still answers status (id echoed)")
    # The chamber's set-point (issue 36): a soak every device's poses wait for; null ends it.
    a.send({"cmd": "chamber", "setpoint_c": "hot"})
    r = a.reply()
    check(r.get("class") == "ERROR" and "setpoint_c" in r.get("message", ""),
          f"chamber with a set-point that is not a number -> ERROR: {r.get('message', r)}")
    a.send({"cmd": "chamber", "setpoint_c": 40})
    r = a.reply(want="CHAMBER")
    check(r.get("setpoint_c") == 40, f"chamber 40 degC -> CHAMBER: {r}")
    a.send({"cmd": "status"})
    r = a.reply(want="STATUS")
    soaks = [d["station"]["temperature"]["soak"] for d in r["devices"].values()]
    check(soaks and all(x and x["setpoint_c"] == 40 for x in soaks),
          f"status shows every device's soak at 40 degC: {soaks}")
    a.send({"cmd": "chamber", "setpoint_c": None})
    r = a.reply(want="CHAMBER")
    check(r.get("setpoint_c") is None, f"chamber null ends the soak: {r}")

    # Other clients are served promptly while the slow one is not reading.
    b = Client(sock)
    latencies = []
    samples_before = None
    for _ in range(30):
        t0 = time.monotonic()
        b.send({"cmd": "status"})
        r = b.reply()
        latencies.append(time.monotonic() - t0)
        samples = r["devices"]["imu"]["counters"]["samples"]
        samples_before = samples_before if samples_before is not None else samples
        time.sleep(0.2)
    # A server blocked by the stalled subscriber would answer late every time, or never: the
    # median says whether it is served promptly; the worst only bounds a loaded host's stalls
    # (796 ms once beside 200 unit tests, 2026-11-23).
    latencies.sort()
    median, worst = latencies[len(latencies) // 2], latencies[-1]
    check(median < 0.1 and worst < 2.0,
          f"status answered in {median * 1000:.1f} ms (median), {worst * 1000:.1f} ms at worst, "
          "while a subscriber stalls")
    check(samples - samples_before > 10000,
          f"the pipeline kept going: {samples - samples_before} samples decoded during the stall")
    rss = rss_kb(daemon.pid)
    check(SANITIZED or rss < 100 * 1024, f"daemon RSS {rss / 1024:.1f} MiB with a stalled subscriber")
    # The stalled subscriber now reads: it is told how much it lost.
    dropped = 0
    slow.s.settimeout(5)
    try:
        for _ in range(200000):
            line = slow.f.readline()
            if not line:
                break
            j = json.loads(line)
            if j.get("class") == "DROPPED":
                dropped = j["total"]
                break
    except socket.timeout:
        pass
    check(dropped > 0, f"the stalled subscriber is told it lost {dropped} messages (DROPPED)")

    # Mutating commands need an allowed uid: nobody (65534) may ask but not change.
    os.chmod(d, 0o755)  # mkdtemp's 0700 would keep nobody out before the socket's own mode
    os.chmod(sock, 0o666)
    probe = (
        "import json,os,socket,sys\n"
        "os.setgid(65534); os.setuid(65534)\n"
        "s=socket.socket(socket.AF_UNIX); s.connect(sys.argv[1]); f=s.makefile('rb'); f.readline()\n"
        "out=[]\n"
        "for r in ({'cmd':'status'},{'cmd':'pose','phi_deg':0,'gamma_deg':0,'psi_deg':0},"
        "{'cmd':'reset'},{'cmd':'publish'}):\n"
        "  s.sendall((json.dumps(r)+'\\n').encode())\n"
        "  while True:\n"
        "    j=json.loads(f.readline())\n"
        "    if j['class'] in ('STATUS','ERROR'): out.append(j); break\n"
        "print(json.dumps(out))\n")
    r = subprocess.run([sys.executable, "-c", probe, sock], capture_output=True, text=True, timeout=30)
    replies = json.loads(r.stdout) if r.returncode == 0 else []
    check(len(replies) == 4 and replies[0]["class"] == "STATUS" and
          all(x["class"] == "ERROR" and "refused" in x["message"] for x in replies[1:]),
          f"uid 65534: status answered, pose/reset/publish refused "
          f"({[x.get('message', x['class'])[:40] for x in replies]}{r.stderr[-200:]})")

    # SIGHUP: the configuration is read again (a typo is refused and the old one kept).
    watcher = Client(sock)
    watcher.send({"cmd": "watch", "events": True})
    watcher.reply(want="WATCH")
    with open(config, "a") as f:
        f.write("[sequencer]\ndwel_s = 2\n")
    # A reload drains the solve worker first (the old station's queued solves are skipped, the
    # one running finishes): waited for, not timed (the CI host under a sanitizer is slow).
    daemon.send_signal(signal.SIGHUP)
    r = watcher.reply(timeout=120, want="ERROR")
    check("reload refused" in r.get("message", "") and "dwel_s" in r.get("message", ""),
          f"SIGHUP with a typo: {r.get('message', '')[:100]}")
    with open(config) as f:
        text = f.read().replace("dwel_s", "dwell_s")
    with open(config, "w") as f:
        f.write(text)
    daemon.send_signal(signal.SIGHUP)
    r = watcher.reply(timeout=120, want="RELOADED")
    check(r.get("class") == "RELOADED", "SIGHUP: configuration reloaded")
    c = Client(sock)
    c.send({"cmd": "devices"})
    check(c.reply().get("class") == "DEVICES", "still serving after the reload")

    daemon.send_signal(signal.SIGTERM)
    code = daemon.wait(timeout=20)
    check(code == 0, f"SIGTERM: exit {code}")
    check(not os.path.exists(sock), "SIGTERM: the socket file is removed")
    daemon = None
finally:
    if daemon:
        daemon.kill()
    if failures:
        print(f"(kept {d})")
    else:
        shutil.rmtree(d, ignore_errors=True)

print(f"socket protocol: {len(failures)} failure(s)")
sys.exit(1 if failures else 0)
