#!/usr/bin/env python3
"""Freeze a live test's processes now and then, all at once, as a host that is not scheduled does.

Every 2-8 s (seeded) it stops (SIGSTOP) every process whose command line contains PATTERN, the
live tests' temporary directory prefix (turncald, the simulator, the watching client all name a
path in it), for MIN_S-MAX_S seconds, then continues them (SIGCONT). The host clocks go on, so
the simulator comes back owing the frames of the freeze and the daemon finds a backlog: what a
virtual machine whose host took its CPUs away does to the live tests. Not a ctest; run it beside
one (docs/RELIABILITY.md, "Live tests on a loaded host"):

  tests/daemon/freeze_sessions.py --seed 2 --min-s 0.5 --max-s 3 turncal-e2e- &
  python3 tests/daemon/e2e_live_test.py build/tools/turncal build/daemon/turncald all
  kill %1

Prints one line per freeze; stops by itself after --for-s seconds (default 900).
"""
import argparse
import os
import random
import signal
import subprocess
import time

parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
parser.add_argument("pattern", help="part of the frozen processes' command lines")
parser.add_argument("--seed", type=int, default=1)
parser.add_argument("--min-s", type=float, default=0.5, help="shortest freeze (s)")
parser.add_argument("--max-s", type=float, default=2.0, help="longest freeze (s)")
parser.add_argument("--for-s", type=float, default=900, help="stop after this long (s)")
args = parser.parse_args()
if not 0 <= args.min_s <= args.max_s:
    parser.error("need 0 <= --min-s <= --max-s")

rng = random.Random(args.seed)
end = time.monotonic() + args.for_s
frozen_total, count = 0.0, 0
while time.monotonic() < end:
    time.sleep(rng.uniform(2, 8))
    found = subprocess.run(["pgrep", "-f", args.pattern], capture_output=True, text=True).stdout
    pids = [int(p) for p in found.split() if int(p) != os.getpid()]
    if not pids:
        continue
    stopped = []
    for pid in pids:
        try:
            os.kill(pid, signal.SIGSTOP)
            stopped.append(pid)
        except ProcessLookupError:
            pass
    seconds = rng.uniform(args.min_s, args.max_s)
    time.sleep(seconds)
    for pid in stopped:
        try:
            os.kill(pid, signal.SIGCONT)
        except ProcessLookupError:
            pass
    count += 1
    frozen_total += seconds
    print(f"freeze {count}: {len(stopped)} processes for {seconds:.2f} s "
          f"({frozen_total:.1f} s frozen so far)", flush=True)
