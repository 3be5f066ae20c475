#!/usr/bin/env python3
"""turncald's systemd protocol without systemd (sd_notify(3), sd_listen_fds(3)): a datagram socket
plays $NOTIFY_SOCKET and a pre-bound listening socket plays socket activation (fd 3). Checks:
READY=1 with a STATUS line once the device's first open attempt finished; WATCHDOG=1 at least
every WATCHDOG_USEC/2; SIGHUP gives RELOADING=1 then READY=1; the activated socket serves
clients (VERSION banner) and is left in place at exit; SIGTERM gives STOPPING=1 and exit 0.

Usage: systemd_notify_test.py TURNCALD
"""
import os
import shutil
import signal
import socket
import struct
import subprocess
import sys
import tempfile
import time

TURNCALD = sys.argv[1]
failures = []


def check(ok, message):
    print(("ok   " if ok else "FAIL ") + message, flush=True)
    if not ok:
        failures.append(message)


d = tempfile.mkdtemp(prefix="turncal-notify-")
listener = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
listener.bind(f"{d}/activated.sock")
listener.listen(8)
if listener.fileno() != 3:  # the child must find it at fd 3 (SD_LISTEN_FDS_START)
    os.dup2(listener.fileno(), 3)
notify = socket.socket(socket.AF_UNIX, socket.SOCK_DGRAM)
notify.bind(f"{d}/notify")
notify.settimeout(0.1)
# Each message is timed by the kernel when the daemon sent it (SO_TIMESTAMP, wall clock), not when
# this script got round to reading it: a test process that a loaded host leaves unscheduled for a
# while must not make the daemon's cadence look irregular.
SO_TIMESTAMP = 29  # <asm-generic/socket.h>; Python's socket module does not name it
notify.setsockopt(socket.SOL_SOCKET, SO_TIMESTAMP, 1)
config = f"{d}/t.toml"
with open(config, "w") as f:
    f.write(f'state_dir = "{d}/state"\n[[device]]\nname = "a"\nprotocol = "mip"\nport = "{d}/absent"\n')

# fd 3 in the child is the listening socket; LISTEN_PID must be the child's pid, so a shell sets
# it after fork (exec keeps the pid).
env = dict(os.environ, NOTIFY_SOCKET=f"{d}/notify", WATCHDOG_USEC="1000000", LISTEN_FDS="1")
daemon = subprocess.Popen(
    ["sh", "-c", 'export LISTEN_PID=$$; exec "$0" "$@"', TURNCALD, "--config", config],
    env=env, pass_fds=(3,), stdin=subprocess.DEVNULL,
    stdout=open(f"{d}/log", "w"), stderr=subprocess.STDOUT)
messages = []


def collect(seconds):
    end = time.monotonic() + seconds
    while time.monotonic() < end:
        try:
            data, ancillary, _, _ = notify.recvmsg(4096, 64)
            sent = time.time()
            for level, kind, value in ancillary:
                if level == socket.SOL_SOCKET and kind == SO_TIMESTAMP:
                    seconds, microseconds = struct.unpack("qq", value[:16])
                    sent = seconds + microseconds * 1e-6
            messages.append((sent, data.decode()))
        except socket.timeout:
            pass


try:
    collect(2.6)
    ready = [m for t, m in messages if m.startswith("READY=1")]
    check(bool(ready) and "STATUS=0/1 devices streaming" in ready[0],
          f"READY=1 with STATUS: {ready[:1]}")
    dog = [t for t, m in messages if m == "WATCHDOG=1"]
    gaps = [b - a for a, b in zip(dog, dog[1:])]
    # Every WATCHDOG_USEC/2 (the daemon's 50 ms tick rounds it up): the mean gap over the run says
    # the cadence (one late message makes its own gap longer and the next one shorter: a median of
    # 439 ms on a loaded host, 2026-11-23, when messages were timed as read); systemd's own limit,
    # WATCHDOG_USEC, bounds the largest (CI once showed a 318 ms gap with a 300 ms limit, so the
    # limit here is 1 s).
    mean = (dog[-1] - dog[0]) / len(gaps) if gaps else 9
    check(len(dog) >= 4 and 0.45 <= mean <= 0.6 and max(gaps) < 1.0,
          f"WATCHDOG=1 {len(dog)} times in 2.6 s, mean gap {mean * 1000:.0f} ms, largest "
          f"{max(gaps or [9]) * 1000:.0f} ms (WATCHDOG_USEC 1000 ms)")
    c = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
    c.connect(f"{d}/activated.sock")
    banner = c.makefile("rb").readline()
    check(b'"class":"VERSION"' in banner, f"the activated socket serves: {banner[:60]!r}")
    c.close()
    messages.clear()
    daemon.send_signal(signal.SIGHUP)
    collect(1.0)
    states = [m.split("\n")[0] for t, m in messages if m != "WATCHDOG=1"]
    check(states[:2] == ["RELOADING=1", "READY=1"], f"SIGHUP: {states[:2]}")
    messages.clear()
    daemon.send_signal(signal.SIGTERM)
    code = daemon.wait(timeout=10)
    collect(0.3)
    check(any(m == "STOPPING=1" for t, m in messages), "SIGTERM: STOPPING=1")
    check(code == 0, f"SIGTERM: exit {code}")
    check(os.path.exists(f"{d}/activated.sock"), "the activated socket's file is left to systemd")
    log = open(f"{d}/log").read()
    check("retrying" in log, "the absent device is reported and retried")
finally:
    if daemon.poll() is None:
        daemon.kill()
    print(open(f"{d}/log").read()[-600:]) if failures else None
    shutil.rmtree(d, ignore_errors=True)

print(f"systemd notify: {len(failures)} failure(s)")
sys.exit(1 if failures else 0)
