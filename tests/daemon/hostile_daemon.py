"""The hostile clients test's daemon side (hostile_clients_test.py): turncald started (and
restarted after a crash) on a config, a line-oriented client connection that tells replies from
stream messages, a subscriber thread that reads every raw sample, VmRSS."""
import json
import re
import socket
import subprocess
import threading
import time

from live_session import check, failures  # noqa: F401 (the test's ok/FAIL lines and their count)


def note(message):
    print("     " + message, flush=True)


# Classes that are not a direct reply to a request (docs/protocol.md "Messages from the daemon").
STREAM = {"SAMPLE", "CORRECTED", "DROPPED", "DEVICE", "POSE_STARTED", "POSE_COLLECTING",
          "POSE_PROGRESS", "NOISE_MEASURED", "NOISE_RETRY", "ESTIMATE", "CALIBRATION_ACTIVE",
          "SESSION_RESUMED", "SESSION_RESET", "RELOADED"}


def parse(line):
    """A daemon line as a dict. A reply too deep for Python's json (a deeply nested id echoed)
    is recognised by its first keys (nlohmann writes keys sorted: class, id, message)."""
    try:
        return json.loads(line)
    except RecursionError:
        m = re.match(rb'\{"class":"([A-Z_]+)"', line)
        msg = re.search(rb'"message":"([^"]*)"', line)
        return {"class": m.group(1).decode() if m else None,
                "message": msg.group(1).decode() if msg else None, "deep": True}


def rss_kb(pid):
    try:
        with open(f"/proc/{pid}/status") as f:
            for line in f:
                if line.startswith("VmRSS:"):
                    return int(line.split()[1])
    except OSError:
        pass
    return 0


class Closed(Exception):
    pass


class Conn:
    def __init__(self, path, rcvbuf=None, timeout=10):
        self.s = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
        if rcvbuf:
            self.s.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, rcvbuf)
        self.s.settimeout(timeout)
        self.s.connect(path)
        self.f = self.s.makefile("rb")
        self.banner = self.line()

    def send(self, data):
        self.s.sendall(data if isinstance(data, bytes) else (json.dumps(data) + "\n").encode())

    def line(self, timeout=10):
        self.s.settimeout(timeout)
        raw = self.f.readline()
        if not raw:
            raise Closed()
        return parse(raw)

    def reply(self, timeout=10, want_id=None):
        """The next message that is not a stream message (with `want_id`: the one with that id)."""
        deadline = time.monotonic() + timeout
        while True:
            j = self.line(max(0.01, deadline - time.monotonic()))
            if j.get("class") in STREAM:
                continue
            if want_id is None or j.get("id") == want_id:
                return j

    def until_sentinel(self, sid, timeout=10):
        """Every reply before the VERSION reply with id `sid`."""
        out = []
        deadline = time.monotonic() + timeout
        while True:
            j = self.line(max(0.01, deadline - time.monotonic()))
            if j.get("class") in STREAM:
                continue
            if j.get("class") == "VERSION" and j.get("id") == sid:
                return out
            out.append(j)

    def close(self):
        # The file from makefile() holds the descriptor too: both go, or the connection stays.
        for x in (self.f, self.s):
            try:
                x.close()
            except OSError:
                pass


class Daemon:
    def __init__(self, turncald, d, config, sock):
        self.turncald = turncald
        self.d, self.config, self.sock = d, config, sock
        self.proc = None
        self.starts = 0
        self.log = f"{d}/turncald.log"

    def start(self):
        self.starts += 1
        with open(self.log, "a") as log:
            log.write(f"--- start {self.starts}\n")
        self.proc = subprocess.Popen([self.turncald, "--config", self.config],
                                     stdout=open(self.log, "a"), stderr=subprocess.STDOUT)
        deadline = time.monotonic() + 15
        while time.monotonic() < deadline:
            try:
                c = Conn(self.sock, timeout=2)
                c.close()
                return
            except (OSError, Closed):
                time.sleep(0.05)
        raise RuntimeError("turncald did not start")

    def alive(self):
        return self.proc.poll() is None

    def last_words(self):
        with open(self.log, errors="replace") as f:
            lines = [l.strip() for l in f.read().split("--- start")[-1].splitlines()]
        interesting = [l for l in lines if "terminate" in l or "what()" in l or "error" in l.lower()]
        return " | ".join((interesting or lines)[-3:])[:300]

    def wait_dead(self, timeout=2):
        try:
            self.proc.wait(timeout=timeout)
        except subprocess.TimeoutExpired:
            pass
        return self.proc.poll()


class Subscriber(threading.Thread):
    """Watches every raw sample and event, reading continuously."""

    def __init__(self, sock):
        super().__init__(daemon=True)
        self.c = Conn(sock)
        self.c.send({"cmd": "watch", "raw": True, "events": True, "id": "sub"})
        self.samples = 0
        self.dropped = 0
        self.eof = False
        self.stop = False
        self.start()

    def run(self):
        self.c.s.settimeout(None)
        try:
            for raw in self.c.f:
                if raw.startswith(b'{"class":"SAMPLE"'):
                    self.samples += 1
                elif raw.startswith(b'{"class":"DROPPED"'):
                    self.dropped = json.loads(raw)["total"]
                if self.stop:
                    return
        except (OSError, ValueError):
            pass
        self.eof = not self.stop


# ----------------------------------------------------------------------------------------------
