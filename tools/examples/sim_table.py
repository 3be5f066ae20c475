#!/usr/bin/env python3
"""The --table-cmd of turntable_controller.py when the table is `turncal sim --live`.

`turncal sim --live PTY` plays a simulated table and prints one JSON line per pose on its standard
output once the table has settled there ({"event":"pose","phi_deg":…,"gamma_deg":…,"psi_deg":…}).
This command returns (exit 0) once that file holds the pose with these angles, that is once the
simulated table is at the pose; it fails (exit 1) after --timeout seconds. With AXIS RATE after the
angles it waits for the rate segment ({"event":"rate",…}) instead: the table turns steadily.

    sim_table.py EVENTS_FILE PHI GAMMA PSI [AXIS RATE] [--timeout S]

The simulator plays its own pose list in order, so the controller's poses must be the same list
(the demo and tests/daemon/example_controller_test.sh pass one CSV to both).
"""
import argparse
import json
import sys
import time


def is_turning(key, axis):
    """Whether the angle `key` is the turning axis's (its value then means nothing)."""
    return {"inner": "phi_deg", "middle": "gamma_deg", "outer": "psi_deg"}[axis] == key


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("events", help="the simulator's standard output (JSON lines)")
    parser.add_argument("angles", nargs=3, type=float, metavar="DEG", help="phi gamma psi")
    parser.add_argument("rate", nargs="*", metavar="AXIS RATE",
                        help="a rate segment: the turning axis and its rate in deg/s")
    parser.add_argument("--timeout", type=float, default=60.0)
    args = parser.parse_args()
    deadline = time.monotonic() + args.timeout
    keys = ("phi_deg", "gamma_deg", "psi_deg")
    while time.monotonic() < deadline:
        try:
            with open(args.events) as f:
                for line in f:
                    try:
                        e = json.loads(line)
                    except ValueError:
                        continue  # a line still being written
                    if args.rate:
                        if (e.get("event") == "rate" and e.get("rate_axis") == args.rate[0]
                                and abs(e.get("rate_dps", 0) - float(args.rate[1])) < 1e-6
                                and all(abs(e[k] - v) < 1e-6 for k, v in zip(keys, args.angles)
                                        if not is_turning(k, args.rate[0]))):
                            return 0
                    elif e.get("event") == "pose" and all(
                            abs(e[k] - v) < 1e-6 for k, v in zip(keys, args.angles)):
                        return 0
        except FileNotFoundError:
            pass
        time.sleep(0.02)
    print(f"sim_table.py: the simulated table never reached {args.angles} within "
          f"{args.timeout:g} s", file=sys.stderr)
    return 1


if __name__ == "__main__":
    sys.exit(main())
