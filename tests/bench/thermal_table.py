#!/usr/bin/env python3
"""The Markdown table of docs/THERMAL.md "Through the whole pipeline" from the JSON lines
tests/bench/thermal_matrix.sh writes (one line per row; several files, e.g. one per seed, are
read in turn), with the summary statistics under it.

  tests/bench/thermal_table.py docs/thermal-matrix.jsonl
"""
import json
import math
import sys


def profile(d):
    return "soaks" if "soak" in d.get("chamber", "") else "ramp"


def row(d):
    z = [p["std_z"] for p in d["params"]]
    m = [abs(p["mean_z"]) for p in d["params"]]
    bad = [p for p in d["params"] if not p["honest"]]
    outside = ", ".join("{} ({:.3f}, {:+.3f})".format(p["name"], p["std_z"], p["mean_z"])
                        for p in bad) or "—"
    return "| {} | {} | {} | {} | {}/{} | {:.3f}–{:.3f} | {:.3f} | {:.3g} | {} | {} of {}: {} |".format(
        d["model"], d["class"], profile(d), d.get("seed", "?"), d["solved"], d["runs"], min(z),
        max(z), max(m), d["chi2_ks_p"], d["gate_pass"], len(bad), len(z), outside)


def main():
    rows = [json.loads(line) for name in sys.argv[1:] for line in open(name) if line.strip()]
    print("| model | class | chamber | seed | solved | std z, min–max | largest \\|mean z\\| | "
          "χ² p-values, KS p | gate passed | outside the criteria (std z, mean z) |")
    print("|---|---|---|---|---|---|---|---|---|---|")
    for d in rows:
        print(row(d))
    std = [p["std_z"] for d in rows for p in d["params"]]
    mean = [p["mean_z"] for d in rows for p in d["params"]]
    out = sum(not p["honest"] for d in rows for p in d["params"])
    over = sum(p["std_z"] > 1.1 for d in rows for p in d["params"])
    under = sum(p["std_z"] < 0.9 for d in rows for p in d["params"])
    avg = sum(std) / len(std)
    rms = math.sqrt(sum(x * x for x in mean) / len(mean))
    ks = [d["chi2_ks_p"] for d in rows]
    print("\n{} rows, {} entries: {} outside the criteria ({} with std z > 1.1, {} below 0.9); "
          "std z average {:.3f}, {:.3f}–{:.3f}; mean z RMS {:.3f}; KS p {:.3g}–{:.3g}, {} of {} "
          "below 0.01".format(len(rows), len(std), out, over, under, avg, min(std), max(std), rms,
                              min(ks), max(ks), sum(k < 0.01 for k in ks), len(ks)))


if __name__ == "__main__":
    main()
