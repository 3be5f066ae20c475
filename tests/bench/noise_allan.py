#!/usr/bin/env python3
"""The plain vectorised overlapping Allan deviation, as allantools computes it (phase as the
cumulative sum, then the second difference at every starting point for each cluster size, one
numpy pass per size), on a .npy array of columns t, x y z, ... (tests/bench/noise_speed.sh).

Usage: noise_allan.py FILE.npy TURNCAL.json  -- the cluster sizes are turncal noise --json's;
prints one JSON line: load and compute seconds, peak memory, and the largest relative
difference from turncal's deviations (and that difference in units of turncal's 68 % interval).
"""
import json
import resource
import sys
import time

import numpy as np

t0 = time.perf_counter()
data = np.load(sys.argv[1])
t1 = time.perf_counter()
result = json.load(open(sys.argv[2]))
worst_rel, worst_ci = 0.0, 0.0
for column, axis in enumerate(result["axes"], start=1):
    y = data[:, column]
    x = np.concatenate(([0.0], np.cumsum(y - y[0])))  # phase, centred
    for p in axis["allan"]:
        m = p["m"]
        d = x[2 * m:] - 2.0 * x[m:-m] + x[:-2 * m]
        adev = np.sqrt(np.dot(d, d) / (2.0 * m * m * len(d)))
        rel = abs(p["adev"] - adev) / adev
        worst_rel = max(worst_rel, rel)
        half = (p["ci68"][1] - p["ci68"][0]) / 2
        worst_ci = max(worst_ci, abs(p["adev"] - adev) / half if half > 0 else 0.0)
t2 = time.perf_counter()
print(json.dumps({"numpy": np.__version__, "load_s": t1 - t0, "compute_s": t2 - t1,
                  "points": sum(len(a["allan"]) for a in result["axes"]),
                  "peak_rss_mb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024,
                  "largest_relative_difference": worst_rel,
                  "largest_difference_in_ci68_halfwidths": worst_ci}))
