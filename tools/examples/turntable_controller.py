#!/usr/bin/env python3
"""Example turntable controller for turncald (docs/protocol.md). Python 3 standard library only.

For each pose it moves the table (move_table), announces the pose on turncald's socket
({"cmd":"pose"}), shows the collection progress (POSE_PROGRESS) and waits until every device
named in POSE_ACCEPTED answered with POSE_CAPTURED or POSE_REJECTED. A rejected pose is announced
again to the devices that rejected it, up to --retries times, without moving the table. The poses come from a CSV file
(phi,gamma,psi in degrees, one header line; a row phi,gamma,psi,AXIS,RATE is a rate segment: the
table turns about AXIS -- outer, middle or inner -- at RATE deg/s with the other axes at their
angles, announced as {"cmd":"rate"} for a gyroscope model) or, with --plan, from the daemon's own advice
({"cmd":"next_pose"}) until the publication gate passes for every model of every device
({"cmd":"result"}). The advice is a rate segment when the daemon's [table] plan_rates_dps lists
the rates the table can hold and a gyroscope model needs one.

    turntable_controller.py --poses cube.csv --table-cmd "/usr/local/bin/move-table"
    turntable_controller.py --plan --socket /run/turncal/turncal.sock   # the operator moves it

Exit status: 0 every pose was captured by every device (with --plan: and the gate passed);
1 some pose was not (rejected after the retries, unanswered, a device skipped it) or --plan
stopped before the gate passed; 2 usage, connection or protocol error, a pose refused (for
example a user not in control_users), or a failed table command.

Replace move_table() with your table's driver; the default runs --table-cmd with the three
angles as arguments, and for a rate segment the axis and the rate after them (it must return once
the table is at the pose, or turns at the rate steadily), or asks the operator.
"""
import argparse
import collections
import csv
import json
import os
import select
import shlex
import socket
import subprocess
import sys
import time

PROTO_MAJOR = 1  # the protocol version this script speaks (docs/protocol.md "Versioning")


class Fatal(Exception):
    """An error that ends the run with exit status 2."""


# --------------------------------------------------------------------------------------------
# The turntable. Replace this with your own driver.

def move_table(pose, args):
    """Brings the table to pose (phi, gamma, psi) degrees and returns once it is there; for a
    rate segment (phi, gamma, psi, axis, rate_dps), once it turns about the axis at the rate
    steadily with the other axes at their angles."""
    phi, gamma, psi = pose[:3]
    if args.table_cmd:
        command = shlex.split(args.table_cmd) + [fmt_angle(phi), fmt_angle(gamma), fmt_angle(psi)]
        if len(pose) == 5:
            command += [pose[3], fmt_angle(pose[4])]
        done = subprocess.run(command)
        if done.returncode != 0:
            raise Fatal(f"table command {command} exited with {done.returncode}")
        return
    prompt = (f"Move the table to phi {phi:g}, gamma {gamma:g}, psi {psi:g} degrees, "
              "let it stop, then press Enter: ")
    if len(pose) == 5:
        prompt = (f"Turn the table about its {pose[3]} axis at {pose[4]:g} deg/s with the others "
                  f"at phi {phi:g}, gamma {gamma:g}, psi {psi:g} degrees; once the rate is "
                  "steady, press Enter: ")
    try:
        with open("/dev/tty", "r+") as tty:  # the operator, even when stdout is redirected
            tty.write(prompt)
            tty.flush()
            tty.readline()
    except OSError:
        sys.stderr.write(prompt)
        sys.stderr.flush()
        if not sys.stdin.readline():
            raise Fatal("no operator: standard input closed (give --table-cmd)")


def fmt_angle(x):
    return repr(float(x))


# --------------------------------------------------------------------------------------------
# The socket: JSON Lines, one object per line.

class Connection:
    def __init__(self, path, timeout=5.0):
        self.sock = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
        try:
            self.sock.connect(path)
        except OSError as e:
            raise Fatal(f"cannot connect to turncald at {path}: {e}")
        self.buffer = b""
        self.backlog = collections.deque()  # messages that arrived while a request waited
        self.next_id = 1
        banner = self.read(timeout)
        if banner is None or banner.get("class") != "VERSION":
            raise Fatal(f"{path}: no VERSION banner (is this turncald's socket?)")
        if banner.get("proto_major") != PROTO_MAJOR:
            raise Fatal(f"turncald speaks protocol {banner.get('proto_major')}."
                        f"{banner.get('proto_minor')}; this script speaks {PROTO_MAJOR}.x")
        self.banner = banner

    def send(self, request):
        try:
            self.sock.sendall((json.dumps(request) + "\n").encode())
        except OSError as e:
            raise Fatal(f"turncald closed the connection: {e}")

    def read(self, timeout):
        """The next message, or None when nothing arrived within `timeout` seconds."""
        if self.backlog:
            return self.backlog.popleft()
        deadline = time.monotonic() + timeout
        while b"\n" not in self.buffer:
            left = deadline - time.monotonic()
            if left <= 0:
                return None
            ready, _, _ = select.select([self.sock], [], [], left)
            if not ready:
                return None
            chunk = self.sock.recv(65536)
            if not chunk:
                raise Fatal("turncald closed the connection")
            self.buffer += chunk
        line, self.buffer = self.buffer.split(b"\n", 1)
        try:
            return json.loads(line)
        except ValueError:
            raise Fatal(f"turncald sent a line that is not JSON: {line[:80]!r}")

    def request(self, request, timeout=30.0):
        """Sends `request` with a fresh "id" and returns the reply carrying that id (an ERROR
        reply included). Other messages meanwhile (a pose's events) are kept for read()."""
        request = dict(request, id=self.next_id)
        self.next_id += 1
        self.send(request)
        deadline = time.monotonic() + timeout
        others = []
        while True:
            message = self.read(max(0.0, deadline - time.monotonic()))
            if message is None:
                raise Fatal(f"no reply to {request['cmd']} within {timeout} s")
            if message.get("id") == request["id"]:
                self.backlog.extendleft(reversed(others))
                return message
            others.append(message)


# --------------------------------------------------------------------------------------------

class Progress:
    """POSE_PROGRESS as a bar on a terminal, or a line at every quarter otherwise."""

    def __init__(self):
        self.tty = sys.stderr.isatty()
        self.shown = {}

    def update(self, message):
        needed = max(1, message.get("needed", 1))
        fraction = min(1.0, message.get("collected", 0) / needed)
        device, index = message.get("device", "?"), message.get("index")
        if self.tty:
            bar = "#" * round(30 * fraction) + "." * (30 - round(30 * fraction))
            sys.stderr.write(f"\r  {device} pose {index} [{bar}] {100 * fraction:3.0f}%")
            sys.stderr.flush()
            return
        quarter = int(fraction * 4)
        if quarter > self.shown.get((device, index), 0):
            self.shown[(device, index)] = quarter
            print(f"  {device} pose {index}: {message.get('collected')}/{needed} samples",
                  flush=True)

    def end_line(self):
        if self.tty:
            sys.stderr.write("\r" + " " * 60 + "\r")
            sys.stderr.flush()


def announce(conn, args, pose, targets, progress):
    """Announces the pose and waits for the answers. targets: None for every streaming device
    (or --device), else a list of devices, one request each (a retry). Returns (devices,
    answers, skipped): the devices POSE_ACCEPTED named, their answers {device: (class, reason,
    index)} (a device that did not answer in time is missing), the devices skipped {device:
    state}."""
    base = {"cmd": "pose", "phi_deg": pose[0], "gamma_deg": pose[1], "psi_deg": pose[2]}
    if len(pose) == 5:  # a rate segment (docs/protocol.md "rate")
        base.update(cmd="rate", axis=pose[3], rate_dps=pose[4])
    if args.dwell:
        base["dwell_s"] = args.dwell
    requests = []
    for device in targets if targets is not None else [args.device]:
        requests.append(dict(base, device=device) if device else base)
    waiting, skipped = set(), {}  # waiting: (index, device)
    for request in requests:
        # Each request gets the next index: the daemon keeps one waiting list per index and
        # connection, so two requests with one index would lose the first one's answers.
        accepted = conn.request(request)
        if accepted.get("class") == "ERROR":
            message = accepted.get("message", "")
            if "no device is streaming" not in message:  # not allowed, or a bad request
                raise Fatal(message)
            print(f"  pose refused: {message}", flush=True)
            continue
        waiting |= {(accepted["index"], d) for d in accepted["devices"]}
        skipped.update(accepted.get("skipped", {}))
    for device, state in skipped.items():
        print(f"  {device} skipped: it is {state}", flush=True)
    devices = sorted(d for _, d in waiting)
    answers = {}
    deadline = time.monotonic() + args.timeout
    while waiting and time.monotonic() < deadline:
        message = conn.read(min(1.0, max(0.0, deadline - time.monotonic())))
        if message is None:
            continue
        key = (message.get("index"), message.get("device"))
        if key not in waiting:
            continue  # DROPPED notes, other poses' events
        kind = message.get("class")
        if kind == "POSE_PROGRESS":
            progress.update(message)
        elif kind in ("POSE_CAPTURED", "POSE_REJECTED"):
            waiting.discard(key)
            answers[key[1]] = (kind, message.get("reason", ""), key[0])
            progress.end_line()
            word = "captured" if kind == "POSE_CAPTURED" else "REJECTED"
            print(f"  {key[1]}: pose {key[0]} {word}: {message.get('reason', '')}", flush=True)
    progress.end_line()
    for index, device in sorted(waiting):
        print(f"  {device}: pose {index}: no answer within {args.timeout:g} s", flush=True)
    return devices, answers, skipped


def run_pose(conn, args, pose, progress, summary, total=None):
    phi, gamma, psi = pose[:3]
    number = f"{len(summary) + 1}/{total}" if total else f"{len(summary) + 1} (planned)"
    spin = f", turning about the {pose[3]} axis at {pose[4]:g} deg/s" if len(pose) == 5 else ""
    print(f"pose {number}: phi {phi:g} gamma {gamma:g} psi {psi:g}{spin}", flush=True)
    move_table(pose, args)
    if args.settle > 0:
        time.sleep(args.settle)
    outcome, skipped, attempts, targets = {}, {}, 0, None  # outcome: device -> (class, index)
    while True:
        attempts += 1
        devices, answers, new_skipped = announce(conn, args, pose, targets, progress)
        if targets is None:
            skipped = new_skipped
        for device in devices:
            kind, _, index = answers.get(device, ("no answer", "", None))
            outcome[device] = (kind, index)
        rejected = [d for d, (kind, _) in outcome.items() if kind == "POSE_REJECTED"]
        unanswered = [d for d, (kind, _) in outcome.items() if kind == "no answer"]
        if (outcome and not rejected and not unanswered) or attempts > args.retries:
            break
        if outcome and not rejected:
            break  # devices that did not answer: announcing again would not help
        # Again to the devices that rejected it (all of them when the pose was refused); the
        # table stays where it is.
        targets = rejected or None
        print(f"  announcing again ({attempts} of {args.retries} retries)", flush=True)
        time.sleep(args.retry_delay)
    captured = bool(outcome) and all(kind == "POSE_CAPTURED" for kind, _ in outcome.values())
    entry = {"pose": {"phi_deg": phi, "gamma_deg": gamma, "psi_deg": psi},
             "attempts": attempts,
             "answers": {d: {"class": kind, "index": index}
                         for d, (kind, index) in outcome.items()},
             "skipped": skipped, "ok": captured and not skipped}
    if len(pose) == 5:
        entry["pose"].update(rate_axis=pose[3], rate_dps=pose[4])
    summary.append(entry)
    return entry["ok"]


def read_poses(path):
    poses = []
    with open(path, newline="") as f:
        rows = [r for r in csv.reader(f)
                if r and r[0].strip() and not r[0].lstrip().startswith("#")]
    if not rows:
        raise Fatal(f"{path}: no poses")
    try:
        float(rows[0][0])
    except ValueError:
        rows = rows[1:]  # the header line
    for n, row in enumerate(rows):
        try:
            phi, gamma, psi = (float(x) for x in row[:3])
            if len(row) >= 5 and row[3].strip():
                axis, rate = row[3].strip(), float(row[4])
                if axis not in ("outer", "middle", "inner") or rate == 0:
                    raise ValueError(axis)
                poses.append((phi, gamma, psi, axis, rate))
                continue
        except ValueError:
            raise Fatal(f"{path}: pose {n}: need phi,gamma,psi in degrees (and for a rate "
                        f"segment AXIS,RATE: outer|middle|inner, deg/s), got {row}")
        poses.append((phi, gamma, psi))
    return poses


def gates(conn, settle_s=0.0):
    """{(device, model): pass} from the daemon's result, for the models that have taken poses
    (a magnetometer model takes none from a device without a magnetometer). The estimates may
    follow POSE_CAPTURED by a moment: with settle_s, waits up to that long until every model has
    taken every captured pose of its device."""
    deadline = time.monotonic() + settle_s
    while True:
        result = conn.request({"cmd": "result"})
        if result.get("class") != "RESULT":
            raise Fatal(f"result: {result.get('message', result)}")
        devices = result["devices"]
        behind = any(model["poses"] < device["poses"]
                     for device in devices.values() for model in device["models"].values())
        if not behind or time.monotonic() >= deadline:
            break
        time.sleep(0.2)
    return {(d, m): bool(model["gate"]["pass"])
            for d, device in devices.items() for m, model in device["models"].items()
            if model["poses"] > 0}


def wait_for_devices(conn, args):
    deadline = time.monotonic() + args.wait_devices
    while True:
        devices = conn.request({"cmd": "devices"})["devices"]
        wanted = [d for d in devices if not args.device or d["name"] == args.device]
        if not wanted:
            raise Fatal(f"turncald has no device {args.device!r}")
        if all(d["state"] == "streaming" for d in wanted):
            return
        if time.monotonic() > deadline:
            states = ", ".join(f"{d['name']} {d['state']}" for d in wanted)
            print(f"not every device is streaming after {args.wait_devices:g} s ({states}); "
                  "going on with those that are", flush=True)
            return
        time.sleep(0.5)


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    source = parser.add_mutually_exclusive_group(required=True)
    source.add_argument("--poses", metavar="CSV", help="poses: phi,gamma,psi degrees, header line")
    source.add_argument("--plan", action="store_true",
                        help="ask the daemon for the next pose (next_pose) until the gate passes")
    parser.add_argument("--socket", default=os.environ.get("TURNCAL_SOCKET",
                                                           "/run/turncal/turncal.sock"))
    parser.add_argument("--table-cmd", metavar="CMD",
                        help="command that moves the table: CMD PHI GAMMA PSI (degrees); "
                             "default: ask the operator")
    parser.add_argument("--retries", type=int, default=2, help="announcements again per pose")
    parser.add_argument("--retry-delay", type=float, default=1.0, metavar="S")
    parser.add_argument("--timeout", type=float, default=120.0, metavar="S",
                        help="seconds to wait for the answers to one announcement")
    parser.add_argument("--settle", type=float, default=0.0, metavar="S",
                        help="seconds to wait after the move before announcing")
    parser.add_argument("--dwell", type=float, metavar="S", help="dwell_s of every pose")
    parser.add_argument("--device", help="only this device (default: every streaming device)")
    parser.add_argument("--max-poses", type=int, default=60, help="with --plan: at most this many")
    parser.add_argument("--wait-devices", type=float, default=30.0, metavar="S",
                        help="wait this long for the devices to stream before the first pose")
    parser.add_argument("--json", action="store_true", help="print the summary as JSON too")
    args = parser.parse_args()

    try:
        poses = read_poses(args.poses) if args.poses else None
        conn = Connection(args.socket)
        print(f"turncald {conn.banner.get('release')}, protocol "
              f"{conn.banner['proto_major']}.{conn.banner['proto_minor']}", flush=True)
        wait_for_devices(conn, args)
        progress, summary = Progress(), []
        gate_passed = None
        if poses is not None:
            for pose in poses:
                run_pose(conn, args, pose, progress, summary, total=len(poses))
        else:
            while len(summary) < args.max_poses:
                g = gates(conn, settle_s=3.0 if summary else 0.0)
                if args.device:
                    g = {k: v for k, v in g.items() if k[0] == args.device}
                if g and all(g.values()):
                    gate_passed = True
                    break
                gate_passed = False
                request = {"cmd": "next_pose"}
                if args.device:
                    request["device"] = args.device
                advice = conn.request(request, timeout=60)
                if not advice.get("ok"):
                    print(f"no next pose: {advice.get('error', advice.get('message'))}")
                    break
                p = advice["pose"]
                pose = (p["phi_deg"], p["gamma_deg"], p["psi_deg"])
                if "rate_axis" in p:  # a rate segment ([table] plan_rates_dps)
                    pose += (p["rate_axis"], p["rate_dps"])
                run_pose(conn, args, pose, progress, summary)
            else:
                g = gates(conn, settle_s=3.0)
                if args.device:
                    g = {k: v for k, v in g.items() if k[0] == args.device}
                gate_passed = bool(g) and all(g.values())
        final = gates(conn, settle_s=3.0)
    except Fatal as e:
        print(f"turntable_controller: {e}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        return 2

    captured = sum(1 for e in summary if e["ok"])
    print(f"\nsummary: {captured} of {len(summary)} poses captured")
    for n, e in enumerate(summary, 1):
        if not e["ok"]:
            answers = ", ".join(f"{d} {a['class']}" for d, a in e["answers"].items())
            skipped = ", ".join(f"{d} skipped ({state})" for d, state in e["skipped"].items())
            p = e["pose"]
            print(f"  pose {n} (phi {p['phi_deg']:g} gamma {p['gamma_deg']:g} psi "
                  f"{p['psi_deg']:g}) after {e['attempts']} announcement(s): "
                  f"{'; '.join(x for x in (answers, skipped) if x) or 'not accepted'}")
    for (device, model), ok in sorted(final.items()):
        print(f"  {device} {model}: gate {'PASS' if ok else 'fail'}")
    if args.json:
        print(json.dumps({"poses": summary, "captured": captured,
                          "gates": {f"{d} {m}": ok for (d, m), ok in final.items()}}))
    if args.plan:
        ok = gate_passed is True and captured == len(summary)
    else:
        ok = len(summary) > 0 and captured == len(summary)
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
